"""Solve the mobile-sensor Kalman problem by direct collocation with ε-continuation (SPEC §1.3).

``solve_direct(problem)`` builds (or reuses) the transcription for the problem's structure and grid,
starts from the ε → 0 limit (coasting sensors, Σ from the Riccati IVP), continues in ε with primal and
dual warm starts, and returns a :class:`~ocp.solution.Solution` — complete, or up to the last ε
solved with ``status="failed"`` and the worst-violated constraint named in problem terms.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from functools import lru_cache
from typing import Any

import numpy as np

from ocp.homotopy import run_continuation
from ocp.model import Structure, vec_to_sym
from ocp.problem import Problem
from ocp.simulate import Trajectory, coast
from ocp.solution import HomotopyStep, Solution
from ocp.transcription import DirectCollocation, NLPResult

__all__ = ["solve_direct", "transcription_for", "coasting_baseline"]


@lru_cache(maxsize=16)
def _cached_transcription(
    structure: Structure,
    scheme: str,
    degree: int,
    intervals: int,
    tolerance: float,
    max_iterations: int,
    time_limit: float | None = None,
) -> DirectCollocation:
    extra = {} if time_limit is None else {"max_wall_time": time_limit}
    return DirectCollocation(
        structure, scheme, degree, intervals, ipopt_options=extra, tolerance=tolerance, max_iterations=max_iterations
    )


def transcription_for(problem: Problem) -> DirectCollocation:
    """The (cached) transcription for ``problem``'s structure and solver options."""
    opts = problem.solver
    c = opts.collocation
    return _cached_transcription(
        Structure.of(problem), c.scheme, c.degree, c.intervals, opts.tolerance, opts.max_iterations, opts.time_limit
    )


def _state_grid(tr: DirectCollocation, t0: float, tf: float) -> tuple[np.ndarray, np.ndarray]:
    """Merged state time grid (interval starts and collocation nodes, no duplicates) and its sort order."""
    starts, nodes = tr.times(t0, tf)
    t_all = np.concatenate([starts, nodes.ravel()])
    order = np.argsort(t_all, kind="stable")
    keep = np.concatenate([[True], np.diff(t_all[order]) > 1e-12 * max(1.0, abs(tf - t0))])
    return t_all[order][keep], order[keep]


def coasting_baseline(problem: Problem, t_eval: np.ndarray, tr: DirectCollocation | None = None) -> Trajectory:
    """The ε → 0 solution: sensors coast (u ≡ 0), Σ from the Riccati IVP — the classical Kalman filter."""
    tr = tr or transcription_for(problem)
    P = tr.layout.pack(tr.layout.values(problem))
    return coast(tr.model, P, t_eval)


def _initial_guess(
    tr: DirectCollocation, trajectory: Trajectory, P: np.ndarray, u: np.ndarray | None = None
) -> np.ndarray:
    """Decision vector of a trajectory sampled on the state grid (every start and node) and controls ``u``.

    ``u`` has shape (K, d, nu) (controls at the collocation nodes); ``None`` means coasting (u = 0).
    """
    K, d = tr.intervals, tr.colloc.degree
    starts, nodes = tr.times(trajectory.t[0], trajectory.t[-1])
    t_all = np.concatenate([starts, nodes.ravel()])
    tol = 1e-9 * max(1.0, abs(trajectory.t[-1] - trajectory.t[0]))
    x_all = trajectory.x[np.clip(np.searchsorted(trajectory.t, t_all - tol), 0, len(trajectory.t) - 1)]
    u = np.zeros((K, d, tr.structure.nu)) if u is None else u
    return tr.pack(x_all[: K + 1], x_all[K + 1 :].reshape(K, d, -1), u, P)


def _worst_violation(tr: DirectCollocation, result: NLPResult, problem: Problem) -> dict[str, Any]:
    _, _, lbg, ubg = tr.bounds()
    violation = np.maximum(np.maximum(lbg - result.g, result.g - ubg), 0.0)
    index = int(np.argmax(violation))
    labels = tr.constraint_labels([s.name for s in problem.sensors], problem.horizon.t0, problem.horizon.tf)
    what, when = labels[index]
    return {"constraint": what, "time": when, "violation": float(violation[index])}


