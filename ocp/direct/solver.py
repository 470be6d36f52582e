"""Solve the mobile-sensor Kalman problem by direct collocation with ε-continuation (docs/theory/direct.md §5).

``solve_direct(problem)`` builds (or reuses) the transcription for the problem's structure and grid,
starts from the ε → 0 limit (coasting sensors, Σ from the Riccati IVP), continues in ε with primal and
dual warm starts, and returns a :class:`~mobisense.ocp.solution.Solution` — complete, or up to the last ε
solved with ``status="failed"`` and the worst-violated constraint named in problem terms.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..homotopy import run_continuation
from ..problem import Problem
from ..simulate import Trajectory, coast
from ..solution import HomotopyStep, Solution, SolveStatus, StartKind
from .guesses import initial_guess, state_grid
from .transcription import DirectCollocation, NLPResult, transcription_for

__all__ = ["solve_direct"]


@dataclass
class _Continuation:
    """The state of one ε-continuation: the accepted primal–dual point, every step, the accepted path."""

    tr: DirectCollocation
    values: dict[str, Any]
    w: np.ndarray
    progress: Callable[[HomotopyStep], None] | None = None
    lam_w: np.ndarray | None = None
    lam_g: np.ndarray | None = None
    result: NLPResult | None = None  # the last accepted result
    eps: float = 0.0  # the last accepted ε
    failed: NLPResult | None = None  # the last failed result
    steps: list[HomotopyStep] = field(default_factory=list)
    path: list[tuple[float, np.ndarray]] = field(default_factory=list)

    def parameters(self, eps: float) -> np.ndarray:
        """The NLP parameter vector at ``eps``."""
        return self.tr.layout.pack({**self.values, "eps": eps})

    def attempt(self, eps: float) -> bool:
        """Solve at ``eps`` from the accepted point; accept it if Ipopt converged."""
        P = self.parameters(eps)
        result = self.tr.solve(P, self.w, self.lam_w, self.lam_g)
        phi, running, _ = (float(v) for v in self.tr.cost_terms(result.w, P))
        step = HomotopyStep(eps, phi + running / eps, result.iterations, result.status, result.time_s, result.success)
        self.steps.append(step)
        if self.progress is not None:
            self.progress(step)
        if result.success:
            self.w, self.lam_w, self.lam_g, self.result, self.eps = result.w, result.lam_w, result.lam_g, result, eps
            self.path.append((eps, result.w))
        else:
            self.failed = result
        return result.success

    def restart(self, w: np.ndarray, lam_w: np.ndarray | None = None, lam_g: np.ndarray | None = None) -> None:
        """Continue from another primal (and dual) point."""
        self.w, self.lam_w, self.lam_g = w, lam_w, lam_g


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
    values = tr.layout.values(problem)
    t_grid, order = state_grid(tr, t0, tf)
    coasting = coast(tr.model, tr.layout.pack(values), t_grid)
    if not (np.isfinite(coasting.cost) and np.all(np.isfinite(coasting.x))):
        raise RuntimeError(
            f"the no-control (coasting) solution is not finite (J = {coasting.cost:g}): the covariance or the cost "
            "overflows over the horizon; rescale the problem"
        )
    # the NLP objective is J / cost_scale = O(1): the scale follows the cost however small (M SPD makes it > 0);
    # an absolute floor would make tiny-cost problems (M = 1e-40) optimise the control energy alone
    values["cost_scale"] = max(abs(coasting.cost), 1e-300)
    w0 = initial_guess(tr, coasting, tr.layout.pack(values))
    run = _Continuation(tr, values, w0, progress)

    stats: dict[str, Any] = {"build_time_s": tr.build_time_s, "nlp_variables": tr.nw, "nlp_constraints": tr.ng}
    eps_reached = 0.0
    if init is not None:
        start = _start_from_solution(init, run)
        stats["start"] = start
        if start is StartKind.WARM:
            eps_reached = 1.0 if run.attempt(1.0) else 0.0
            if eps_reached < 1.0:
                stats["start"] = StartKind.WARM_FAILED
                run.restart(w0)
    elif guess is not None:
        stats["start"] = StartKind.GUESS
        run.restart(np.asarray(guess, float))
        eps_reached = 1.0 if run.attempt(1.0) else 0.0
    if eps_reached < 1.0 and guess is None:
        eps_reached = run_continuation(run.attempt, problem.solver.homotopy)
    solved = eps_reached == 1.0
    message = "converged at ε = 1"
    if not solved and run.failed is not None:
        worst = _worst_violation(tr, run.failed, problem)
        stats["worst_violation"] = worst
        message = (
            f"Ipopt returned {run.failed.status} at ε = {run.steps[-1].eps:g}; last ε solved = {eps_reached:g}; "
            f"worst-violated constraint: {worst['constraint']} at t = {worst['time']:.4g} "
            f"(violation {worst['violation']:.3g})"
        )
    stats["total_time_s"] = time.perf_counter() - t_start
    return _assemble(problem, run, coasting, order, solved, message, stats)


def _start_from_solution(init: Solution | dict[str, Any], run: _Continuation) -> StartKind:
    """Load ``init``'s primal–dual point into ``run`` if its NLP has the same layout; say what happened."""
    nlp = init.nlp if isinstance(init, Solution) else init
    if nlp is None or (isinstance(init, Solution) and init.eps != 1.0):
        return StartKind.INIT_WITHOUT_POINT
    if nlp["signature"] != repr(run.tr.signature):
        return StartKind.INIT_OTHER_LAYOUT
    w, lam_w, lam_g = run.tr.transfer(nlp["w"], nlp["lam_w"], nlp["lam_g"], nlp["P"], run.parameters(1.0))
    run.restart(w, lam_w, lam_g)
    return StartKind.WARM


