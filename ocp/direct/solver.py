"""Solve the mobile-sensor Kalman problem by direct collocation (docs/theory/direct.md §5).

``solve_direct(problem)`` builds (or reuses) the transcription for the problem's structure and grid,
computes the ε → 0 limit (coasting sensors, Σ from the Riccati IVP) as the initial guess and baseline, runs
the problem's solve strategy (:mod:`mobisense.ocp.direct.strategy`: cold solve, ε-continuation with
primal–dual warm starts, random starts) and returns a :class:`~mobisense.ocp.solution.Solution` — complete,
or up to the last ε solved with ``status="failed"`` and the worst-violated constraint named in problem terms.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ..problem import Problem
from ..simulate import Trajectory, coast
from ..solution import HomotopyStep, Solution, SolveStatus, StartKind
from .guesses import cost_scale, initial_guess, state_grid
from .path_report import constraint_report
from .stiff_start import coarse_grid_hint
from .strategy import Continuation, SolveContext, run_strategy, solve_labelled
from .transcription import DirectCollocation, NLPResult, transcription_for
from .violations import worst_violation

__all__ = ["solve_direct", "solve_starts"]


#: the keys of a primal–dual point (:attr:`Solution.nlp`, an ``init`` given as a dict)
NLP_KEYS = ("w", "lam_w", "lam_g", "P", "signature")
#: largest scaled constraint violation of a failed solve not blamed on a constraint (Ipopt stopped for another
#: reason, e.g. its iteration limit, with the dynamics and path constraints satisfied)
FEASIBLE_VIOLATION = 1e-6


def solve_direct(
    problem: Problem,
    progress: Callable[[HomotopyStep], None] | None = None,
    transcription: DirectCollocation | None = None,
    init: Solution | dict[str, Any] | None = None,
    guess: np.ndarray | None = None,
    solved_elsewhere: list[dict[str, Any]] | None = None,
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
        continuation from the coasting solution runs. ``TypeError`` for another type, ``ValueError`` for a
        dict without those keys.
    guess : ndarray, shape (nw,), optional
        A scaled decision vector (see :meth:`DirectCollocation.pack`) to start a cold ε = 1 solve from,
        without continuation (multi-start).
    solved_elsewhere : list of dict, optional
        Starts of the strategy already solved for this same problem (:func:`solve_starts`, e.g. on other
        workers at the same time): adopted instead of solved again; records of another problem are ignored.

    Returns
    -------
    Solution
        ``status`` is ``"solved"`` when ε = 1 converged, else ``"failed"`` with what was solved.
    """
    if init is not None and not isinstance(init, Solution):
        if not isinstance(init, dict):
            raise TypeError(f"solve_direct: init: expected a Solution or its nlp point (a dict), got "
                            f"{type(init).__name__}")  # fmt: skip
        missing = [key for key in NLP_KEYS if key not in init]
        if missing:
            raise ValueError(f"solve_direct: init: expected a Solution or its nlp point (a dict with keys "
                             f"{', '.join(NLP_KEYS)}), got a dict without {', '.join(missing)}")  # fmt: skip
    t_start = time.perf_counter()
    tr = transcription or transcription_for(problem)
    ctx, coasting, order = _context(problem, tr, progress)
    if solved_elsewhere:
        digest = problem.digest()
        ctx.solved_elsewhere = {r["label"]: r for r in solved_elsewhere if r.get("problem") == digest}

    stats: dict[str, Any] = {
        "build_time_s": tr.build_time_s,
        "nlp_variables": tr.nw,
        "nlp_constraints": tr.ng,
        "kernels": tr.kernel_mode,
    }
    kept: Continuation | None = None
    if init is not None:
        start, warm = _start_from_solution(init, ctx)
        stats["start"] = start
        if warm is not None:
            if warm.attempt(1.0):
                kept = warm
            else:
                stats["start"] = StartKind.WARM_FAILED
    elif guess is not None:
        stats["start"] = StartKind.GUESS
        kept = ctx.start("guess", np.asarray(guess, float))
        kept.attempt(1.0)
    if kept is None:
        kept, stats["strategy"] = run_strategy(ctx)
    solved = kept.solved
    message = "converged at ε = 1"
    if "strategy" in stats and len(stats["strategy"]["starts"]) > 1:
        message += f" ({kept.label} kept, the best of {len(stats['strategy']['starts'])} starts)"
    if not solved and kept.failed is not None:
        worst = worst_violation(tr, kept.failed.g, kept.parameters(1.0), problem)
        stats["worst_violation"] = worst
        where = f"{worst['constraint']} at t = {worst['time']:.4g}"
        size = f"{worst['violation']:.3g} {worst['units']}".removesuffix(" 1")
        message = f"Ipopt returned {kept.failed.status} at ε = {kept.steps[-1].eps:g}; last ε solved = {kept.eps:g}; "
        if worst["scaled_violation"] <= FEASIBLE_VIOLATION:  # not a constraint's doing: the optimality conditions
            held = f"{worst['scaled_violation']:.3g} in the NLP's scaling (the largest: {where}, {size})"
            message += f"every constraint holds to {held}: not optimal yet"
        else:
            message += f"worst-violated constraint: {where} (violation {size})"
        hint = coarse_grid_hint(tr, coasting, kept.parameters(1.0), problem.horizon.t0, problem.horizon.tf)
        if hint:
            message += f"; {hint}"
    elif not solved:  # the kept start never ran into a failure of its own (its iteration budget was spent first)
        why = "its iteration budget was used up" if kept.exhausted else "it was not run"
        message = f"no start converged at ε = 1: {kept.label} stopped at ε = {kept.eps:g} ({why})"
        failures = [step for step in ctx.steps if not step.success]
        if failures:
            last = failures[-1]
            message += f"; the last failure: Ipopt returned {last.status} at ε = {last.eps:g} ({last.start})"
    stats["total_time_s"] = time.perf_counter() - t_start
    solution = _assemble(problem, kept, coasting, order, solved, message, stats)
    if solution.success and solution.worse_than_baseline:  # the grid may exclude every plan near coasting
        hint = coarse_grid_hint(tr, coasting, kept.parameters(1.0), problem.horizon.t0, problem.horizon.tf)
        if hint:
            solution.stats["coarse_grid"] = hint
    return solution


