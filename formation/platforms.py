"""Newtonian platforms ``r_i'' = f_i`` (unit mass) with force and speed limits (docs/theory/formation_control.md §5).

:class:`PlatformLimits` turns the commanded forces into the applied ones:

* force limit — ``f ← f · min(1, f_max/‖f‖)`` per platform (direction kept);
* speed limit — where ``‖v‖ ≥ v_max`` the component of ``f`` that would speed the platform up further
  (``f·v > 0``) is removed, so ``d‖v‖/dt ≤ 0`` there and ``‖v‖`` never exceeds ``max(v_max, ‖v(0)‖)``.

Limits break the exact decoupling of the Jacobi transform (a saturated shape force moves the centre);
without them :func:`PlatformLimits.apply` is the identity. Shapes ``(..., N, 2)``; units L, T (forces are
accelerations, L/T²).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.config import PositiveFloat, StrictModel
from ..estimation.checks import check_positive

__all__ = ["PlatformLimits", "PlatformLimitsConfig", "newton_rates"]


@dataclass(frozen=True)
class PlatformLimits:
    """Force and speed limits of every platform (``None`` = unlimited).

    Parameters
    ----------
    max_force : float, optional
        ``f_max`` (L/T²).
    max_speed : float, optional
        ``v_max`` (L/T).

    Raises
    ------
    ValueError
        For a limit that is not a number > 0 (``inf``, like ``None``, is no limit; NaN is refused).
    """

    max_force: float | None = None
    max_speed: float | None = None

    def __post_init__(self) -> None:
        for name in ("max_force", "max_speed"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, check_positive(name, value, allow_inf=True))

    def apply(self, forces: np.ndarray, velocities: np.ndarray) -> np.ndarray:
        """Applied forces ``(..., N, 2)`` for commanded ``forces`` at ``velocities`` ``(..., N, 2)``."""
        f = np.asarray(forces, dtype=float)
        if self.max_force is not None:
            norm = np.linalg.norm(f, axis=-1, keepdims=True)
            f = f * np.minimum(1.0, self.max_force / np.maximum(norm, 1e-300))
        if self.max_speed is not None:
            v = np.asarray(velocities, dtype=float)
            speed2 = np.sum(v**2, axis=-1, keepdims=True)
            along = np.sum(f * v, axis=-1, keepdims=True)
            blocked = (speed2 >= self.max_speed**2) & (along > 0)
            f = np.where(blocked, f - along / np.maximum(speed2, 1e-300) * v, f)
        return f


def newton_rates(
    velocities: np.ndarray, forces: np.ndarray, limits: PlatformLimits | None = None
) -> np.ndarray:
    """``(r', v') = (v, f)`` flattened for ``solve_ivp``: ``(N, 2), (N, 2)`` → ``(4N,)``."""
    applied = forces if limits is None else limits.apply(forces, velocities)
    return np.concatenate([np.ravel(velocities), np.ravel(applied)])


class PlatformLimitsConfig(StrictModel):
    """YAML form: ``{max_force: 2.0, max_speed: 3.0}`` (both optional)."""

    max_force: PositiveFloat | None = None
    max_speed: PositiveFloat | None = None

    def build(self) -> PlatformLimits:
        """The corresponding :class:`PlatformLimits`."""
        return PlatformLimits(self.max_force, self.max_speed)
