"""The arguments of re-planning (:func:`mobisense.ocp.replan.replan_monte_carlo`), checked before any work.

The rules are those of a ``kind: replan`` file (:mod:`mobisense.formation.replay.replan`): ``runs`` in
1 … 100 000, ``every`` and ``time_step`` positive with ``time_step ≤ every`` and ``time_step ≤ (tf − t0)/2``,
a receding window ``every ≤ length ≤ tf − t0``, a seed numpy accepts, a current of two finite components and a
force noise ≥ 0; the problem is solved by direct collocation or a field's shooting; and the flights, the plans
kept and the re-solves must fit the budget of memory and time (:func:`replan_estimates`,
:func:`mobisense.core.budget.check_budget`) before anything is allocated.
"""

from __future__ import annotations

import math
from typing import Any, Literal

from pydantic import Field, model_validator

from ..core.budget import Estimate, check_budget, check_limits
from ..core.config import (
    ConfigError,
    FiniteFloat,
    InvalidValue,
    NonNegativeFloat,
    PositiveFloat,
    Seed,
    StrictModel,
    parse_config,
)
from .problem import Problem

__all__ = ["DisturbanceArguments", "ReplanArguments", "check_replan_arguments", "check_horizon", "replan_estimates",
           "MAX_RUNS"]  # fmt: skip

#: most Monte Carlo runs (as a scenario file's ``monte_carlo.runs``)
MAX_RUNS = 100_000
#: least time of one re-solve beyond its Ipopt iterations (s), as the replay's budget counts it
SECONDS_PER_RESOLVE = 5e-3
#: copies of the per-step data made while a result is assembled, as the replay's budget counts them
COPIES = 4


class DisturbanceArguments(StrictModel):
    """A current of two finite components (L/T) and a force noise ≥ 0 (L/T^1.5)."""

    drift: list[FiniteFloat] = Field([0.0, 0.0], min_length=2, max_length=2, description="current (L/T)")
    force_noise_std: NonNegativeFloat = 0.0


class ReplanArguments(StrictModel):
    """The Monte Carlo runs, the re-plan period, the window and the flight's step."""

    runs: int = Field(ge=1, le=MAX_RUNS)
    every: PositiveFloat
    time_step: PositiveFloat
    seed: Seed = 1
    length: PositiveFloat | None = None
    warm_start: Literal["shifted", "reused", "cold"] = "shifted"

    @model_validator(mode="after")
    def _window(self) -> ReplanArguments:
        if self.length is not None and self.every > self.length:
            raise InvalidValue("every", f"expected every ≤ length = {self.length:g}, got {self.every:g}")
        if self.every < self.time_step:
            message = f"expected at least time_step = {self.time_step:g} (one re-plan per step at most)"
            raise InvalidValue("every", f"{message}, got {self.every:g}")
        return self


def check_replan_arguments(
    problem: Problem, plan_samples: int, limits: tuple[int | None, float | None], **arguments: Any
) -> ReplanArguments:
    """Validate ``replan_monte_carlo``'s arguments against the problem and the budget.

    Parameters
    ----------
    problem : Problem
    plan_samples : int
        Points at which each plan is kept (for the memory estimate).
    limits : tuple
        ``(max_memory, max_time)`` of the budget (bytes, seconds; None: the defaults of
        :func:`~mobisense.core.budget.check_budget`).
    **arguments
        ``runs``, ``every``, ``time_step``, ``seed``, ``length``, ``warm_start``.

    Raises
    ------
    ConfigError
        One line ``replan_monte_carlo: ARGUMENT: expected …, got …``, or the budget's "too large".
    """
    source = "replan_monte_carlo"
    check_limits(*limits, source)
    args = parse_config(arguments, ReplanArguments, source=source)
    check_horizon(problem, args.length, args.time_step, source)
    hint = "use fewer runs, a larger time_step or a larger every"
    estimates = replan_estimates(problem, args.runs, args.every, args.time_step, plan_samples, hint, args.length,
                                 args.warm_start)  # fmt: skip
    check_budget(estimates, limits[0], source, limits[1])
    return args


