"""The closed-loop replay on a field (docs/theory/replay.md §2): platforms, formation control, centre motion, filter.

State of the ODE: platform positions and velocities ``(N, 2)`` each, plus the extra states of the shape
task (``ψ, Ω`` of a rotating formation). Its right-hand side, at any time t:

1. centre and Jacobi vectors of positions and velocities (:class:`~mobisense.formation.jacobi.JacobiTransform`);
2. field value and derivatives at the centre — the filter's Taylor prediction from the last sample, or
   the true field (:mod:`mobisense.formation.replay.estimator`);
3. centre acceleration ``a_c``: level-curve tracking (eq. 48 + speed control) or tracking of an
   optimised reference (:mod:`mobisense.formation.replay.reference`);
4. shape forces ``u_j`` (:mod:`mobisense.formation.replay.shape_tasks`);
5. platform forces ``f = [N a_c, u] Ψ^T`` (eq. 40 inverted), limited (:mod:`mobisense.formation.platforms`).

``solve_ivp`` (RK45, ``rtol`` 1e-7) integrates between consecutive filter samples, the controllers being
continuous; at each sample every platform measures ``p_i = z(r_i) + w(r_i) + n_i`` (``w`` one sample
function of the scenario's spatial noise, ``n`` white) and the filter steps. :func:`simulate` returns a
:class:`ReplayRecord` of everything at the sample times.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...core.config import ConfigError
from ...core.interrupts import raise_if_interrupted
from ...core.ode_budget import bounded_rhs
from ...estimation.cooperative.information_model import formation_center, rotation
from ..jacobi import JacobiTransform
from ..level_curve import LEVEL_FUNCTIONS, LevelCurveController
from ..platforms import PlatformLimits, newton_rates
from .estimator import ClosedLoopEstimator, TrueField
from .plan import resolve
from .reference import ReferenceTrajectory, TrackingController, load_or_solve
from .scenario import FieldReplayScenario, LevelCurveMotion, ReferenceMotion
from .shape_tasks import build_shape_task

__all__ = ["ReplayError", "ReplaySystem", "ReplayRecord", "build_system", "simulate"]


class ReplayError(RuntimeError):
    """The closed loop became singular (centre at rest, vanishing gradient) or the integrator failed."""


@dataclass
class CenterTracking:
    """The centre follows one sensor of an optimised solution (time shifted to start at the solution's t0)."""

    reference: ReferenceTrajectory
    controller: TrackingController
    t0: float

    def __call__(self, t: float, center: np.ndarray, velocity: np.ndarray, *_: Any) -> np.ndarray:
        """Centre acceleration (L/T²)."""
        p, v, u = self.reference(self.t0 + t)
        return self.controller(center, velocity, (p[0], v[0], u[0]))

    def position(self, t: np.ndarray) -> np.ndarray:
        """Reference centre positions ``t.shape + (2,)``."""
        return self.reference(self.t0 + np.asarray(t))[0][..., 0, :]


@dataclass
class CenterLevelCurve:
    """The centre tracks a level curve (docs/theory/level_curve.md) with the field knowledge it is given."""

    controller: LevelCurveController

    def __call__(
        self, t: float, center: np.ndarray, velocity: np.ndarray, z: Any, g: Any, H: Any
    ) -> np.ndarray:
        """Centre acceleration (L/T²)."""
        return self.controller(velocity, z, g, H)


@dataclass
class ReplaySystem:
    """Everything a replay needs, built (and validated) from a scenario by :func:`build_system`."""

    scenario: FieldReplayScenario
    field: Any
    jacobi: JacobiTransform
    limits: PlatformLimits
    shape: Any
    center: CenterLevelCurve | CenterTracking
    estimator: ClosedLoopEstimator
    true_derivatives: bool
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def n_platforms(self) -> int:
        """N."""
        return self.jacobi.n_platforms


def build_system(scenario: FieldReplayScenario, scenario_path: Path) -> ReplaySystem:
    """Build the closed loop of ``scenario``; referenced files are read (or solved) here, before any output.

    Raises
    ------
    ConfigError
        A referenced file is missing or invalid, or the reference does not cover the duration.
    """
    noise = scenario.filter.noise
    jacobi = JacobiTransform(scenario.platforms.count)
    shape, info = build_shape_task(scenario.formation, jacobi, noise, scenario_path)
    motion = scenario.motion
    if isinstance(motion, LevelCurveMotion):
        level = LEVEL_FUNCTIONS[motion.level_function.kind](motion.level, motion.level_function.gain)
        controller = LevelCurveController(level, motion.speed, motion.speed_gain, motion.steering_gain)
        center: CenterLevelCurve | CenterTracking = CenterLevelCurve(controller)
    elif isinstance(motion, ReferenceMotion):
        solution, note = load_or_solve(
            resolve(scenario_path, motion.solution), resolve(scenario_path, motion.problem)
        )
        info["reference"] = note
        if motion.sensor >= solution.problem.N:
            raise ConfigError(
                f"{scenario_path}: motion.sensor: expected < {solution.problem.N} (sensors in the solution)"
            )
        horizon = solution.t[-1] - solution.t[0]
        if scenario.duration > horizon * (1 + 1e-9):
            raise ConfigError(
                f"{scenario_path}: duration: expected <= the solution's horizon {horizon:g}, "
                f"got {scenario.duration:g}"
            )
        i = [motion.sensor]
        reference = ReferenceTrajectory(
            solution.t, solution.p[:, i], solution.v[:, i], solution.t_u, solution.u[:, i]
        )
        center = CenterTracking(reference, motion.build(), float(solution.t[0]))
    else:
        raise TypeError(f"motion: unsupported kind {type(motion).__name__}")
    spatial = None if scenario.spatial_noise is None else scenario.spatial_noise.to_noise()
    field_ = scenario.field.build()
    f = scenario.filter
    estimator = ClosedLoopEstimator(
        noise.to_noise(), spatial, f.hessian, field_, f.window, f.hessian_smoothing, f.hessian_warmup,
        f.hessian_relative_error, f.estimator, f.fit_window,
    )
    limits = PlatformLimits(scenario.platforms.max_force, scenario.platforms.max_speed)
    true_derivatives = isinstance(motion, LevelCurveMotion) and motion.derivatives == "true_field"
    return ReplaySystem(scenario, field_, jacobi, limits, shape, center, estimator, true_derivatives, info)


@dataclass
class ReplayRecord:
    """Everything at the K + 1 sample times (arrays with the time axis first).

    Attributes
    ----------
    t : (K+1,) ; r, v : (K+1, N, 2) ; measurements : (K+1, N)
    z_true, z_est : (K+1,) ; grad_true, grad_est : (K+1, 2) ; hess_true, hess_est : (K+1, 2, 2)
    covariance : (K+1, 3, 3) posterior P ; a_desired, b_desired : (K+1,) ; q_desired : (K+1, N−1, 2)
    extra : (K+1, n_extra) ; reference : (K+1, 2) or None
    spatial_noise : callable or None
        The sample function ``w(points (M, 2)) -> (M,)`` of the spatial noise drawn for this run (None without
        spatial noise), e.g. to draw the noisy level curve ``z + w = C``.
    """

    t: list = field(default_factory=list)
    r: list = field(default_factory=list)
    v: list = field(default_factory=list)
    measurements: list = field(default_factory=list)
    z_true: list = field(default_factory=list)
    z_est: list = field(default_factory=list)
    grad_true: list = field(default_factory=list)
    grad_est: list = field(default_factory=list)
    hess_true: list = field(default_factory=list)
    hess_est: list = field(default_factory=list)
    covariance: list = field(default_factory=list)
    a_desired: list = field(default_factory=list)
    b_desired: list = field(default_factory=list)
    q_desired: list = field(default_factory=list)
    extra: list = field(default_factory=list)
    reference: Any = None
    spatial_noise: Any = None
    meta: dict[str, Any] = field(default_factory=dict)

    def arrays(self) -> dict[str, np.ndarray]:
        """The recorded lists stacked into arrays."""
        names = [k for k, v in vars(self).items() if isinstance(v, list)]
        return {k: np.asarray(getattr(self, k), dtype=float) for k in names}


class _Loop:
    """Right-hand side and measurement model of one replay."""

    def __init__(self, system: ReplaySystem, rng: np.random.Generator) -> None:
        s = system.scenario
        self.system, self.rng = system, rng
        self.N = system.n_platforms
        spatial = s.spatial_noise
        self.w = None if spatial is None else spatial.to_noise().realisation(rng)
        self.sigma = s.filter.noise.sigma_measurement
        self.knowledge = TrueField(system.field) if system.true_derivatives else system.estimator

    def split(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        N = self.N
        return y[: 2 * N].reshape(N, 2), y[2 * N : 4 * N].reshape(N, 2), y[4 * N :]

    def commands(self, t: float, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Centre acceleration, shape forces, extra rates and the Jacobi vectors at state ``y``."""
        sys = self.system
        r, v, extra = self.split(y)
        rc, q = sys.jacobi.to_jacobi(r)
        vc, dq = sys.jacobi.to_jacobi(v)
        z, g, H = self.knowledge.derivatives(rc, t)
        a_c = sys.center(t, rc, vc, z, g, H)  # docs/theory/level_curve.md §4 (or reference tracking)
        u, extra_rates = sys.shape.forces(t, q, dq, vc, a_c, extra)  # docs/theory/formation_control.md §2–§4
        return a_c, u, extra_rates, q

    def rhs(self, t: float, y: np.ndarray) -> np.ndarray:
        """``y' = (v, f, extra')`` with ``f = [N a_c, u] Ψ^T`` limited."""
        _, v, _ = self.split(y)
        a_c, u, extra_rates, _ = self.commands(t, y)
        forces = self.system.jacobi.forces_from_jacobi(self.N * a_c, u)  # eq. formation_control.5
        out = np.concatenate([newton_rates(v, forces, self.system.limits), extra_rates])
        if not np.all(np.isfinite(out)):
            raise ReplayError(f"the closed loop became singular at t = {t:.6g} (centre at rest or ∇z = 0)")
        return out

    def measure(self, r: np.ndarray) -> np.ndarray:
        """``p_i = z(r_i) + w(r_i) + n_i`` (docs/theory/cooperative.md, eq. cooperative.1)."""
        p = self.system.field.value(r) + self.sigma * self.rng.standard_normal(self.N)
        return p if self.w is None else p + self.w(r)


def _initial_state(system: ReplaySystem, rng: np.random.Generator) -> np.ndarray:
    init = system.scenario.platforms.initial
    center, velocity = np.asarray(init.center, float), np.asarray(init.velocity, float)
    angle = init.angle if init.angle is not None else float(np.arctan2(velocity[1], velocity[0]))
    body = system.shape.offsets
    offsets = (rotation(angle) @ body[..., None])[..., 0]
    r = center + offsets + init.perturbation * rng.standard_normal(offsets.shape)
    r = r - formation_center(r) + center  # the perturbation changes the shape, not the centre
    v = velocity + system.shape.initial_velocities(offsets)
    return np.concatenate([r.ravel(), v.ravel(), system.shape.initial_extra(angle)])


def _start_estimator(system: ReplaySystem, loop: _Loop, r: np.ndarray, rng: np.random.Generator) -> None:
    f = system.scenario.filter
    rc = formation_center(r)
    truth = np.concatenate([[system.field.value(rc)], system.field.gradient(rc)])
    P0 = np.diag([f.initial_std[0] ** 2, f.initial_std[1] ** 2, f.initial_std[1] ** 2])
    s0 = truth + np.sqrt(np.diag(P0)) * rng.standard_normal(3)  # the first estimate is a draw from the prior
    H0 = system.field.hessian(rc) if f.initial_hessian == "true_field" else np.zeros((2, 2))
    system.estimator.start(r, loop.measure(r), s0, P0, H0)


def _adapt_shape(system: ReplaySystem, y: np.ndarray, k: int) -> None:
    """Step 3A every ``every`` samples: the ``(a, b)`` minimising ``J`` at the next sample.

    The formation cannot jump, so the shape chosen now serves the next measurement, whose prior is predicted as
    ``P_k(+) + M`` (``A ≈ I`` over one step along a level curve, docs/theory/steady_state.md §1;
    docs/theory/replay.md §2.4).
    """
    from ...estimation.cooperative.formation_design import adaptive_shape_step
    from ...estimation.cooperative.information_model import cross_formation

    shape_cfg = getattr(system.scenario.formation, "shape", None)
    adaptive = None if shape_cfg is None else shape_cfg.adaptive
    if adaptive is None or k % adaptive.every:
        return
    vc = system.jacobi.to_jacobi(y[2 * system.n_platforms : 4 * system.n_platforms].reshape(-1, 2))[0]
    P = system.estimator.covariance + system.estimator.base_noise.process
    offsets = system.shape.offsets
    current = 0.5 * np.linalg.norm(offsets[1] - offsets[0]), 0.5 * np.linalg.norm(offsets[2] - offsets[3])
    box = tuple(
        (max(lo, c - adaptive.max_change), min(hi, c + adaptive.max_change))
        for (lo, hi), c in zip(adaptive.bounds.pairs(), current, strict=True)
    )  # trust region around the current shape
    design = adaptive_shape_step(
        P, system.estimator.design_noise(), box, system.shape.angle(vc), adaptive.equal_sides
    )  # U_k of the current Hessian estimate (constant σ3² I unless filter.hessian_relative_error > 0)
    system.shape.set_offsets(cross_formation(*design.x))


def _record(rec: ReplayRecord, system: ReplaySystem, loop: _Loop, t: float, y: np.ndarray) -> None:
    r, v, extra = loop.split(y)
    rc = formation_center(r)
    est = system.estimator
    vc = system.jacobi.to_jacobi(v)[0]
    a_c, _, _, _ = loop.commands(t, y)
    q_d = system.shape.desired(vc, a_c, extra)[0]
    offsets = system.shape.offsets
    values = {
        "t": t, "r": r, "v": v, "measurements": est.last_measurements, "z_true": system.field.value(rc),
        "grad_true": system.field.gradient(rc), "hess_true": system.field.hessian(rc), "z_est": est.state[0],
        "grad_est": est.state[1:], "hess_est": est.hessian, "covariance": est.covariance,
        "a_desired": 0.5 * np.linalg.norm(offsets[1] - offsets[0]),
        "b_desired": 0.5 * np.linalg.norm(offsets[2] - offsets[3]) if len(offsets) >= 4 else np.nan,
        "q_desired": q_d, "extra": extra,
    }  # fmt: skip
    for key, value in values.items():
        getattr(rec, key).append(np.array(value, dtype=float))


def simulate(system: ReplaySystem, seed: int | None = None, progress: bool = False) -> ReplayRecord:
    """Run the closed loop of ``system`` over the scenario's duration.

    Parameters
    ----------
    system : ReplaySystem
        From :func:`build_system`.
    seed : int, optional
        Overrides the scenario's seed (noise realisation, measurement noise, initial estimate).
    progress : bool
        Show a ``rich`` progress bar.

    Returns
    -------
    ReplayRecord

    Raises
    ------
    ReplayError
        Singular closed loop or integrator failure.
    """
    from scipy.integrate import solve_ivp

    s = system.scenario
    rng = np.random.default_rng(s.seed if seed is None else seed)
    loop = _Loop(system, rng)
    steps = int(round(s.duration / s.time_step))
    times = np.linspace(0.0, s.duration, steps + 1)
    y = _initial_state(system, rng)
    _start_estimator(system, loop, loop.split(y)[0], rng)
    rec = ReplayRecord(spatial_noise=loop.w)
    scale = max(1.0, float(np.abs(y[: 2 * loop.N]).max()))
    atol = np.concatenate([np.full(4 * loop.N, 1e-9 * scale), np.full(len(y) - 4 * loop.N, 1e-9)])
    started = time.perf_counter()
    bar = _progress(progress, steps, s.name)
    for k in range(steps + 1):
        raise_if_interrupted()  # a Ctrl-C that arrived inside CasADi code (field, estimator) was only recorded
        _adapt_shape(system, y, k)
        _record(rec, system, loop, times[k], y)
        if k == steps:
            break
        sol = solve_ivp(_bounded(loop.rhs, times[k]), (times[k], times[k + 1]), y, rtol=1e-7, atol=atol)
        if not sol.success:
            raise ReplayError(f"integration failed at t = {times[k]:.6g}: {sol.message}")
        y = sol.y[:, -1]
        r = loop.split(y)[0]
        system.estimator.step(r, loop.measure(r))
        if bar is not None:
            bar[0].advance(bar[1])
    if bar is not None:
        bar[0].stop()
    if isinstance(system.center, CenterTracking):
        rec.reference = system.center.position(times)
    rec.meta = {"wall_time_s": time.perf_counter() - started, "steps": steps, **system.info}
    return rec


#: the most evaluations of the closed loop's right-hand side within one filter period: the shipped replays take at
#: most 20–38 (RK45, rtol 1e-7, measured); gains of 1e12 (a fuzzer's) made the loop so stiff that a period took
#: minutes — now stopped after ≈ 3 s
MAX_EVALUATIONS_PER_PERIOD = 20_000


def _bounded(rhs: Any, start: float) -> Any:
    """``rhs`` raising :class:`ReplayError` once called more than :data:`MAX_EVALUATIONS_PER_PERIOD` times."""

    def too_stiff(t: float) -> ReplayError:
        return ReplayError(
            f"the closed loop is too stiff to integrate: more than {MAX_EVALUATIONS_PER_PERIOD} evaluations "
            f"within the filter period from t = {start:.6g} (reached t = {t:.6g}); lower the gains of the "
            "formation or the motion, or the time step"
        )

    return bounded_rhs(rhs, MAX_EVALUATIONS_PER_PERIOD, too_stiff)


def _progress(enabled: bool, total: int, name: str) -> tuple[Any, Any] | None:
    if not enabled:
        return None
    from rich.progress import Progress

    bar = Progress(transient=True)
    task = bar.add_task(f"replay {name}", total=total)
    bar.start()
    return bar, task