def solve_direct(
    problem: Problem,
    progress: Callable[[HomotopyStep], None] | None = None,
    transcription: DirectCollocation | None = None,
    init: Solution | dict[str, Any] | None = None,
    guess: np.ndarray | None = None,
) -> Solution:
    """Solve ``problem`` by direct collocation with the ε-homotopy of its solver options.

    Parameters
    ----------
    problem : Problem
    progress : callable, optional
        Called with each :class:`HomotopyStep` as soon as it finishes (for progress displays).
    transcription : DirectCollocation, optional
        A prebuilt transcription of the same structure (default: cached per structure and grid).
    init : Solution or dict, optional
        A solved problem of the same structure and grid (e.g. a sweep neighbour), or its ``nlp`` point
        (dict with ``w, lam_w, lam_g, P, signature``): the primal–dual point,
        re-scaled to this problem, warm-starts ε = 1 directly; if Ipopt fails from there the usual
        continuation from the coasting solution runs.
    guess : ndarray, shape (nw,), optional
        A scaled decision vector (see :meth:`DirectCollocation.pack`) to start a cold ε = 1 solve from,
        without continuation (multi-start).

    Returns
    -------
    Solution
        ``status`` is ``"solved"`` when ε = 1 converged, else ``"failed"`` with what was solved.
    """
    t_start = time.perf_counter()
    tr = transcription or transcription_for(problem)
    t0, tf = problem.horizon.t0, problem.horizon.tf
    layout = tr.layout
    values = layout.values(problem)
    t_grid, order = _state_grid(tr, t0, tf)
    coasting = coast(tr.model, layout.pack(values), t_grid)
    values["cost_scale"] = max(abs(coasting.cost), 1e-8)
    w0 = _initial_guess(tr, coasting, layout.pack(values))

    state: dict[str, Any] = {"w": w0, "lam_w": None, "lam_g": None, "result": None, "eps": 0.0, "failed": None}
    steps: list[HomotopyStep] = []
    path: list[tuple[float, np.ndarray]] = []

    def attempt(eps: float) -> bool:
        P = layout.pack({**values, "eps": eps})
        result = tr.solve(P, state["w"], state["lam_w"], state["lam_g"])
        phi, running, _ = (float(v) for v in tr.cost_terms(result.w, P))
        step = HomotopyStep(eps, phi + running / eps, result.iterations, result.status, result.time_s, result.success)
        steps.append(step)
        if progress is not None:
            progress(step)
        if result.success:
            state.update(w=result.w, lam_w=result.lam_w, lam_g=result.lam_g, result=result, eps=eps)
            path.append((eps, result.w))
        else:
            state["failed"] = (result, P)
        return result.success

    stats: dict[str, Any] = {"build_time_s": tr.build_time_s, "nlp_variables": tr.nw, "nlp_constraints": tr.ng}
    eps_reached = 0.0
    if init is not None:
        stats["start"] = _start_from_solution(init, tr, layout.pack({**values, "eps": 1.0}), state)
        if stats["start"] == "warm start from init":
            eps_reached = 1.0 if attempt(1.0) else 0.0
            if eps_reached < 1.0:
                stats["start"] = "warm start from init failed; continuation from coasting"
                state.update(w=w0, lam_w=None, lam_g=None)
    elif guess is not None:
        stats["start"] = "initial guess, ε = 1 directly"
        state["w"] = np.asarray(guess, float)
        eps_reached = 1.0 if attempt(1.0) else 0.0
    if eps_reached < 1.0 and guess is None:
        eps_reached = run_continuation(attempt, problem.solver.homotopy)
    solved = eps_reached == 1.0
    message = "converged at ε = 1"
    if not solved:
        failed_result, _ = state["failed"]
        worst = _worst_violation(tr, failed_result, problem)
        stats["worst_violation"] = worst
        message = (
            f"Ipopt returned {failed_result.status} at ε = {steps[-1].eps:g}; last ε solved = {eps_reached:g}; "
            f"worst-violated constraint: {worst['constraint']} at t = {worst['time']:.4g} "
            f"(violation {worst['violation']:.3g})"
        )
    stats["total_time_s"] = time.perf_counter() - t_start
    return _assemble(problem, tr, values, state, steps, path, coasting, t_grid, order, solved, message, stats)


