"""A bound on the right-hand-side evaluations of one ODE integration, so that stiff dynamics fail fast.

An explicit integrator (``solve_ivp``'s RK45, DOP853) on dynamics far faster than the time scale asked for takes
steps of the fastest time constant: gains or frequencies of 1e12 (a fuzzer's) made single integrations run for
minutes. :func:`bounded_rhs` counts the evaluations and raises the caller's error once a budget is spent.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["bounded_rhs"]


def bounded_rhs(
    rhs: Callable[..., Any], limit: int, error: Callable[[float], Exception]
) -> Callable[..., Any]:
    """``rhs(t, y, *args)`` that raises ``error(t)`` when called more than ``limit`` times.

    Parameters
    ----------
    rhs : callable
        The right-hand side ``f(t, y, *args)``.
    limit : int
        The most evaluations allowed.
    error : callable
        Builds the exception from the time reached (the caller's type and message).
    """
    calls = 0

    def counted(t: float, y: Any, *args: Any) -> Any:
        nonlocal calls
        calls += 1
        if calls > limit:
            raise error(t)
        return rhs(t, y, *args)

    return counted