def check_horizon(problem: Problem, length: float | None, time_step: float, source: str,
                  length_key: str = "length", step_key: str = "time_step") -> None:  # fmt: skip
    """Refuse a problem re-planning cannot solve, a window longer than its horizon or a step over half of it.

    Parameters
    ----------
    problem : Problem
    length : float or None
        Receding-horizon window length (T); None: shrinking horizon.
    time_step : float
        The flight's step (T).
    source : str
        Who was given them, first in the message (a file, or ``replan_monte_carlo``).
    length_key, step_key : str
        Their names there (``replan.length`` and ``monte_carlo.time_step`` in a ``kind: replan`` file).

    Raises
    ------
    ConfigError
        One line naming ``source`` and the key.
    """
    span = problem.horizon.tf - problem.horizon.t0
    if problem.solver.method not in ("direct", "shooting"):
        raise ConfigError(f"{source}: problem: re-planning solves by direct collocation (or a field's shooting); "
                          f"the problem's solver.method is {problem.solver.method!r}")  # fmt: skip
    if length is not None and length > span:
        raise ConfigError(f"{source}: {length_key}: expected a window within the horizon, ≤ tf − t0 = {span:g}, "
                          f"got {length:g}")  # fmt: skip
    if time_step > span / 2:
        raise ConfigError(f"{source}: {step_key}: expected at most half the horizon ({span / 2:g}), "
                          f"got {time_step:g}")  # fmt: skip


def replan_estimates(
    problem: Problem, runs: int, every: float, time_step: float, plan_samples: int, hint: str,
    length: float | None = None, warm_start: str = "shifted",
) -> list[Estimate]:  # fmt: skip
    """Flights (3 policies × runs × steps), the plans kept (runs × re-plans × samples) and the re-solves.

    One transcription per window length is held (up to one per re-plan); each warm re-solve takes ≥ 2
    Ipopt iterations at the per-non-zero cost of :mod:`mobisense.ocp.sizes`, plus :data:`SECONDS_PER_RESOLVE`.
    A field's re-solves by shooting hold one solve's memory at a time: each window's fine ε = 1 solve takes at
    least :data:`~mobisense.ocp.field.FINE_ITERATIONS` iterations on the whole grid at one substep (a low bound:
    windows shrink); a ``cold`` window runs the whole solve (coarse homotopy and random starts included) on its
    share of the horizon, its grids scaled with it; with path constraints each costs
    :data:`~mobisense.ocp.field.CONSTRAINED_FACTOR` times as much (the island re-planned cold every 0.5 T was
    estimated at 23 s without the two and ran 286 s).
    """
    from .direct.nlp_size import transcription_size
    from .field import CONSTRAINED_FACTOR, FLOPS_PER_SECOND, shooting_seconds
    from .model import Structure
    from .sizes import SECONDS_PER_NONZERO_ITERATION, direct_estimate, shooting_estimate

    h = problem.horizon
    span = h.tf - h.t0
    steps = int(math.ceil(span / time_step)) + 1
    replans = min(int(math.ceil(span / every)), steps)
    n, N = problem.n, problem.N
    floats = runs * (steps * (2 * N + n * n) + (replans + 1) * plan_samples * (2 * N + 1))
    what = f"{runs} runs × {steps:.3g} steps × {replans} re-plans (horizon / time_step, horizon / every)"
    flights = Estimate(what, COPIES * 8.0 * floats, hint, 3 * runs * steps * (30e-6 + 4.0 * n**3 / FLOPS_PER_SECOND))
    resolves = runs * replans
    if problem.solver.method == "shooting":
        whole = shooting_estimate(problem)
        windows = [(t, h.tf if length is None else min(t + length, h.tf))
                   for t in (h.t0 + k * every for k in range(1, replans)) if t < h.tf]  # fmt: skip
        fine = shooting_seconds(n, problem.solver.shooting.intervals, 1, N)
        if problem.constraints is not None:
            fine *= CONSTRAINED_FACTOR
        if warm_start == "cold":  # the whole solve on each window's share of the horizon (grids scale with it)
            per_run = whole.seconds * sum(end - t for t, end in windows) / span
        else:
            per_run = len(windows) * fine
        return [flights, Estimate(f"{resolves:.3g} re-solves of {whole.what}", whole.bytes,
                                  hint + whole.hint.join(("; or ", "")),
                                  whole.seconds + runs * per_run + resolves * SECONDS_PER_RESOLVE)]  # fmt: skip
    c = problem.solver.collocation
    size = transcription_size(Structure.of(problem), c.degree, c.intervals, c.scheme)
    solve_seconds = SECONDS_PER_RESOLVE + 2 * (size.jacobian_nnz + size.hessian_nnz) * SECONDS_PER_NONZERO_ITERATION
    held = direct_estimate(problem)
    return [flights, Estimate(f"{resolves:.3g} re-solves of {held.what}", min(replans, c.intervals) * held.bytes,
                              hint, held.seconds + resolves * solve_seconds)]  # fmt: skip