def solve_starts(problem: Problem, labels: list[str]) -> list[dict[str, Any]]:
    """Solve the starts ``labels`` of ``problem``'s strategy (e.g. :func:`~.strategy.certain_starts`), as records.

    A record (:meth:`Continuation.record`, with the problem's digest) is plain data; handed to
    :func:`solve_direct` (``solved_elsewhere``) in another process, it stands for that start there. So the
    starts of one solve can run on several workers at once and the strategy still decides as if it had solved
    them one by one (the records are the same bits: each start is deterministic given the problem). A start
    that reached ε = 1 also gives its cost ``J`` (``cost``) and its primal–dual point in the form of
    :attr:`Solution.nlp` (``carry``), from which a neighbouring problem can be warm-started.

    Parameters
    ----------
    problem : Problem
    labels : list of str
        ``"cold"`` and/or ``"random start k"`` (k = 1 … ``solver.starts``).

    Returns
    -------
    list of dict
        One record per label, in order, with the wall time (s) it took (``seconds``), and ``cost`` and
        ``carry`` (None when the start did not reach ε = 1).
    """
    tr = transcription_for(problem)
    ctx, _, _ = _context(problem, tr, None)
    records = []
    for label in labels:
        t0 = time.perf_counter()
        run = solve_labelled(ctx, label)
        point = _nlp_point(tr, run.result, ctx.parameters(1.0)) if run.solved and run.result is not None else None
        records.append({**run.record(), "seconds": time.perf_counter() - t0,
                        "cost": None if point is None else ctx.cost(run.w), "carry": point})  # fmt: skip
    return records


def _context(
    problem: Problem, tr: DirectCollocation, progress: Callable[[HomotopyStep], None] | None
) -> tuple[SolveContext, Trajectory, np.ndarray]:
    """What every start of a solve shares (its coasting guess and cost scale), the coasting solution, the grid order."""
    t0, tf = problem.horizon.t0, problem.horizon.tf
    values = tr.layout.values(problem)
    t_grid, order = state_grid(tr, t0, tf)
    coasting = coast(tr.model, tr.layout.pack(values), t_grid)
    if not (np.isfinite(coasting.cost) and np.all(np.isfinite(coasting.x))):
        raise RuntimeError(
            f"the no-control (coasting) solution is not finite (J = {coasting.cost:g}): the covariance or the cost "
            "overflows over the horizon; rescale the problem"
        )
    values["cost_scale"] = cost_scale(coasting.cost)  # the NLP objective is J / cost_scale = O(1)
    ctx = SolveContext(problem, tr, values, lambda P: initial_guess(tr, coasting, P), progress)
    return ctx, coasting, order


