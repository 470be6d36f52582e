"""ε-continuation schedules (SPEC §1.3), shared by the direct and the indirect method.

The driver calls ``attempt(eps)``, which tries to solve at ``eps`` starting from the last accepted
solution and returns whether it succeeded (the caller keeps the accepted state). Modes:

- ``fixed``: ε = δ, 2δ, …, 1 (the paper: δ = 0.05); the first failure stops the continuation.
- ``adaptive``: start with δ; after a success grow the step by ``growth``, after a failure halve it and
  retry from the last accepted ε; stop when the step falls below ``min_step``.
- ``none``: solve ε = 1 directly.
"""

from __future__ import annotations

from collections.abc import Callable

from ocp.problem import HomotopyOptions

__all__ = ["run_continuation"]


def run_continuation(attempt: Callable[[float], bool], options: HomotopyOptions) -> float:
    """Drive ``attempt`` from ε ≈ 0 to ε = 1; return the last ε that succeeded (0.0 if none)."""
    if options.mode == "none":
        return 1.0 if attempt(1.0) else 0.0
    if options.mode == "fixed":
        steps = max(1, round(1.0 / options.step))
        if abs(steps * options.step - 1.0) > 1e-9:
            steps = int(1.0 / options.step) + 1  # last step shorter, ending exactly at 1
        accepted = 0.0
        for k in range(1, steps + 1):
            eps = min(1.0, round(k * options.step, 12))
            if not attempt(eps):
                return accepted
            accepted = eps
        return accepted
    # adaptive
    accepted, step = 0.0, options.step
    while accepted < 1.0:
        eps = min(1.0, round(accepted + step, 12))
        if attempt(eps):
            accepted = eps
            step *= options.growth
        else:
            step *= 0.5
            if step < options.min_step:
                return accepted
    return accepted
