"""Re-planning under a current and force noise: shrinking or receding horizon (docs/theory/path_constraints.md §5).

The platforms fly ``p' = v + c``, ``v' = u + w`` (a constant current ``c`` the plan does not know, white
force noise ``w`` of standard deviation ``force_noise_std`` per axis, Euler–Maruyama with ``time_step``);
the filter's covariance follows the Riccati equation along the *flown* positions. Open loop flies the
first plan's control (past a receding plan's window: u = 0); closed loop re-solves the problem every
``every`` time units from the measured state and the filter's current Σ over the window of
:class:`~mobisense.ocp.replan_window.Replanner` (shrinking ``[t, tf]`` or receding ``[t, min(t + L, tf)]``),
warm-started from the previous plan shifted onto the new grid; no control flies ``u = 0``. The realised
cost is ``Tr[M Σ(tf)] + ∫ (α/2|u|² + Tr[KΣ]) dt``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..core.config import parse_config
from .model import SensorKalmanModel, Structure
from .path_constraints import margins
from .problem import Problem
from .replan_inputs import DisturbanceArguments, check_replan_arguments
from .replan_window import Replanner, ReplanRecord
from .solving import as_problem

__all__ = [
    "Disturbance",
    "FlightResult",
    "MAX_RK4_SUBSTEPS",
    "implicit_riccati_step",
    "riccati_step",
    "fly",
    "PlanFailed",
    "replan_monte_carlo",
]


@dataclass(frozen=True)
class Disturbance:
    """A constant current ``drift`` (L/T, shape (2,)) and white force noise, ``force_noise_std`` per axis (L/T^1.5).

    Raises ``ConfigError`` (``Disturbance: drift[0]: expected a finite number, got nan``) for a current that is not
    two finite numbers or a noise level that is not a finite number ≥ 0.
    """

    drift: tuple[float, float] = (0.0, 0.0)
    force_noise_std: float = 0.0

    def __post_init__(self) -> None:
        data = {"drift": self.drift, "force_noise_std": self.force_noise_std}
        checked = parse_config(data, DisturbanceArguments, source="Disturbance")
        object.__setattr__(self, "drift", tuple(checked.drift))
        object.__setattr__(self, "force_noise_std", checked.force_noise_std)


@dataclass
class FlightResult:
    """One flight: times (T,), positions and velocities (T, N, 2), Σ (T, n, n), realised cost, plans, re-solves.

    ``plans``: (instant, times (S,), positions (S, N, 2)) of each plan, sampled at ``PLAN_SAMPLES`` points.
    """

    t: np.ndarray
    p: np.ndarray
    Sigma: np.ndarray
    cost: float
    v: np.ndarray
    plans: list[tuple[float, np.ndarray, np.ndarray]] = field(default_factory=list)
    records: list[ReplanRecord] = field(default_factory=list)

    @property
    def solve_times(self) -> list[float]:
        """Wall time of each re-solve (s)."""
        return [r.time_s for r in self.records]


#: points at which each plan is stored (uniform over its window)
PLAN_SAMPLES = 101


def _plan_record(t: float, plan: Any) -> tuple[float, np.ndarray, np.ndarray]:
    times = np.linspace(float(plan.t[0]), float(plan.t[-1]), PLAN_SAMPLES)
    return t, times, plan.sample(times).p


#: RK4 substeps of a flight step at most; a stiffer step is taken by :func:`implicit_riccati_step`
MAX_RK4_SUBSTEPS = 16


def implicit_riccati_step(A: np.ndarray, W: np.ndarray, Sigma: np.ndarray, S: np.ndarray, dt: float) -> np.ndarray:
    """Σ(t + dt) by one implicit (backward) Euler step of the Riccati equation, for any stiffness.

    Σ₁ = Σ₀ + dt (AΣ₁ + Σ₁A' + W − Σ₁SΣ₁) is the algebraic Riccati equation
    (A − I/2dt)Σ₁ + Σ₁(A − I/2dt)' − Σ₁ S Σ₁ + W + Σ₀/dt = 0, whose stabilising solution (scipy's
    ``solve_continuous_are`` with S = LL', L its symmetric square root) is symmetric positive definite and, as
    dt·‖ΣS‖ → ∞, the steady state under S: first order in dt, L-stable.

    Parameters
    ----------
    A, W, Sigma, S : ndarray, shape (n, n)
        Process matrix (1/T), noise intensity (state²/T), Σ(t) (state²), information C'R⁻¹C at t + dt.
    dt : float
        Step (T).
    """
    from scipy.linalg import solve_continuous_are

    n = len(Sigma)
    values, vectors = np.linalg.eigh(0.5 * (S + S.T))
    root = (vectors * np.sqrt(np.clip(values, 0.0, None))) @ vectors.T
    shifted = A.T - np.eye(n) / (2.0 * dt)
    out = solve_continuous_are(shifted, root, W + Sigma / dt, np.eye(n))
    return 0.5 * (out + out.T)


def riccati_step(A: np.ndarray, W: np.ndarray, Sigma: np.ndarray, infos: list[np.ndarray], dt: float) -> np.ndarray:
    """Σ(t + dt) of Σ' = AΣ + ΣA' + W − Σ S(t) Σ by RK4 on its linear (Möbius) form.

    With Σ = X Y⁻¹: X' = AX + WY, Y' = S X − A'Y, X(0) = Σ, Y(0) = I (exact for the Riccati flow). The linear
    system's rates are bounded by ρ = ‖A‖ + sqrt(‖W‖ ‖S‖) (the Hamiltonian scaled by diag(αI, I)), about the
    square root of the Riccati equation's stiffness 2‖ΣS‖, and the step is cut into ⌈ρ dt⌉ RK4 substeps
    (one when ρ dt ≤ 1, as on the shipped problems). Explicit Runge–Kutta on Σ itself overflowed to NaN within a
    few steps when precise sensors met a large Σ; this stays positive definite. One substep is O(dt⁴) accurate
    with the three given S; several interpolate S linearly between them (O(dt²) in S's change, stable). Beyond
    :data:`MAX_RK4_SUBSTEPS` the step is :func:`implicit_riccati_step` (first order, any stiffness).

    Parameters
    ----------
    A, W : ndarray, shape (n, n)
        Process matrix (1/T) and noise intensity BQB' (state²/T).
    Sigma : ndarray, shape (n, n)
        Σ(t) (state²).
    infos : list of three ndarray, shape (n, n)
        The measurements' information C'R⁻¹C at t, t + dt/2, t + dt (1/(state² T)).
    dt : float
        Step (T).
    """
    norm_S = max(float(np.linalg.norm(S)) for S in infos)
    rate = float(np.linalg.norm(A)) + float(np.sqrt(np.linalg.norm(W) * norm_S))
    substeps = max(1, int(np.ceil(rate * dt)))
    if substeps > MAX_RK4_SUBSTEPS:  # stiffer still: one L-stable step, whatever the stiffness
        return implicit_riccati_step(A, W, Sigma, infos[2], dt)
    h = dt / substeps

    def info(tau: float) -> np.ndarray:  # S at fraction tau of the step
        if substeps == 1:
            return infos[round(2 * tau)]
        k, frac = (0, 2 * tau) if tau <= 0.5 else (1, 2 * tau - 1)
        return (1 - frac) * infos[k] + frac * infos[k + 1]

    def rates(X: np.ndarray, Y: np.ndarray, S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return A @ X + W @ Y, S @ X - A.T @ Y

    X, Y = Sigma, np.eye(len(Sigma))
    for j in range(substeps):
        S0, S1, S2 = (info((j + c) / substeps) for c in (0.0, 0.5, 1.0))
        kx1, ky1 = rates(X, Y, S0)
        kx2, ky2 = rates(X + 0.5 * h * kx1, Y + 0.5 * h * ky1, S1)
        kx3, ky3 = rates(X + 0.5 * h * kx2, Y + 0.5 * h * ky2, S1)
        kx4, ky4 = rates(X + h * kx3, Y + h * ky3, S2)
        X = X + h / 6 * (kx1 + 2 * kx2 + 2 * kx3 + kx4)
        Y = Y + h / 6 * (ky1 + 2 * ky2 + 2 * ky3 + ky4)
        X = np.linalg.solve(Y.T, X.T).T  # back to Σ = X Y⁻¹ (Y = I) after each substep: no growth carried
        Y = np.eye(len(Sigma))
    return 0.5 * (X + X.T)


def fly(
    problem: Problem,
    plan: Any,
    disturbance: Disturbance,
    rng: np.random.Generator,
    time_step: float,
    every: float | None = None,
    control: bool = True,
    replanner: Replanner | None = None,
) -> FlightResult:
    """Fly ``plan`` (a direct or field-shooting :class:`~mobisense.ocp.solution.Solution`) under ``disturbance``.

    ``every``: re-plan period (None: open loop) with ``replanner`` (default: shrinking horizon, shifted warm
    starts); ``control=False`` flies u = 0.
    """
    if every is not None and replanner is None:
        replanner = Replanner(problem)
    model = SensorKalmanModel(Structure.of(problem))
    values = model.layout.values(problem)
    P = model.layout.pack(values)
    mats = problem.matrices()
    A, BQB, M, Kc, alpha = mats["A"], mats["BQB"], mats["M"], mats["K"], problem.cost.alpha
    n, N = problem.n, problem.N
    t0, tf = problem.horizon.t0, problem.horizon.tf
    steps = int(round((tf - t0) / time_step))
    dt = (tf - t0) / steps
    p = np.array([s.p0 for s in problem.sensors], float)
    v = np.array([s.v0 for s in problem.sensors], float)
    Sigma = mats["Sigma0"].copy()
    drift = np.asarray(disturbance.drift, float)
    shape = (steps + 1, N, 2)
    result = FlightResult(np.empty(steps + 1), np.empty(shape), np.empty((steps + 1, n, n)), 0.0, np.empty(shape))
    result.plans.append(_plan_record(t0, plan))
    next_replan = t0 + every if every else np.inf
    running = 0.0
    grid = t0 + dt * np.arange(steps + 1)

    def controls(solution: Any, j: int) -> np.ndarray:
        """The plan's control at the grid times from step j on (sampled once per plan; 0 past its end), (T-j, N, 2)."""
        times = grid[j:]
        if not control:
            return np.zeros((len(times), N, 2))
        u = solution.sample(np.clip(times, solution.t[0], solution.t[-1])).u
        u[times > solution.t[-1] + 1e-9 * (tf - t0)] = 0.0
        return u

    u_plan, j_plan = controls(plan, 0), 0

    def information(pos: np.ndarray) -> np.ndarray:
        return np.asarray(model.information(pos.ravel(), P)).reshape(n, n)

    for j in range(steps + 1):
        t = t0 + j * dt
        result.t[j], result.p[j], result.v[j], result.Sigma[j] = t, p, v, Sigma
        if j == steps:
            break
        if replanner is not None and t >= next_replan - 1e-9 and tf - t > 2 * dt:
            new = replanner.solve(plan, t, p, v, Sigma)
            result.records.append(replanner.records[-1])
            if replanner.records[-1].flown:
                plan = new
                result.plans.append(_plan_record(t, new))
                u_plan, j_plan = controls(plan, j), j
            next_replan += every  # type: ignore[operator]
        u = u_plan[j - j_plan]
        # Σ by the Möbius-RK4 step along the straight step of the positions; Euler–Maruyama for the platforms
        w = disturbance.force_noise_std * np.sqrt(dt) * rng.standard_normal((N, 2))
        p_next = p + dt * (v + drift)
        Sigma_next = riccati_step(A, BQB, Sigma, [information(q) for q in (p, 0.5 * (p + p_next), p_next)], dt)
        trace_K = 0.5 * (np.trace(Kc @ Sigma) + np.trace(Kc @ Sigma_next))
        running += dt * (0.5 * alpha * float(np.sum(u**2)) + trace_K)
        Sigma = Sigma_next
        v = v + dt * u + w
        p = p_next
    result.cost = float(np.trace(M @ Sigma)) + running
    return result


class PlanFailed(RuntimeError):
    """The plan a re-planning flight starts from failed: nothing is flown; ``solution`` is what was solved."""

    def __init__(self, what: str, solution: Any) -> None:
        super().__init__(f"{what} failed: {solution.message}")
        self.what, self.solution = what, solution


def replan_monte_carlo(
    problem: Problem | str | Path,
    disturbance: Disturbance,
    runs: int,
    every: float,
    time_step: float,
    seed: int = 1,
    length: float | None = None,
    warm_start: str = "shifted",
    progress: Any = None,
    *,
    max_memory: int | None = None,
    max_time: float | None = None,
) -> dict[str, Any]:
    """Closed loop vs open loop vs no control over ``runs`` flights with the same noise draws.

    Parameters
    ----------
    problem : Problem, str or Path
        The problem, or the path of its YAML file (or a shipped example's name).
    length : float, optional
        Receding-horizon length L (T), ``every ≤ length ≤ tf − t0``; None: shrinking horizon.
    warm_start : {"shifted", "reused", "cold"}
        How each re-solve starts (:mod:`mobisense.ocp.replan_window`).
    progress : callable, optional
        Called with the number of runs done after each run.
    max_memory, max_time : float, optional
        The budget checked before anything runs (bytes, default half of the RAM; seconds of a lower estimate of
        the computing time, default one hour), as ``mobisense replay``'s ``--max-memory`` and ``--max-time``.

    Returns
    -------
    dict
        ``closed_loop``, ``open_loop``, ``no_control``: ``{cost_mean, cost_std, cost_stderr}``;
        ``replan_solve_time_s``: ``{median, max}``; ``replan_iterations``: ``{median, max}``;
        ``replan_every_s``; ``horizon``; ``plan_cost`` (the full-horizon plan's optimal cost); ``flights``
        (closed loop); ``replan_relaxed`` (re-solves that relaxed a constraint the measured state violated) and
        ``replan_relaxation_max`` (group -> largest such violation); with path constraints
        ``flown_violation``: policy -> group -> the largest violation along the flown paths of all runs
        (physical units, ≤ 0: held).

    The open loop flies the full-horizon plan whatever the horizon of the closed loop: it is what would be
    flown without re-planning, and for a receding horizon the benchmark the windows are measured against.

    Raises ``TypeError`` for a ``problem`` or ``disturbance`` of another type, ``ConfigError`` for arguments
    outside the rules of a ``kind: replan`` file (:mod:`mobisense.ocp.replan_inputs`) or work beyond the
    budget, before anything is solved or allocated.
    """
    problem = as_problem(problem, "replan_monte_carlo")
    if not isinstance(disturbance, Disturbance):
        raise TypeError(f"replan_monte_carlo: disturbance: expected a Disturbance, got {type(disturbance).__name__}")
    if progress is not None and not callable(progress):
        raise TypeError(f"replan_monte_carlo: progress: expected a callable, got {type(progress).__name__}")
    check_replan_arguments(problem, PLAN_SAMPLES, (max_memory, max_time), runs=runs, every=every,
                           time_step=time_step, seed=seed, length=length, warm_start=warm_start)  # fmt: skip
    replanner = Replanner(problem, length, warm_start)  # type: ignore[arg-type]
    h = problem.horizon
    build_time = replanner.prepare(np.arange(h.t0 + every, h.tf - 2 * time_step, every))
    full = replanner.solved(problem)
    plan = full if replanner.window(h.t0)[0] >= h.tf else replanner.first_plan()
    for what, solution in (("the full-horizon plan", full), ("the first window's plan", plan)):
        if not solution.success:
            raise PlanFailed(what, solution)
    costs: dict[str, list[float]] = {"closed_loop": [], "open_loop": [], "no_control": []}
    violations: dict[str, dict[str, float]] = {name: {} for name in costs}
    flights = []
    for r in range(runs):
        for name, kwargs in (
            ("closed_loop", {"every": every, "replanner": replanner}),
            ("open_loop", {}),
            ("no_control", {"control": False}),
        ):
            rng = np.random.default_rng([seed, r])  # the same draws for the three policies
            flight = fly(problem, plan if name == "closed_loop" else full, disturbance, rng, time_step, **kwargs)
            costs[name].append(flight.cost)
            if problem.constraints is not None:
                for group, margin in margins(problem.constraints, flight.p, flight.v).items():
                    violations[name][group] = max(violations[name].get(group, -np.inf), float(margin.max()))
            if name == "closed_loop":
                flights.append(flight)
        if progress is not None:
            progress(r + 1)
    out: dict[str, Any] = {
        name: {
            "cost_mean": float(np.mean(c)),
            "cost_std": float(np.std(c, ddof=1)) if len(c) > 1 else 0.0,
            "cost_stderr": float(np.std(c, ddof=1) / np.sqrt(len(c))) if len(c) > 1 else 0.0,
        }
        for name, c in costs.items()
    }
    records = replanner.records
    for key, values in (
        ("replan_solve_time_s", [x.time_s for x in records]),
        ("replan_iterations", [x.iterations for x in records]),
    ):
        out[key] = {"median": float(np.median(values)), "max": float(np.max(values))} if values else {}
    out["replan_build_time_s"] = build_time
    out["replan_failures"] = sum(not x.success for x in records)
    out["replan_flown_unconverged"] = sum(x.flown_unconverged for x in records)
    out["replan_relaxed"] = sum(bool(x.relaxed) for x in records)
    out["replan_relaxation_max"] = {
        group: max(x.relaxed[group] for x in records if group in x.relaxed)
        for group in sorted({g for x in records for g in x.relaxed})
    }
    if problem.constraints is not None:
        out["flown_violation"] = violations
    out["replan_every_s"] = every
    out["horizon"] = {"kind": "shrinking"} if length is None else {"kind": "receding", "length": length}
    out["warm_start"] = warm_start
    out["plan_cost"] = full.cost
    out["flights"] = flights
    return out
