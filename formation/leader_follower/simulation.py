"""Closed-loop simulation of a leader and a chain of unicycle followers (docs/theory/leader_follower.md §9).

The scenarios are those of Karasalo & Hu (2010), §8.

:func:`simulate` integrates the agents' kinematics with ``scipy.integrate.solve_ivp`` and returns an
``xarray.Dataset``. Two regimes, chosen from the problem:

* **continuous** — exact sensing and a reference known in closed form: the controls are evaluated inside the
  ODE right-hand side and the whole horizon is one ``solve_ivp`` call (outputs at the grid ``t_k = k h``).
  This is the regime of the analytic tests (``x_e = x_e(0) e^{−kt}``), where the only error is the
  integrator's, controlled by ``rtol``/``atol``.
* **sampled** — a sensor ring (the switching filter runs every ``h`` seconds, the controls are held
  constant between samples) or a reference needing the predecessor's path (updated every ``h``; with exact
  sensing the control itself stays continuous). ``solve_ivp`` integrates each interval ``[t_k, t_{k+1}]``.
  Before its filter's first detection of the predecessor a follower waits (zero inputs).

The leader's inputs are pre-defined: ``v_1`` constant, ``ω_1(t) = ω + a sin(2π t / T)``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import xarray as xr
from scipy.integrate import solve_ivp

from ...core.ode_budget import bounded_rhs
from .controls import FormationControl, FormationReference
from .paths import path_deviation
from .references import ReferenceSchedule
from .sensing import ExactSensing, RingSpec, exact_measurement
from .unicycle import reference_point_error, relative_state, unicycle_rates

__all__ = ["LeaderMotion", "IntegrationSettings", "LeaderFollowerProblem", "simulate"]


@dataclass(frozen=True)
class LeaderMotion:
    """The leader's initial pose and pre-defined inputs.

    Attributes
    ----------
    pose : ndarray, shape (3,)
        ``(x, y, φ)`` at t = 0 (m, m, rad).
    speed : float
        ``v_1`` (m/s).
    turn_rate : float
        Mean turn rate ``ω`` (rad/s).
    turn_rate_amplitude, turn_rate_period : float
        ``a`` (rad/s) and ``T`` (s) of the sinusoidal part of ``ω_1(t)``.
    """

    pose: np.ndarray
    speed: float
    turn_rate: float = 0.0
    turn_rate_amplitude: float = 0.0
    turn_rate_period: float = 1.0

    def inputs(self, t: float) -> tuple[float, float]:
        """``(v_1, ω_1)`` at time ``t``."""
        return self.speed, self.turn_rate + self.turn_rate_amplitude * math.sin(2 * math.pi * t / self.turn_rate_period)


@dataclass(frozen=True)
class IntegrationSettings:
    """``solve_ivp`` method and tolerances."""

    method: str = "DOP853"
    rtol: float = 1e-9
    atol: float = 1e-12


@dataclass(frozen=True)
class LeaderFollowerProblem:
    """A leader and ``m`` followers, each tracking its predecessor with the same control and reference.

    Attributes
    ----------
    leader : LeaderMotion
    follower_poses : ndarray, shape (m, 3)
        Initial follower poses, in chain order (agent 2, 3, …).
    control : FormationControl
    reference : ReferenceSchedule
    gain : float
        ``k`` (1/s).
    duration, step : float
        Horizon (s) and output / sample period ``h`` (s); ``duration`` is a multiple of ``step``.
    ring : RingSpec or None
        Sensor ring and switching filter for every follower; None for exact sensing.
    integration : IntegrationSettings
    seed : int
        Seed of the range noise.
    """

    leader: LeaderMotion
    follower_poses: np.ndarray
    control: FormationControl
    reference: ReferenceSchedule
    gain: float
    duration: float
    step: float
    ring: RingSpec | None = None
    integration: IntegrationSettings = IntegrationSettings()
    seed: int = 0

    @property
    def n_agents(self) -> int:
        """Leader plus followers."""
        return len(self.follower_poses) + 1

    @property
    def sampled(self) -> bool:
        """True if the loop runs at sample instants (ring sensing or a path-dependent reference)."""
        return self.ring is not None or self.reference.needs_history


class _History:
    """Growable buffer of a predecessor's recorded positions (amortised O(1) append)."""

    def __init__(self, initial: np.ndarray, capacity: int) -> None:
        self.data = np.empty((len(initial) + capacity, 2))
        self.data[: len(initial)] = initial
        self.size = len(initial)

    def append(self, point: np.ndarray) -> None:
        self.data[self.size] = point
        self.size += 1

    def view(self) -> np.ndarray:
        return self.data[: self.size]


