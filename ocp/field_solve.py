"""``solver.method: shooting``: the mesh-sequenced ε-homotopy of the reduced field NLP (docs/theory/field.md §3.4).

The geometric ε schedule runs on a coarse grid (``solver.shooting.coarse_intervals``, energy scaling, loose
tolerance, capped iterations: it only has to find the basin); one ε = 1 solve on the fine grid
(``intervals``, kinematic scaling, ``solver.tolerance``) starts from its interpolated controls.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ..core.config import ConfigError
from .field import COARSE_H_LAMBDA, FULL_SIGMA_STATES
from .field_constraints import shooting_constraint_report, shooting_control_report
from .problem import Problem
from .shooting import FieldShooting
from .solution import HomotopyStep, Solution, SolveStatus, StartKind

__all__ = ["solve_shooting"]

def _best_coarse_start(
    coarse: FieldShooting, homotopy: np.ndarray, cost_scale: float, problem: Problem,
    record: Callable[..., bool],
) -> tuple[np.ndarray, list[dict[str, Any]]]:  # fmt: skip
    """The coarse controls of lowest J among the homotopy's and ``solver.shooting.starts`` random ε = 1 starts.

    Random start k is ε = 1 from standard normal controls in the coarse grid's energy scaling (seed k): on small
    fields the homotopy's basin was 7–14 % above a random start's (docs/theory/field.md §3.4).
    """
    o, tol = problem.solver.shooting, problem.solver.tolerance
    if not o.starts:
        return homotopy, []
    J = float(sum(coarse.cost_terms(homotopy, coarse.parameters(1.0, cost_scale))[:2]))
    best, lowest, starts = homotopy, J, [{"start": "homotopy", "cost": J}]
    for k in range(1, o.starts + 1):
        t0 = time.perf_counter()
        w0 = np.random.default_rng(k).standard_normal(coarse.nw)
        w, info = coarse.solve(w0, 1.0, cost_scale, max(tol, o.homotopy_tolerance), o.coarse_max_iterations,
                               o.memory, problem.solver.time_limit)  # fmt: skip
        J = float(sum(coarse.cost_terms(w, coarse.parameters(1.0, cost_scale))[:2]))
        record(1.0, J, info, t0, f"random start {k} (coarse)")
        starts.append({"start": f"random start {k}", "cost": J, "status": info["status"]})
        if info["success"] and J < lowest:
            best, lowest = w, J
    for entry in starts:
        entry["kept"] = entry["cost"] == lowest
    return best, starts


def solve_shooting(
    problem: Problem,
    progress: Callable[[HomotopyStep], Any] | None = None,
    init: Solution | None = None,
) -> Solution:
    """Solve a field problem by reduced-space shooting (docs/theory/field.md §3).

    Parameters
    ----------
    problem : Problem
        With ``process.field`` and point sensors.
    progress : callable, optional
        Called with each :class:`HomotopyStep` (the coarse ε steps, then the fine ε = 1 solve).
    init : Solution, optional
        A solution of a problem with the same sensors and horizon: its controls start the fine ε = 1
        solve directly (no homotopy).

    Returns
    -------
    Solution
        Method ``shooting``; ``Sigma`` on the K+1 nodes, no costates; ``baseline`` holds the coasting
        cost and ``trace_Sigma_tf``; ``stats`` the build times, NLP size, substeps and Tr Σ(tf).
    """
    if problem.process.field is None:
        raise ConfigError("solver.method: expected process.field with method 'shooting'")
    started = time.perf_counter()
    o, tol = problem.solver.shooting, problem.solver.tolerance
    fine = FieldShooting(problem, o.intervals, o.substeps)
    zero = np.zeros(fine.nw)
    coast = fine.evaluate(zero)
    base_cost = coast.costs[0] + coast.costs[1]
    cost_scale = max(abs(base_cost), 1e-12)
    baseline = {"cost": base_cost, "terminal_cost": coast.costs[0], "running_cost": coast.costs[1],
                "trace_Sigma_tf": float(np.trace(coast.Sigma[-1])),
                "trace_Sigma": np.trace(coast.Sigma, axis1=1, axis2=2).tolist(),
                "sigma_diag_tf": np.diagonal(coast.Sigma[-1]).tolist()}  # fmt: skip
    steps: list[HomotopyStep] = []

    def record(eps: float, cost: float, info: dict[str, Any], t0: float, label: str = "") -> bool:
        step = HomotopyStep(eps, cost, info["iterations"], info["status"], time.perf_counter() - t0, info["success"],
                            label)  # fmt: skip
        steps.append(step)
        if progress is not None:
            progress(step)
        return step.success

    start = StartKind.WARM.value
    coarse_time = 0.0
    starts: list[dict[str, Any]] = []
    usable = init is not None and init.problem.N == problem.N
    init_unused = None
    if init is not None and not usable:
        init_unused = (f"init was not used: it has {init.problem.N} sensors, the problem {problem.N}; solved from the "
                       "coarse ε-homotopy as without it")  # fmt: skip
    if usable:
        w = fine.controls_to_w(init.t_u, init.u, cost_scale)
    else:
        start = StartKind.COARSE.value
        t_coarse = time.perf_counter()
        # without |u| ≤ u_max: the bound's rows, far from active, moved the coarse steps into another basin (a
        # 2 × 3 field with u_max = 5 where the unbounded optimum uses |u| ≤ 2: J 7.6008 against 6.3788,
        # random-problem audit); the fine solve holds the bound from the basin found
        coarse = FieldShooting(problem, o.coarse_intervals, scaling="energy", max_h_lambda=COARSE_H_LAMBDA,
                               control_bounds=False)  # fmt: skip
        wc = np.zeros(coarse.nw)
        for eps in o.homotopy:
            t0 = time.perf_counter()
            wc, info = coarse.solve(wc, eps, cost_scale, max(tol, o.homotopy_tolerance), o.coarse_max_iterations,
                                    o.memory, problem.solver.time_limit)  # fmt: skip
            phi, run, _ = (float(v) for v in coarse.cost_terms(wc, coarse.parameters(eps, cost_scale)))
            # J_ε as the direct method reports it (eq. direct.9 = eq. field.8 / ε: the same minimisers), so that
            # the homotopy costs of summary.json mean one thing for every method; a capped coarse step still
            # starts the fine solve
            record(eps, phi + run / eps, info, t0)
        wc, starts = _best_coarse_start(coarse, wc, cost_scale, problem, record)
        rough = coarse.evaluate(wc, cost_scale)
        coarse_time = time.perf_counter() - t_coarse
        w = fine.controls_to_w(rough.t, rough.u, cost_scale)
    t0 = time.perf_counter()
    w_start = w
    w, info = fine.solve(w, 1.0, cost_scale, tol, problem.solver.max_iterations, o.memory, problem.solver.time_limit)
    result = fine.evaluate(w, cost_scale)
    record(1.0, result.costs[0] + result.costs[1], info, t0)
    status = SolveStatus.SOLVED if info["success"] else SolveStatus.FAILED
    solved_eps = [step.eps for step in steps if step.success]
    # the fine ε = 1 solve failed: the largest ε solved, below 1 (the coarse ε = 1 step solved a relaxed problem:
    # another grid, without |u| ≤ u_max)
    eps = 1.0 if info["success"] else max([e for e in solved_eps if e < 1.0], default=0.0)
    full = o.full_sigma if o.full_sigma is not None else problem.n <= FULL_SIGMA_STATES
    stats = {
        "start": start, "build_time_s": fine.build_time_s, "coarse_time_s": coarse_time,
        **({"init_unused": init_unused} if init_unused else {}),
        **({"coarse_starts": starts} if starts else {}),
        "wall_time_s": time.perf_counter() - started, "nlp_variables": fine.nw, "intervals": fine.K,
        "substeps": fine.m, "coarse_intervals": o.coarse_intervals, "full_sigma": bool(full),
        "trace_Sigma_tf": float(np.trace(result.Sigma[-1])), "field_jitter": fine.field.jitter_used,
        "trace_Sigma_tf_reduction_percent": 100.0 * (1.0 - np.trace(result.Sigma[-1]) / baseline["trace_Sigma_tf"]),
        "min_sigma_eigenvalue": float(np.linalg.eigvalsh(result.Sigma).min()),
    }  # fmt: skip
    if len(fine.bound_rows):
        stats["constraints"] = {"u_max": shooting_control_report(
            problem, result, info["g"][fine.bound_rows], info["lam_g"][fine.bound_rows], cost_scale)}  # fmt: skip
    if problem.constraints is not None:  # the path rows are the last K·R of g, node by node
        R = len(fine.path_groups)
        stats.setdefault("constraints", {}).update(shooting_constraint_report(
            problem, result, info["g"][-fine.K * R :].reshape(fine.K, R),
            info["lam_g"][-fine.K * R :].reshape(fine.K, R), fine.path_units, fine.path_groups, cost_scale,
        ))  # fmt: skip
    message = f"Ipopt (L-BFGS, ε = 1 on K = {fine.K}): {info['status']}"
    if not info["success"]:
        rows = fine.rows(w, cost_scale)
        stats["unconverged"] = _unconverged(fine, w_start, result, rows, cost_scale, info["status"])
        worst = fine.worst_violation(rows, float(fine.parameters(1.0, cost_scale)[2]))
        if worst is not None:
            stats["worst_violation"] = worst
            message += (f"; worst-violated constraint: {worst['constraint']} at t = {worst['time']:.4g} "
                        f"(violation {worst['violation']:.3g})")  # fmt: skip
    return Solution(
        problem=problem, method="shooting", status=status,
        message=message, eps=eps,
        t=result.t, Sigma=result.Sigma, p=result.p, v=result.v, t_u=result.t, u=result.u,
        terminal_cost=result.costs[0], running_cost=result.costs[1], control_energy=result.costs[2],
        homotopy=steps, baseline=baseline, stats=stats,
    )  # fmt: skip


def _unconverged(fine: FieldShooting, w_start: np.ndarray, end: Any, rows: np.ndarray, cost_scale: float,
                 status: str) -> dict[str, Any]:  # fmt: skip
    """What a failed fine solve ended on, against where it started.

    Ipopt's status, and J and the largest scaled row violation (the rows are O(1) by construction) of the start and
    of the end (its trajectory ``end`` and rows ``rows``, already evaluated): a caller can tell a feasible plan that
    only ran out of iterations and improved on its start (re-planning flies it:
    :func:`mobisense.ocp.replan_window.unconverged_plan_flyable`).
    """
    start = fine.evaluate(w_start, cost_scale).costs
    return {"status": status, "cost": end.costs[0] + end.costs[1],
            "violation": float(fine.row_excess(rows).max(initial=0.0)), "start_cost": start[0] + start[1],
            "start_violation": float(fine.row_excess(fine.rows(w_start, cost_scale)).max(initial=0.0))}  # fmt: skip
