"""One-shot entry point: ``solve(problem, method=…, init=…)`` with any registered method."""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from ..core.config import ConfigError
from .problem import Problem, load_problem
from .registries import METHODS
from .solution import HomotopyStep, Solution
from .solution_warnings import init_warning

__all__ = ["solve", "as_problem"]


def solve(
    problem: Problem | str | Path,
    method: str | None = None,
    *,
    init: Solution | None = None,
    progress: Callable[[HomotopyStep], Any] | None = None,
) -> Solution:
    """Solve a mobile-sensor Kalman problem.

    Parameters
    ----------
    problem : Problem, str or Path
        The problem, or the path of its YAML file (or the name of a shipped example, see
        :func:`mobisense.ocp.problem.load_problem`).
    method : str, optional
        A name in :data:`mobisense.ocp.registries.METHODS` (``"direct"``, ``"indirect"``, ``"both"``,
        ``"shooting"`` for fields); default ``problem.solver.method``.
    init : Solution, optional
        A previous solution of a problem of the same structure and grid (e.g. with other weights):
        its primal–dual point warm-starts ε = 1 directly (continuation from the coasting solution if
        that fails) — continuation as plain data flow. One of another structure or grid, or without a
        converged point, is not used: the solve runs as without it and a ``UserWarning`` says so.
    progress : callable, optional
        Called with each :class:`~mobisense.ocp.solution.HomotopyStep` as it finishes.

    Returns
    -------
    Solution
        ``status`` tells whether ε = 1 was reached; a failed solve keeps what was solved. A solution with
        NaN or infinite values is never ``solved``.
    """
    if init is not None and not isinstance(init, Solution):
        raise TypeError(f"solve: init: expected a Solution (of an earlier solve), got {type(init).__name__}")
    if progress is not None and not callable(progress):
        raise TypeError(f"solve: progress: expected a callable (called with each HomotopyStep), got "
                        f"{type(progress).__name__}")  # fmt: skip
    problem = as_problem(problem, "solve")
    method = method or problem.solver.method
    if method not in METHODS:
        raise ConfigError(f"solver.method: {METHODS.unknown(method)}")
    solution = METHODS[method](problem, progress=progress, init=init)
    solution.reject_non_finite()
    from .direct.plan_check import record_plan_check

    record_plan_check(solution)  # a direct plan: its J checked independently
    if init is not None and (unused := init_warning(solution)):
        warnings.warn(unused, UserWarning, stacklevel=2)
    return solution


def as_problem(problem: Problem | str | Path, caller: str) -> Problem:
    """``problem``, or the problem read from its YAML path or shipped example's name (:func:`load_problem`).

    Parameters
    ----------
    problem : Problem, str or Path
    caller : str
        The function taking it, for the message (``"solve"``).

    Raises
    ------
    TypeError
        ``problem`` is none of these (a mapping: :meth:`Problem.from_dict` validates one).
    ConfigError
        The file is missing or invalid.
    """
    if isinstance(problem, Problem):
        return problem
    if not isinstance(problem, (str, os.PathLike)):
        got = "a mapping (Problem.from_dict validates one)" if isinstance(problem, Mapping) else type(problem).__name__
        raise TypeError(f"{caller}: problem: expected a Problem, a YAML path or an example's name, got {got}")
    return load_problem(problem)