def _agent_inputs(
    problem: LeaderFollowerProblem,
    t: float,
    poses: np.ndarray,
    reference_at: Callable[[int, float], FormationReference],
    held: list[tuple[float, float] | None],
) -> tuple[np.ndarray, np.ndarray]:
    """Inputs ``(v, ω)`` of all agents: leader's pre-defined, followers' from exact feedback or held values."""
    v = np.empty(problem.n_agents)
    w = np.empty(problem.n_agents)
    v[0], w[0] = problem.leader.inputs(t)
    for i in range(1, problem.n_agents):
        if held[i - 1] is not None:
            v[i], w[i] = held[i - 1]
        else:  # cascade: v_{i−1} is the predecessor's input just computed
            measurement = exact_measurement(poses[i], poses[i - 1], v[i - 1])
            v[i], w[i] = problem.control.command(measurement, reference_at(i - 1, t), problem.gain)
    return v, w


#: most right-hand-side evaluations of one ``solve_ivp`` call per output step in it (the shipped scenarios need at
#: most 38 per step, 2933 per call, measured): a safety net behind the pre-flight time estimate
#: (:mod:`mobisense.formation.sizes`) for dynamics too fast to integrate (a fuzzer's reference frequency of 1e12
#: rad/s ran 5·10⁶ evaluations, ≈ 100 s, before the fixed limit of 5·10⁶ per call stopped it)
MAX_EVALUATIONS_PER_STEP = 2_000


def _integrate(
    problem: LeaderFollowerProblem,
    span: tuple[float, float],
    state: np.ndarray,
    reference_at: Callable[[int, float], FormationReference],
    held: list[tuple[float, float] | None],
    t_eval: np.ndarray | None = None,
):
    limit = MAX_EVALUATIONS_PER_STEP * max(1, len(t_eval) - 1 if t_eval is not None else 1)

    def rates(t: float, s: np.ndarray) -> np.ndarray:
        poses = s.reshape(-1, 3)
        v, w = _agent_inputs(problem, t, poses, reference_at, held)
        return unicycle_rates(poses, v, w).ravel()  # docs/theory/leader_follower.md, eq. leader_follower.1

    def too_fast(t: float) -> RuntimeError:
        return RuntimeError(
            f"the integrator needed more than {limit:.3g} evaluations on [{span[0]:g}, {span[1]:g}] s "
            f"({MAX_EVALUATIONS_PER_STEP} per output step; stopped at t = {t:.6g} s): the dynamics are too fast "
            "for the time step (speeds, turn rates, frequencies or gains)"
        )

    cfg = problem.integration
    bounded = bounded_rhs(rates, limit, too_fast)
    sol = solve_ivp(bounded, span, state, method=cfg.method, rtol=cfg.rtol, atol=cfg.atol, t_eval=t_eval)
    if not sol.success:
        raise RuntimeError(f"solve_ivp failed on [{span[0]:g}, {span[1]:g}] s: {sol.message}")
    return sol


