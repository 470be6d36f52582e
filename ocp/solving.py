"""One-shot entry point: ``solve(problem)`` with the method named in its solver options (or given)."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

from ocp.config import ConfigError
from ocp.problem import Problem
from ocp.solution import HomotopyStep, Solution

__all__ = ["METHODS", "solve"]

#: solver.method -> "module:function" taking (problem, progress=callable) and returning a Solution
METHODS: dict[str, str] = {
    "direct": "ocp.direct:solve_direct",
    "indirect": "ocp.indirect:solve_indirect",
    "both": "ocp.compare:solve_both",
}


def solve(
    problem: Problem, method: str | None = None, progress: Callable[[HomotopyStep], Any] | None = None
) -> Solution:
    """Solve ``problem`` with ``method`` (default ``problem.solver.method``)."""
    method = method or problem.solver.method
    module_name, function_name = METHODS[method].split(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError:
        raise ConfigError(
            f"solver.method: method {method!r} is not available in this installation; use 'direct'"
        ) from None
    return getattr(module, function_name)(problem, progress=progress)
