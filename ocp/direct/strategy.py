"""Solve strategies of the direct method: which starts are solved, which optimum is kept (docs/theory/direct.md §5.6).

The NLP has many local optima: from the coasting guess, from the end of the ε-continuation and from random
starts Ipopt lands on different ones, up to 10 % apart (48 % for one homotopy), and none of the starts is reliably
the best (benchmarks/bench_ocp_quality.py, benchmarks/RESULTS.md). ``solver.strategy`` chooses:

``auto`` (default)
    a cold ε = 1 solve, then random starts one by one until ``solver.consensus`` starts (the cold one
    included) have reached the lowest cost found (relative ``agreement``), at most ``solver.starts``; when
    they never agree, the continuation too, within as many Ipopt iterations as the starts took together; the
    lowest is kept. Three agreeing starts rather than two: on the benchmark's 24 problems two agreeing
    starts were a local optimum that a later start beat on 4, three on none. The continuation after a
    disagreement: on one of the 24 (n = 3, N = 3), cold and eight random starts reached eight different
    optima and only the continuation the best (0.02 % below the best random start).
``thorough``
    the cold solve, the random starts and the continuation, always (the continuation within as many Ipopt
    iterations as the others took together, at least its ``budget``); the best is kept.
``homotopy``
    the continuation (Hussein, 2008); with a ``budget`` a cold solve first, kept instead when the
    continuation would cost more than ``budget`` × its iterations or fails (detect and fall back).
``cold``
    the cold solve alone.

Every start is a :class:`Continuation`; its steps are reported through ``progress`` as they finish, each
labelled with its start. The starts ``auto`` solves whatever happens (:func:`certain_starts`) can be solved
elsewhere — on other workers, at the same time — and handed in as records (:meth:`Continuation.record`): the
strategy adopts a record instead of solving that start again, and decides exactly as if it had solved it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..homotopy import run_continuation
from ..problem import Problem
from ..registries import STRATEGIES
from ..solution import HomotopyStep
from .transcription import DirectCollocation, NLPResult

__all__ = [
    "Continuation",
    "SolveContext",
    "certain_starts",
    "share_starts",
    "solve_labelled",
    "run_strategy",
    "auto_strategy",
    "thorough_strategy",
    "homotopy_strategy",
    "cold_strategy",
]


@dataclass
class SolveContext:
    """What every start of one solve shares: the problem, its NLP, the coasting guess, the step record.

    ``guess(P)`` makes the coasting guess (:attr:`w0`) from the parameters at ε = 1 when a start first needs
    it: a warm-started solve never does. ``values`` are the parameter blocks
    (:meth:`mobisense.ocp.model.ParameterLayout.values`), not changed once the context exists.
    """

    problem: Problem
    tr: DirectCollocation
    values: dict[str, Any]
    guess: Callable[[np.ndarray], np.ndarray]
    progress: Callable[[HomotopyStep], None] | None = None
    steps: list[HomotopyStep] = field(default_factory=list)
    #: starts already solved elsewhere, by label (:meth:`Continuation.record`), adopted instead of solved
    solved_elsewhere: dict[str, dict[str, Any]] = field(default_factory=dict)
    _parameters: dict[float, np.ndarray] = field(default_factory=dict, repr=False)
    _w0: np.ndarray | None = field(default=None, repr=False)

    @property
    def w0(self) -> np.ndarray:
        """The coasting guess (scaled decision vector, shape (nw,)), made on first use."""
        if self._w0 is None:
            self._w0 = self.guess(self.parameters(1.0))
        return self._w0

    def parameters(self, eps: float) -> np.ndarray:
        """The NLP parameter vector at ``eps`` (read-only; packed once per ε)."""
        P = self._parameters.get(eps)
        if P is None:
            P = self._parameters[eps] = self.tr.layout.pack({**self.values, "eps": eps})
            P.setflags(write=False)
        return P

    def cost(self, w: np.ndarray) -> float:
        """J at ε = 1 of a decision vector."""
        phi, running, _ = self.tr.cost_values(w, self.parameters(1.0))
        return phi + running

    def start(
        self,
        label: str,
        w: np.ndarray | None = None,
        lam_w: np.ndarray | None = None,
        lam_g: np.ndarray | None = None,
        budget: int | None = None,
    ) -> Continuation:
        """A new start from ``w`` (default: the coasting guess), optionally primal–dual, within ``budget``."""
        return Continuation(self, label, self.w0 if w is None else w, lam_w, lam_g, budget=budget)

    def solve_at_one(self, label: str, point: Callable[[], np.ndarray]) -> Continuation:
        """The start ``label`` solved at ε = 1 from ``point()`` — or adopted, if it was solved elsewhere."""
        record = self.solved_elsewhere.get(label)
        if record is not None:
            return Continuation.adopt(self, record)
        run = self.start(label, point())
        run.attempt(1.0)
        return run


@dataclass
class Continuation:
    """One start: the accepted primal–dual point, its steps, its accepted ε path, the iterations it spent.

    ``budget`` (Ipopt iterations over all its steps, enforced inside Ipopt) stops it: once spent, every
    further ``attempt`` fails and ``exhausted`` is set.
    """

    ctx: SolveContext
    label: str
    w: np.ndarray
    lam_w: np.ndarray | None = None
    lam_g: np.ndarray | None = None
    budget: int | None = None
    result: NLPResult | None = None  # the last accepted result
    eps: float = 0.0  # the last accepted ε
    failed: NLPResult | None = None  # the last failed result
    used: int = 0
    exhausted: bool = False
    steps: list[HomotopyStep] = field(default_factory=list)
    path: list[tuple[float, np.ndarray]] = field(default_factory=list)

    @property
    def tr(self) -> DirectCollocation:
        """The transcription."""
        return self.ctx.tr

    def parameters(self, eps: float) -> np.ndarray:
        """The NLP parameter vector at ``eps``."""
        return self.ctx.parameters(eps)

    def attempt(self, eps: float) -> bool:
        """Solve at ``eps`` from the accepted point; accept it if Ipopt converged."""
        left = None if self.budget is None else self.budget - self.used
        if self.exhausted or (left is not None and left <= 0):
            self.exhausted = True
            return False
        P = self.parameters(eps)
        result = self.tr.solve(P, self.w, self.lam_w, self.lam_g, max_iterations=left)
        self.used += result.iterations
        if left is not None and result.status == "User_Requested_Stop":
            self.exhausted = True
        phi, running, _ = self.tr.cost_values(result.w, P)
        step = HomotopyStep(
            eps, phi + running / eps, result.iterations, result.status, result.time_s, result.success, self.label
        )
        self.steps.append(step)
        self.ctx.steps.append(step)
        if self.ctx.progress is not None:
            self.ctx.progress(step)
        if result.success:
            self.w, self.lam_w, self.lam_g, self.result, self.eps = result.w, result.lam_w, result.lam_g, result, eps
            self.path.append((eps, result.w))
        else:
            self.failed = result
        return result.success

    def record(self) -> dict[str, Any]:
        """The start as plain data (numpy arrays, dataclasses), with its problem's digest (``problem``).

        What :meth:`adopt` restores in another process.
        """
        state = {name: getattr(self, name) for name in _RECORDED}
        return {**state, "steps": list(self.steps), "path": list(self.path), "problem": self.ctx.problem.digest()}

    @classmethod
    def adopt(cls, ctx: SolveContext, record: dict[str, Any]) -> Continuation:
        """A start solved elsewhere (``record`` from :meth:`record`), its steps reported as if solved here."""
        run = cls(ctx, **{name: record[name] for name in _RECORDED})
        run.steps, run.path = list(record["steps"]), list(record["path"])
        for step in run.steps:
            ctx.steps.append(step)
            if ctx.progress is not None:
                ctx.progress(step)
        return run

    @property
    def solved(self) -> bool:
        """True when this start converged at ε = 1."""
        return self.eps == 1.0 and self.result is not None

    def summary(self) -> dict[str, Any]:
        """Start label, J at ε = 1 (None if not reached), iterations, ε reached, last status."""
        last = self.steps[-1].status if self.steps else "not run"
        return {
            "start": self.label,
            "cost": self.ctx.cost(self.w) if self.solved else None,
            "iterations": self.used,
            "eps_reached": self.eps,
            "status": "budget spent" if self.exhausted else last,
        }


#: the state of a start that :meth:`Continuation.record` keeps (besides its steps and ε path)
_RECORDED = ("label", "w", "lam_w", "lam_g", "budget", "result", "eps", "failed", "used", "exhausted")


def solve_labelled(ctx: SolveContext, label: str) -> Continuation:
    """The start ``label`` solved at ε = 1, or adopted if solved elsewhere (:meth:`SolveContext.solve_at_one`).

    ``"cold"`` starts from the coasting guess moved outside the keep-out zones (path_constraints.md §2.1);
    ``"random start k"`` from :func:`~.guesses.random_guess` with seed k.
    """
    from .feasible_start import cold_start
    from .guesses import random_guess

    if label == "cold":
        return ctx.solve_at_one(label, lambda: cold_start(ctx))
    seed = label.removeprefix("random start ")
    if seed == label or not seed.isdigit():
        raise ValueError(f"unknown start {label!r}: expected 'cold' or 'random start k'")
    return ctx.solve_at_one(label, lambda: random_guess(ctx.problem, int(seed), tr=ctx.tr))


def _cold(ctx: SolveContext) -> Continuation:
    return solve_labelled(ctx, "cold")


def _homotopy(ctx: SolveContext, budget: int | None) -> Continuation:
    run = ctx.start("homotopy", budget=budget)
    run_continuation(run.attempt, ctx.problem.solver.homotopy)
    return run


def _random_starts(ctx: SolveContext) -> Iterator[Continuation]:
    """The random starts 1 … ``solver.starts``, each solved when it is drawn."""
    for seed in range(1, ctx.problem.solver.starts + 1):
        yield solve_labelled(ctx, f"random start {seed}")


def certain_starts(problem: Problem) -> list[str]:
    """Labels of the starts ``problem``'s strategy solves whatever their results: the ones worth solving elsewhere.

    ``auto``: the cold solve and the random starts 1 … ``consensus`` − 1 (fewer agreeing starts cannot stop
    it; a start that fails or disagrees adds more, solved where the strategy runs). Other strategies: none.
    """
    options = problem.solver
    if options.strategy != "auto":
        return []
    return ["cold"] + [f"random start {seed}" for seed in range(1, min(options.consensus - 1, options.starts) + 1)]


def share_starts(labels: list[str], shares: int) -> list[list[str]]:
    """``labels`` cut into ``shares`` contiguous shares, the first one no shorter (it holds the cold solve).

    Random starts cost more Ipopt iterations than the cold solve (on bench_sweep_overhead.py's tasks: cold
    32–156, random start 1 29–104, random start 2 55–255), so for the default three starts on two workers
    ``[cold, random start 1]`` and ``[random start 2]`` balance best of the contiguous cuts.
    """
    shares = max(1, shares)
    bounds = [-(-len(labels) * k // shares) for k in range(shares + 1)]
    return [labels[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


def _confirmed(runs: list[Continuation], count: int, rtol: float) -> bool:
    """True when ``count`` converged starts lie within ``rtol`` of the lowest cost found."""
    costs = [r.ctx.cost(r.w) for r in runs if r.solved]
    if not costs:
        return False
    lowest = min(costs)
    return sum(c <= lowest + rtol * abs(lowest) for c in costs) >= count


def _best(runs: list[Continuation], rtol: float) -> Continuation | None:
    """The earliest converged start whose J is within ``rtol`` of the lowest (one optimum, found first), or None."""
    costs = [(r.ctx.cost(r.w), r) for r in runs if r.solved]
    if not costs:
        return None
    lowest = min(c for c, _ in costs)
    return next(r for c, r in costs if c <= lowest + rtol * abs(lowest))


def _budget(cold: Continuation, factor: float | None) -> int | None:
    """Iterations the continuation may take: ``factor`` × the cold solve's, if the cold solve converged."""
    return None if factor is None or not cold.solved else int(factor * cold.used)