def simulate(problem: LeaderFollowerProblem, rng: np.random.Generator | None = None) -> xr.Dataset:
    """Simulate the closed loop.

    Parameters
    ----------
    problem : LeaderFollowerProblem
    rng : numpy.random.Generator, optional
        Range-noise generator (default ``default_rng(problem.seed)``).

    Returns
    -------
    xarray.Dataset
        Dimensions ``agent`` (1 = leader, 2, …), ``follower`` (2, …), ``time`` (s) and ``pair`` (1, …,
        ring mode). Variables: ``x, y, phi, v, omega`` per agent; ``d, beta, gamma, d0, beta0, xe, ye,
        deviation`` per follower (true values; ``deviation`` is eq. 54); the follower's estimates
        ``d_est, beta_est, speed_est, target_x_est, target_y_est`` and ``position_error`` (NaN before the first
        detection; equal to the truth with exact sensing); ``active`` (follower, time, pair) and
        ``selected_pair`` (1-based, 0 for none or a combination) in ring mode.

    Raises
    ------
    mobisense.formation.leader_follower.controls.FormationSingularityError
        If a control reaches its singular set.
    RuntimeError
        If the integrator fails.
    """
    rng = np.random.default_rng(problem.seed) if rng is None else rng
    n, m = problem.n_agents, problem.n_agents - 1
    n_steps = round(problem.duration / problem.step)
    times = problem.step * np.arange(n_steps + 1)
    state = np.vstack([problem.leader.pose, problem.follower_poses]).astype(float).ravel()
    n_pairs = problem.ring.ring.n_pairs if problem.ring is not None else 0
    rec = {
        "poses": np.empty((n_steps + 1, n, 3)),
        "v": np.empty((n_steps + 1, n)),
        "omega": np.empty((n_steps + 1, n)),
        "d0": np.empty((n_steps + 1, m)),
        "beta0": np.empty((n_steps + 1, m)),
        "estimate": np.full((n_steps + 1, m, 4), np.nan),
        "d_est": np.full((n_steps + 1, m), np.nan),
        "beta_est": np.full((n_steps + 1, m), np.nan),
        "active": np.zeros((n_steps + 1, m, n_pairs), dtype=np.int8),
        "selected": np.zeros((n_steps + 1, m), dtype=np.int16),
    }
    if not problem.sampled:

        def analytic(index: int, t: float) -> FormationReference:
            return problem.reference.at(t)

        no_hold: list[tuple[float, float] | None] = [None] * m
        sol = _integrate(problem, (0.0, times[-1]), state, analytic, no_hold, t_eval=times)
        sensing = ExactSensing()
        for k, t in enumerate(times):
            poses = sol.y[:, k].reshape(n, 3)
            v, w = _agent_inputs(problem, t, poses, analytic, no_hold)
            refs = [analytic(i, t) for i in range(m)]
            sensed = [sensing.measure(poses[i + 1], poses[i], v[i]) for i in range(m)]
            _record(rec, k, poses, v, w, refs, sensed)
    else:
        _simulate_sampled(problem, times, state, rng, rec)
    return _dataset(problem, times, rec)


def _simulate_sampled(
    problem: LeaderFollowerProblem, times: np.ndarray, state: np.ndarray, rng: np.random.Generator, rec: dict
) -> None:
    """Sample-and-hold loop: sense and update references at ``t_k``, integrate to ``t_{k+1}``."""
    n, m = problem.n_agents, problem.n_agents - 1
    sensing = [ExactSensing() if problem.ring is None else problem.ring.sensing(problem.step, rng) for _ in range(m)]
    poses = state.reshape(n, 3)
    histories = [_History(problem.reference.initial_history(poses[i]), len(times)) for i in range(m)]
    refs: list[FormationReference | None] = [None] * m

    def held_reference(index: int, t: float) -> FormationReference:
        return refs[index]

    for k, t in enumerate(times):
        poses = state.reshape(n, 3)
        v = np.empty(n)
        w = np.empty(n)
        v[0], w[0] = problem.leader.inputs(t)
        held: list[tuple[float, float] | None] = [None] * m
        sensed_all = []
        for i in range(m):
            sensed = sensing[i].measure(poses[i + 1], poses[i], v[i])
            sensed_all.append(sensed)
            if np.isfinite(sensed.predecessor_state[0]):
                histories[i].append(sensed.predecessor_state[:2])
            new_ref = problem.reference.at(t, histories[i].view() if problem.reference.needs_history else None)
            refs[i] = new_ref if new_ref is not None else refs[i]
            if refs[i] is None:
                raise RuntimeError(f"follower {i + 2}: no formation reference defined at t = {t:g} s")
            if sensing[i].continuous:  # exact sensing: continuous feedback, reference held
                measurement = exact_measurement(poses[i + 1], poses[i], v[i])
            else:  # sampled feedback from the filter's estimate
                measurement = sensed.measurement
            # before the first detection the follower waits (zero inputs)
            command = (0.0, 0.0) if measurement is None else problem.control.command(measurement, refs[i], problem.gain)
            held[i] = None if sensing[i].continuous else command
            v[i + 1], w[i + 1] = command
        _record(rec, k, poses, v, w, refs, sensed_all)
        if k + 1 < len(times):
            sol = _integrate(problem, (t, times[k + 1]), state, held_reference, held)
            state = sol.y[:, -1]