def _start_from_solution(init: Solution | dict[str, Any], ctx: SolveContext) -> tuple[StartKind, Continuation | None]:
    """The start from ``init``'s primal–dual point if its NLP has the same layout (else None); what happened.

    The coasting guess is not made for it (a warm-started sweep task never needs it).
    """
    nlp = init.nlp if isinstance(init, Solution) else init
    if isinstance(init, Solution) and init.method not in ("direct", "both"):  # a shooting or indirect solution
        return StartKind.INIT_OTHER_METHOD, None
    if nlp is None or (isinstance(init, Solution) and init.eps != 1.0):
        return StartKind.INIT_WITHOUT_POINT, None
    if nlp["signature"] != repr(ctx.tr.signature):
        nlp = _on_this_grid(init, ctx)
        if nlp is None:
            return StartKind.INIT_OTHER_LAYOUT, None
    w, lam_w, lam_g = ctx.tr.transfer(nlp["w"], nlp["lam_w"], nlp["lam_g"], nlp["P"], ctx.parameters(1.0))
    return StartKind.WARM, ctx.start("warm start", w, lam_w, lam_g)


def _on_this_grid(init: Solution | dict[str, Any], ctx: SolveContext) -> dict[str, Any] | None:
    """``init``'s point moved onto this transcription's grid when only the number of intervals differs, else None.

    Mesh refinement (the same problem on more intervals) started cold before: 387 iterations from coasting at
    K = 150 where the K = 100 optimum was at hand (first-hour audit). The previous collocation polynomials are
    evaluated on the new nodes and each new interval takes the physical multipliers of the old interval under its
    midpoint (:func:`~mobisense.ocp.direct.warm_shift.shifted_point`, the re-planning's shifted warm start).
    """
    from ..model import Structure
    from .transcription import transcription_for
    from .warm_shift import shifted_point

    problem = ctx.problem
    if not isinstance(init, Solution) or init.collocation is None:
        return None
    old = init.problem
    same_span = (old.horizon.t0, old.horizon.tf) == (problem.horizon.t0, problem.horizon.tf)
    same_scheme = init.collocation[:2] == (problem.solver.collocation.scheme, problem.solver.collocation.degree)
    if not (same_span and same_scheme and Structure.of(old) == Structure.of(problem)):
        return None
    return shifted_point(init, transcription_for(old), ctx.tr, ctx.parameters(1.0),
                         (problem.horizon.t0, problem.horizon.tf))  # fmt: skip


def _assemble(
    problem: Problem,
    run: Continuation,
    coasting: Trajectory,
    order: np.ndarray,
    solved: bool,
    message: str,
    stats: dict[str, Any],
) -> Solution:
    """The Solution of a continuation: the accepted point (or the coasting guess), costates, the ε path."""
    tr = run.tr
    P = run.parameters(max(run.eps, 1e-300))

    def on_grid(parts: dict[str, np.ndarray]) -> np.ndarray:
        return np.concatenate([parts["xs"], parts["xc"].reshape(-1, tr.structure.nx)])[order]

    accepted = tr.unpack(run.w, P)
    states = on_grid(accepted)

    _, nodes = tr.times(problem.horizon.t0, problem.horizon.tf)
    costs = tr.cost_values(run.w, run.parameters(1.0))
    lam = None if run.result is None else tr.costates(run.result, P)
    solution = Solution.from_states(
        problem,
        "direct",
        SolveStatus.SOLVED if solved else SolveStatus.FAILED,
        message,
        run.eps,
        t=coasting.t,
        x=states,
        t_u=nodes.ravel(),
        u=accepted["u"].reshape(nodes.size, -1),
        costs=costs,  # type: ignore[arg-type]
        t_costate=np.concatenate([[problem.horizon.t0], nodes.ravel()]),
        lam=lam,
        path_eps=np.array([e for e, _ in run.path]) if run.path else None,
        # the last accepted step is the accepted point, unpacked above (with the same P)
        path_x=np.stack([states if w is run.w else on_grid(tr.unpack(w, P)) for _, w in run.path])
        if run.path
        else None,
        homotopy=run.ctx.steps,
        baseline={
            "cost": coasting.cost,
            "terminal_cost": coasting.terminal_cost,
            "running_cost": coasting.running_cost,
        },
        stats=stats,
        collocation=(tr.colloc.scheme, tr.colloc.degree, tr.intervals),
    )
    if run.result is not None and (tr.kernels.n_cons or tr.kernels.n_bound):
        u_nodes = solution.u.reshape(tr.intervals, tr.colloc.degree, problem.N, 2)
        solution.stats["constraints"] = constraint_report(problem, tr, run.result, P, u_nodes)
    if run.result is not None:
        solution.nlp = _nlp_point(tr, run.result, P)
    return solution


def _nlp_point(tr: DirectCollocation, result: NLPResult, P: np.ndarray) -> dict[str, Any]:
    """A converged primal–dual point as plain data (:attr:`Solution.nlp`): what warm-starts a neighbour."""
    return {"w": result.w, "lam_w": result.lam_w, "lam_g": result.lam_g, "P": P, "signature": repr(tr.signature)}