def _fallback(runs: list[Continuation]) -> Continuation:
    """What to report when no start converged: the one that solved the largest ε, on a tie the first.

    The continuation keeps its last ε solved (a solution of a nearby problem); a start that solved nothing
    (a continuation with no iterations left in its budget) loses to the cold solve, whose Ipopt failure is
    then reported.
    """
    return max(runs, key=lambda r: r.eps)


def cold_strategy(ctx: SolveContext) -> tuple[list[Continuation], Continuation]:
    """The cold ε = 1 solve alone."""
    runs = [_cold(ctx)]
    return runs, runs[0]


def homotopy_strategy(ctx: SolveContext) -> tuple[list[Continuation], Continuation]:
    """The continuation; with ``solver.homotopy.budget``, a cold solve first to bound it and to fall back on."""
    options = ctx.problem.solver.homotopy
    if options.mode == "none":
        return cold_strategy(ctx)
    if options.budget is None:
        runs = [_homotopy(ctx, None)]
        return runs, runs[0]
    cold = _cold(ctx)
    homotopy = _homotopy(ctx, _budget(cold, options.budget))
    runs = [cold, homotopy]
    return runs, homotopy if homotopy.solved else (_best(runs, ctx.problem.solver.agreement) or _fallback(runs))


def auto_strategy(ctx: SolveContext) -> tuple[list[Continuation], Continuation]:
    """Cold solve, then random starts until ``solver.consensus`` starts reach the lowest cost (at most ``starts``).

    When they never agree, the continuation (a start of another kind: it follows the optimum from the convex
    ε → 0 problem) is solved too, within as many Ipopt iterations as the starts took together.
    """
    options = ctx.problem.solver
    runs = [_cold(ctx)]
    if not _confirmed(runs, options.consensus, options.agreement):
        for run in _random_starts(ctx):
            runs.append(run)
            if _confirmed(runs, options.consensus, options.agreement):
                break
        else:
            if options.homotopy.mode != "none":
                runs.append(_homotopy(ctx, sum(r.used for r in runs)))
    return runs, _best(runs, options.agreement) or _fallback(runs)