def _start_from_solution(
    init: Solution | dict[str, Any], tr: DirectCollocation, P: np.ndarray, state: dict[str, Any]
) -> str:
    """Load ``init``'s primal–dual point into ``state`` if its NLP has the same layout; say what happened."""
    nlp = init.nlp if isinstance(init, Solution) else init
    if nlp is None or (isinstance(init, Solution) and init.eps != 1.0):
        return "init ignored: it carries no converged ε = 1 NLP point"
    if nlp["signature"] != repr(tr.signature):
        return "init ignored: different structure or grid"
    w, lam_w, lam_g = tr.transfer(nlp["w"], nlp["lam_w"], nlp["lam_g"], nlp["P"], P)
    state.update(w=w, lam_w=lam_w, lam_g=lam_g)
    return "warm start from init"


def _assemble(
    problem: Problem,
    tr: DirectCollocation,
    values: dict[str, Any],
    state: dict[str, Any],
    steps: list[HomotopyStep],
    path: list[tuple[float, np.ndarray]],
    coasting: Trajectory,
    t_grid: np.ndarray,
    order: np.ndarray,
    solved: bool,
    message: str,
    stats: dict[str, Any],
) -> Solution:
    s = tr.structure
    n, N = s.n, s.N
    eps = state["eps"]
    P = tr.layout.pack({**values, "eps": max(eps, 1e-300)})
    P1 = tr.layout.pack({**values, "eps": 1.0})

    def on_grid(w: np.ndarray) -> np.ndarray:
        parts = tr.unpack(w, P)
        x_all = np.concatenate([parts["xs"], parts["xc"].reshape(-1, s.nx)])
        return x_all[order]

    x = on_grid(state["w"])
    parts = tr.unpack(state["w"], P)
    _, nodes = tr.times(problem.horizon.t0, problem.horizon.tf)
    phi, running, energy = (float(v) for v in tr.cost_terms(state["w"], P1))
    solution = Solution(
        problem=problem,
        method="direct",
        status="solved" if solved else "failed",
        message=message,
        eps=eps,
        t=t_grid,
        Sigma=vec_to_sym(x[:, : s.n_sigma], n),
        p=x[:, s.n_sigma : s.n_sigma + 2 * N].reshape(-1, N, 2),
        v=x[:, s.n_sigma + 2 * N :].reshape(-1, N, 2),
        t_u=nodes.ravel(),
        u=parts["u"].reshape(-1, N, 2),
        terminal_cost=phi,
        running_cost=running,
        control_energy=energy,
        homotopy=steps,
        baseline={
            "cost": coasting.cost,
            "terminal_cost": coasting.terminal_cost,
            "running_cost": coasting.running_cost,
        },
        stats=stats,
    )
    if state["result"] is not None:
        result = state["result"]
        solution.nlp = {
            "w": result.w,
            "lam_w": result.lam_w,
            "lam_g": result.lam_g,
            "P": P,
            "signature": repr(tr.signature),
        }
        lam = tr.costates(result, P)
        lam_sigma = lam[:, : s.n_sigma].copy()
        Lam = vec_to_sym(lam_sigma, n)
        off = ~np.eye(n, dtype=bool)
        Lam[:, off] *= 0.5  # off-diagonal σ_ij stands for Σ_ij and Σ_ji: λ_σij = 2 Λ_ij
        solution.t_costate = np.concatenate([[problem.horizon.t0], nodes.ravel()])
        solution.Lam = Lam
        solution.lam_p = lam[:, s.n_sigma : s.n_sigma + 2 * N].reshape(-1, N, 2)
        solution.lam_v = lam[:, s.n_sigma + 2 * N :].reshape(-1, N, 2)
    if path:
        grids = [on_grid(w) for _, w in path]
        solution.path_eps = np.array([e for e, _ in path])
        solution.path_p = np.stack([g[:, s.n_sigma : s.n_sigma + 2 * N].reshape(-1, N, 2) for g in grids])
        solution.path_Sigma = np.stack([vec_to_sym(g[:, : s.n_sigma], n) for g in grids])
    return solution