def _assemble(
    problem: Problem,
    run: _Continuation,
    coasting: Trajectory,
    order: np.ndarray,
    solved: bool,
    message: str,
    stats: dict[str, Any],
) -> Solution:
    """The Solution of a continuation: the accepted point (or the coasting guess), costates, the ε path."""
    tr = run.tr
    P = run.parameters(max(run.eps, 1e-300))

    def on_grid(w: np.ndarray) -> np.ndarray:
        parts = tr.unpack(w, P)
        return np.concatenate([parts["xs"], parts["xc"].reshape(-1, tr.structure.nx)])[order]

    _, nodes = tr.times(problem.horizon.t0, problem.horizon.tf)
    costs = tuple(float(v) for v in tr.cost_terms(run.w, run.parameters(1.0)))
    lam = None if run.result is None else tr.costates(run.result, P)
    solution = Solution.from_states(
        problem,
        "direct",
        SolveStatus.SOLVED if solved else SolveStatus.FAILED,
        message,
        run.eps,
        t=coasting.t,
        x=on_grid(run.w),
        t_u=nodes.ravel(),
        u=tr.unpack(run.w, P)["u"].reshape(nodes.size, -1),
        costs=costs,  # type: ignore[arg-type]
        t_costate=np.concatenate([[problem.horizon.t0], nodes.ravel()]),
        lam=lam,
        path_eps=np.array([e for e, _ in run.path]) if run.path else None,
        path_x=np.stack([on_grid(w) for _, w in run.path]) if run.path else None,
        homotopy=run.steps,
        baseline={
            "cost": coasting.cost,
            "terminal_cost": coasting.terminal_cost,
            "running_cost": coasting.running_cost,
        },
        stats=stats,
        collocation=(tr.colloc.scheme, tr.colloc.degree, tr.intervals),
    )
    if run.result is not None:
        solution.nlp = {
            "w": run.result.w,
            "lam_w": run.result.lam_w,
            "lam_g": run.result.lam_g,
            "P": P,
            "signature": repr(tr.signature),
        }
    return solution