def thorough_strategy(ctx: SolveContext) -> tuple[list[Continuation], Continuation]:
    """Cold solve, the random starts and the continuation, always; the best is kept.

    The continuation runs last, within ``solver.homotopy.budget`` × the cold solve's iterations or as many as the
    other starts took together, whichever is more (none: unbudgeted). Budgeted by the cold solve alone, it was cut
    short where only it found the best optimum: three states and three sensors whose cold solve and random starts
    reached four optima up to 1.8 % above the continuation's (docs/theory/direct.md §5.6).
    """
    options = ctx.problem.solver
    runs = [_cold(ctx), *_random_starts(ctx)]
    if options.homotopy.mode != "none":
        budget = _budget(runs[0], options.homotopy.budget)
        runs.append(_homotopy(ctx, None if budget is None else max(budget, sum(r.used for r in runs))))
    return runs, _best(runs, options.agreement) or _fallback(runs)


def run_strategy(ctx: SolveContext) -> tuple[Continuation, dict[str, Any]]:
    """Run ``solver.strategy`` (see module docstring); the start to report and what every start found.

    Returns
    -------
    kept : Continuation
        The start whose solution is reported: the converged start of lowest cost (``homotopy``: the
        continuation when it converged); when none converged, the start that solved the largest ε (the
        continuation keeps its last ε solved), on a tie the first (the cold solve).
    record : dict
        ``strategy``, ``kept`` (label), ``homotopy_budget`` (iterations or None), ``starts``
        (:meth:`Continuation.summary` of each).
    """
    name = ctx.problem.solver.strategy
    runs, kept = STRATEGIES[name](ctx)
    record = {
        "strategy": name,
        "kept": kept.label,
        "homotopy_budget": next((r.budget for r in runs if r.label == "homotopy"), None),
        "starts": [r.summary() for r in runs],
    }
    return kept, record
