"""Shrinking-horizon re-planning under a current and force noise (docs/theory/path_constraints.md §5).

The platforms fly ``p' = v + c``, ``v' = u + w`` (a constant current ``c`` the plan does not know, white
force noise ``w`` of standard deviation ``force_noise_std`` per axis, Euler–Maruyama with ``time_step``);
the filter's covariance follows the Riccati equation along the *flown* positions. Open loop flies the
first plan's control; closed loop re-solves the problem every ``every`` time units from the measured
state and the filter's current Σ over the remaining horizon, warm-started from the previous solution
(same number of intervals, primal–dual point re-scaled, :func:`~mobisense.ocp.direct.solver.solve_direct`);
no control flies ``u = 0``. The realised cost is ``Tr[M Σ(tf)] + ∫ (α/2|u|² + Tr[KΣ]) dt``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .model import SensorKalmanModel, Structure
from .problem import Problem

__all__ = ["Disturbance", "FlightResult", "fly", "replan_monte_carlo"]


@dataclass(frozen=True)
class Disturbance:
    """A constant current ``drift`` (L/T, shape (2,)) and white force noise, ``force_noise_std`` per axis (L/T^1.5)."""

    drift: tuple[float, float] = (0.0, 0.0)
    force_noise_std: float = 0.0


@dataclass
class FlightResult:
    """One flight: times (T,), positions (T, N, 2), Σ (T, n, n), realised cost, plans made, re-solve times."""

    t: np.ndarray
    p: np.ndarray
    Sigma: np.ndarray
    cost: float
    plans: list[tuple[float, np.ndarray]] = field(default_factory=list)
    solve_times: list[float] = field(default_factory=list)


def _sub_problem(problem: Problem, t: float, p: np.ndarray, v: np.ndarray, Sigma: np.ndarray) -> Problem:
    data = problem.normalised()
    data["horizon"]["t0"] = float(t)
    data["process"]["Sigma0"] = (0.5 * (Sigma + Sigma.T)).tolist()
    for i, sensor in enumerate(data["sensors"]):
        sensor["p0"], sensor["v0"] = p[i].tolist(), v[i].tolist()
    data["solver"]["strategy"] = "cold"
    return Problem.from_dict(data, source="<re-plan>")


def fly(
    problem: Problem,
    plan: Any,
    disturbance: Disturbance,
    rng: np.random.Generator,
    time_step: float,
    every: float | None = None,
    control: bool = True,
) -> FlightResult:
    """Fly ``plan`` (a direct :class:`~mobisense.ocp.solution.Solution`) under ``disturbance``.

    ``every``: re-plan period (None: open loop); ``control=False`` flies u = 0.
    """
    from .direct.solver import solve_direct

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
    result = FlightResult(np.empty(steps + 1), np.empty((steps + 1, N, 2)), np.empty((steps + 1, n, n)), 0.0)
    result.plans.append((t0, plan.p.copy()))
    next_replan = t0 + every if every else np.inf
    running = 0.0
    grid = t0 + dt * np.arange(steps + 1)

    def controls(solution: Any, j: int) -> np.ndarray:
        """The plan's control at the grid times from step j on (sampled once per plan), (T - j, N, 2)."""
        times = np.clip(grid[j:], solution.t[0], solution.t[-1])
        return solution.sample(times).u if control else np.zeros((len(times), N, 2))

    u_plan, j_plan = controls(plan, 0), 0

    def sigma_dot(S: np.ndarray, pos: np.ndarray) -> np.ndarray:
        info = np.asarray(model.information(pos.ravel(), P)).reshape(n, n)
        return A @ S + S @ A.T + BQB - S @ info @ S

    for j in range(steps + 1):
        t = t0 + j * dt
        result.t[j], result.p[j], result.Sigma[j] = t, p, Sigma
        if j == steps:
            break
        if t >= next_replan - 1e-9 and tf - t > 2 * dt:
            sub = _sub_problem(problem, t, p, v, Sigma)
            start = time.perf_counter()
            new = solve_direct(sub, init=plan)
            result.solve_times.append(time.perf_counter() - start)
            if new.success:
                plan = new
                result.plans.append((t, new.p.copy()))
                u_plan, j_plan = controls(plan, j), j
            next_replan += every  # type: ignore[operator]
        u = u_plan[j - j_plan]
        # RK2 (Heun) for Σ along the straight step of the positions; Euler–Maruyama for the platforms
        w = disturbance.force_noise_std * np.sqrt(dt) * rng.standard_normal((N, 2))
        p_next = p + dt * (v + drift)
        k1 = sigma_dot(Sigma, p)
        k2 = sigma_dot(Sigma + dt * k1, p_next)
        trace_K = 0.5 * (np.trace(Kc @ Sigma) + np.trace(Kc @ (Sigma + dt * k1)))
        running += dt * (0.5 * alpha * float(np.sum(u**2)) + trace_K)
        Sigma = Sigma + 0.5 * dt * (k1 + k2)
        v = v + dt * u + w
        p = p_next
    result.cost = float(np.trace(M @ Sigma)) + running
    return result


def replan_monte_carlo(
    problem: Problem,
    disturbance: Disturbance,
    runs: int,
    every: float,
    time_step: float,
    seed: int = 1,
) -> dict[str, Any]:
    """Closed loop vs open loop vs no control over ``runs`` flights with the same noise draws.

    Returns
    -------
    dict
        ``closed_loop``, ``open_loop``, ``no_control``: ``{cost_mean, cost_std, cost_stderr}``;
        ``replan_solve_time_s``: ``{median, max}``; ``replan_every_s``; ``plan_cost``; ``flights`` (closed loop).
    """
    from .direct.solver import solve_direct

    plan = solve_direct(problem)
    if not plan.success:
        raise RuntimeError(f"the first plan failed: {plan.message}")
    costs: dict[str, list[float]] = {"closed_loop": [], "open_loop": [], "no_control": []}
    times: list[float] = []
    flights = []
    for r in range(runs):
        for name, kwargs in (
            ("closed_loop", {"every": every}),
            ("open_loop", {}),
            ("no_control", {"control": False}),
        ):
            rng = np.random.default_rng([seed, r])  # the same draws for the three policies
            flight = fly(problem, plan, disturbance, rng, time_step, **kwargs)
            costs[name].append(flight.cost)
            if name == "closed_loop":
                times += flight.solve_times
                flights.append(flight)
    out: dict[str, Any] = {
        name: {
            "cost_mean": float(np.mean(c)),
            "cost_std": float(np.std(c, ddof=1)) if len(c) > 1 else 0.0,
            "cost_stderr": float(np.std(c, ddof=1) / np.sqrt(len(c))) if len(c) > 1 else 0.0,
        }
        for name, c in costs.items()
    }
    out["replan_solve_time_s"] = {"median": float(np.median(times)), "max": float(np.max(times))} if times else {}
    out["replan_every_s"] = every
    out["plan_cost"] = plan.cost
    out["flights"] = flights
    return out
