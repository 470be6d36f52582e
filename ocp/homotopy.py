"""ε-continuation schedules (docs/theory/direct.md §5.2), shared by the direct and the indirect method.

The driver calls ``attempt(eps)``, which tries to solve at ``eps`` starting from the last accepted
solution and returns whether it succeeded (the caller keeps the accepted state). Modes:

- ``fixed``: ε = δ, 2δ, …, 1 (the paper: δ = 0.05); the first failure stops the continuation.
- ``adaptive``: start with δ; after a success grow the step by ``growth``, after a failure halve it and
  retry from the last accepted ε; stop when the step falls below ``min_step`` or after
  :data:`MAX_ATTEMPTS` attempts.
- ``none``: solve ε = 1 directly.
"""

from __future__ import annotations

from collections.abc import Callable

from .problem import HomotopyOptions
from .registries import HOMOTOPY_MODES

#: most attempts of the adaptive continuation (each is an Ipopt solve)
MAX_ATTEMPTS = 10_000

__all__ = [
    "MAX_ATTEMPTS",
    "run_continuation",
    "fixed_schedule",
    "fixed_continuation",
    "adaptive_continuation",
    "direct_to_one",
]


def fixed_schedule(step: float) -> list[float]:
    """ε = δ, 2δ, …, 1 (the last step shorter when 1/δ is not an integer)."""
    steps = max(1, round(1.0 / step))
    if abs(steps * step - 1.0) > 1e-9:
        steps = int(1.0 / step) + 1
    return [min(1.0, round(k * step, 12)) for k in range(1, steps + 1)]


def fixed_continuation(attempt: Callable[[float], bool], options: HomotopyOptions) -> float:
    """ε = δ, 2δ, …, 1; stop at the first failure. Returns the last ε solved (0.0 if none)."""
    accepted = 0.0
    for eps in fixed_schedule(options.step):
        if not attempt(eps):
            return accepted
        accepted = eps
    return accepted


def adaptive_continuation(attempt: Callable[[float], bool], options: HomotopyOptions) -> float:
    """Grow the step by ``growth`` after a success, halve it after a failure; give up below ``min_step``."""
    accepted, step = 0.0, options.step
    for _ in range(MAX_ATTEMPTS):
        if accepted >= 1.0:
            break
        eps = min(1.0, round(accepted + step, 12))
        if attempt(eps):
            accepted = eps
            step *= options.growth
        else:
            step *= 0.5
            if step < options.min_step:
                return accepted
    return accepted


def direct_to_one(attempt: Callable[[float], bool], options: HomotopyOptions) -> float:
    """No continuation: solve ε = 1 directly."""
    return 1.0 if attempt(1.0) else 0.0


def run_continuation(attempt: Callable[[float], bool], options: HomotopyOptions) -> float:
    """Drive ``attempt`` from ε ≈ 0 to ε = 1 with the mode's driver; return the last ε that succeeded (0.0 if none)."""
    return HOMOTOPY_MODES[options.mode](attempt, options)