def _record(rec: dict, k: int, poses: np.ndarray, v: np.ndarray, w: np.ndarray, refs: list, sensed: list) -> None:
    rec["poses"][k] = poses
    rec["v"][k], rec["omega"][k] = v, w
    for i, (ref, s) in enumerate(zip(refs, sensed, strict=True)):
        rec["d0"][k, i], rec["beta0"][k, i] = ref.distance, ref.bearing
        rec["estimate"][k, i] = s.predecessor_state
        if s.measurement is not None:
            rec["d_est"][k, i], rec["beta_est"][k, i] = s.measurement.distance, s.measurement.bearing
        if s.active is not None:
            rec["active"][k, i] = s.active
            rec["selected"][k, i] = s.selected + 1


def _dataset(problem: LeaderFollowerProblem, times: np.ndarray, rec: dict) -> xr.Dataset:
    poses = rec["poses"]
    followers, predecessors = poses[:, 1:], poses[:, :-1]
    d, beta, gamma = relative_state(followers, predecessors)
    xe, ye = reference_point_error(followers, predecessors, rec["d0"], rec["beta0"])
    deviation = np.stack(
        [path_deviation(poses[:, i, :2], poses[:, i + 1, :2]) for i in range(problem.n_agents - 1)], axis=1
    )
    est = rec["estimate"]
    wrap = np.remainder(rec["beta_est"] + np.pi, 2 * np.pi) - np.pi
    agent = np.arange(1, problem.n_agents + 1)
    ft = ("follower", "time")

    def per_follower(values: np.ndarray) -> tuple:
        return ft, values.T

    data = {
        "x": (("agent", "time"), poses[:, :, 0].T, {"units": "m", "long_name": "agent position, x"}),
        "y": (("agent", "time"), poses[:, :, 1].T, {"units": "m", "long_name": "agent position, y"}),
        "phi": (("agent", "time"), poses[:, :, 2].T, {"units": "rad", "long_name": "heading"}),
        "v": (("agent", "time"), rec["v"].T, {"units": "m s-1", "long_name": "forward speed input"}),
        "omega": (("agent", "time"), rec["omega"].T, {"units": "rad s-1", "long_name": "turn-rate input"}),
        "d": (*per_follower(d), {"units": "m", "long_name": "distance to predecessor"}),
        "beta": (*per_follower(beta), {"units": "rad", "long_name": "bearing of predecessor"}),
        "gamma": (*per_follower(gamma), {"units": "rad", "long_name": "heading difference phi_i - phi_{i-1}"}),
        "d0": (*per_follower(rec["d0"]), {"units": "m", "long_name": "reference distance"}),
        "beta0": (*per_follower(rec["beta0"]), {"units": "rad", "long_name": "reference bearing"}),
        "xe": (*per_follower(xe), {"units": "m", "long_name": "reference-point error, world x component"}),
        "ye": (*per_follower(ye), {"units": "m", "long_name": "reference-point error, world y component"}),
        "deviation": (*per_follower(deviation), {"units": "m", "long_name": "deviation from path of predecessor"}),
        "d_est": (*per_follower(rec["d_est"]), {"units": "m", "long_name": "distance used by the control"}),
        "beta_est": (*per_follower(wrap), {"units": "rad", "long_name": "bearing used by the control"}),
        "speed_est": (*per_follower(np.hypot(est[..., 2], est[..., 3])),
                      {"units": "m s-1", "long_name": "estimated predecessor speed"}),
        "target_x_est": (*per_follower(est[..., 0]), {"units": "m", "long_name": "estimated predecessor x"}),
        "target_y_est": (*per_follower(est[..., 1]), {"units": "m", "long_name": "estimated predecessor y"}),
        "position_error": (
            *per_follower(np.hypot(est[..., 0] - predecessors[..., 0], est[..., 1] - predecessors[..., 1])),
            {"units": "m", "long_name": "predecessor position estimation error"},
        ),
        "active": (
            ("follower", "time", "pair"),
            np.moveaxis(rec["active"], 0, 1),
            {"long_name": "sensor pair active: both sensors read and a triangle exists (1) or not (0)",
             "units": "1"},
        ),
        "selected_pair": (*per_follower(rec["selected"]),
                          {"long_name": "sensor pair of the merged sub-filter (1-based; 0: none)", "units": "1"}),
    }
    coords = {
        "time": ("time", times, {"units": "s", "long_name": "time"}),
        "agent": ("agent", agent, {"units": "1", "long_name": "agent number (1: the leader)"}),
        "follower": ("follower", agent[1:], {"units": "1", "long_name": "agent number of the follower"}),
        "pair": ("pair", np.arange(1, rec["active"].shape[2] + 1),
                 {"units": "1", "long_name": "sensor pair number"}),
    }
    return xr.Dataset(data, coords=coords)
