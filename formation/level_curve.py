"""Level-curve tracking of the formation centre (docs/theory/level_curve.md; Zhang & Leonard (2010), §VI, eqs. 44-48).

The centre is a Newtonian particle ``r_c'' = a_c`` (unit mass; the formation's total force is
``f_c = N a_c``, :mod:`mobisense.formation.jacobi`). In Frenet–Serret form, with speed ``α = ‖r_c'‖``, unit velocity
``x2 = r_c'/α`` and its left normal ``y2``: ``α' = v_c = a_c·x2`` and ``x2' = α u_c y2`` with the path
curvature ``u_c = a_c·y2/α²`` (eqs. 44-47), so ``a_c = v_c x2 + α² u_c y2``.

Level-curve frame at ``r_c``: ``y1 = ∇z/‖∇z‖`` and the tangent ``x1`` with ``x1 × y1`` out of the page
(higher values on the left of ``x1``). Heading error θ ∈ (−π, π]: ``cos θ = x1·x2``, ``sin θ = −y1·x2``.
Then ``z' = −α ‖∇z‖ sin θ`` and

    θ' = α (κ1 cos θ + κ2 sin θ − u_c),   κ1 = −x1'∇²z x1/‖∇z‖,   κ2 = +x1'∇²z y1/‖∇z‖.

Sign of κ2 (our derivation; Zhang & Leonard (2010), §VI-A, print a minus; docs/theory/level_curve.md §3.1): θ is the
angle from x2 to x1, the direction of x1 turns at ``−α x1'∇²z x2/‖∇z‖`` along the path, and ``x2 = cos θ x1 − sin θ y1``
gives ``+x1'∇²z y1`` in front of ``sin θ``. :func:`heading_rate` is checked against finite differences of θ along
arbitrary paths in ``tests/test_formation_level_curve.py``; with the printed sign the Lyapunov function below would not
be monotone. κ1 is the signed curvature of the level curve followed along x1.

Steering law (eq. 48) for a level ``C`` and ``f = dh/dz`` (:data:`LEVEL_FUNCTIONS`):

    u_c = κ1 cos θ + κ2 sin θ − 2 f(z) ‖∇z‖ cos²(θ/2) + K4 sin(θ/2),

speed control ``v_c = −K1 (α − α_d)``; ``V = −log cos²(θ/2) + h(z)`` has ``V' = −α K4 sin²(θ/2)/cos(θ/2) ≤ 0``
for every α > 0 (:func:`lyapunov_rate`), so θ → 0 and z → C (Prop. 6.1). Units: L, T, field unit F;
``K1`` 1/T, ``K4`` 1/L, ``f`` 1/F (``h`` dimensionless).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from ..core.registry import Registry
from ..estimation.fields.base import level_curve_frame
from .shape_control import perp

__all__ = [
    "LevelFunction",
    "LinearLevel",
    "ReciprocalLevel",
    "LEVEL_FUNCTIONS",
    "LevelFunctionName",
    "register_level_function",
    "heading_error",
    "curvature_terms",
    "heading_rate",
    "LevelCurveController",
]


class LevelFunction(ABC):
    """``h(z)`` with ``h(C) = 0``, ``h → ∞`` at the field's extrema, ``f = dh/dz`` (the paper's (A1)–(A3))."""

    #: registry key used in scenario files
    kind: str = ""

    def __init__(self, level: float, gain: float = 1.0) -> None:
        if not gain > 0:
            raise ValueError(f"gain: expected > 0, got {gain}")
        self.level, self.gain = float(level), float(gain)

    @abstractmethod
    def f(self, z: np.ndarray) -> np.ndarray:
        """``f(z) = dh/dz`` (1/F)."""

    @abstractmethod
    def h(self, z: np.ndarray) -> np.ndarray:
        """``h(z)`` (dimensionless)."""


#: kind -> LevelFunction subclass
LEVEL_FUNCTIONS: Registry[type[LevelFunction]] = Registry("level function")
#: the schema type of a field naming a level function
LevelFunctionName = LEVEL_FUNCTIONS.choice()


def register_level_function(cls: type[LevelFunction]) -> type[LevelFunction]:
    """Class decorator adding a :class:`LevelFunction` to :data:`LEVEL_FUNCTIONS`."""
    return LEVEL_FUNCTIONS.register(cls.kind, cls)


@register_level_function
class LinearLevel(LevelFunction):
    """``f = k (z − C)``, ``h = ½ k (z − C)²`` (the default; any field)."""

    kind = "linear"

    def f(self, z: np.ndarray) -> np.ndarray:
        """``k (z − C)``."""
        return self.gain * (np.asarray(z) - self.level)

    def h(self, z: np.ndarray) -> np.ndarray:
        """``½ k (z − C)²``."""
        return 0.5 * self.gain * (np.asarray(z) - self.level) ** 2


@register_level_function
class ReciprocalLevel(LevelFunction):
    """``f = k (1/C − 1/z)``, ``h = k (z/C − 1 − log(z/C))`` for positive fields (e.g. potentials).

    ``h → ∞`` both as ``z → 0⁺`` and ``z → ∞`` (assumption A3 for a field with range (0, ∞)).
    """

    kind = "reciprocal"

    def __init__(self, level: float, gain: float = 1.0) -> None:
        super().__init__(level, gain)
        if not self.level > 0:
            raise ValueError(f"the reciprocal level function needs C > 0, got {level}")

    def f(self, z: np.ndarray) -> np.ndarray:
        """``k (1/C − 1/z)``."""
        return self.gain * (1.0 / self.level - 1.0 / np.asarray(z))

    def h(self, z: np.ndarray) -> np.ndarray:
        """``k (z/C − 1 − log(z/C))``."""
        ratio = np.asarray(z) / self.level
        return self.gain * (ratio - 1.0 - np.log(ratio))


def heading_error(velocity: np.ndarray, gradient: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Speed ``α`` and heading error ``θ ∈ (−π, π]`` (eq. level_curve.3) for velocities and gradients ``(..., 2)``."""
    alpha = np.linalg.norm(velocity, axis=-1)
    x2 = np.asarray(velocity, dtype=float) / alpha[..., None]
    x1, y1, _ = level_curve_frame(np.asarray(gradient, dtype=float))
    theta = np.arctan2(-np.sum(y1 * x2, axis=-1), np.sum(x1 * x2, axis=-1))  # cos θ = x1·x2, sin θ = −y1·x2
    return alpha, theta


def curvature_terms(gradient: np.ndarray, hessian: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``κ1 = −x1'∇²z x1/‖∇z‖`` and ``κ2 = x1'∇²z y1/‖∇z‖`` (eq. level_curve.4; sign of κ2 in the module notes)."""
    x1, y1, norm = level_curve_frame(np.asarray(gradient, dtype=float))
    Hx1 = (np.asarray(hessian, dtype=float) @ x1[..., None])[..., 0]
    return -np.sum(x1 * Hx1, axis=-1) / norm, np.sum(y1 * Hx1, axis=-1) / norm


def heading_rate(
    alpha: np.ndarray, theta: np.ndarray, kappa1: np.ndarray, kappa2: np.ndarray, path_curvature: np.ndarray
) -> np.ndarray:
    """``θ' = α (κ1 cos θ + κ2 sin θ − u_c)`` (docs/theory/level_curve.md, eq. level_curve.4)."""
    return alpha * (kappa1 * np.cos(theta) + kappa2 * np.sin(theta) - path_curvature)


@dataclass(frozen=True)
class LevelCurveController:
    """Speed and steering control of the centre along the level ``z = C`` (docs/theory/level_curve.md §4).

    Source: Zhang & Leonard (2010), eq. 48.

    Parameters
    ----------
    level_function : LevelFunction
        ``h`` and ``f`` for the level ``C`` (``level_function.level``).
    speed : float
        Desired speed ``α_d`` (L/T); the paper uses 1.
    speed_gain : float
        ``K1`` (1/T).
    steering_gain : float
        ``K4`` (1/L).
    """

    level_function: LevelFunction
    speed: float = 1.0
    speed_gain: float = 1.0
    steering_gain: float = 1.0

    def __post_init__(self) -> None:
        if min(self.speed, self.speed_gain, self.steering_gain) <= 0:
            raise ValueError("speed, speed_gain and steering_gain must be > 0")

    @property
    def level(self) -> float:
        """The tracked level ``C`` (F)."""
        return self.level_function.level

    def steering(
        self, z: np.ndarray, gradient: np.ndarray, hessian: np.ndarray, theta: np.ndarray
    ) -> np.ndarray:
        """Path curvature ``u_c`` (1/L) of eq. 48."""
        kappa1, kappa2 = curvature_terms(gradient, hessian)
        norm = np.linalg.norm(gradient, axis=-1)
        f = self.level_function.f(z)
        return (
            kappa1 * np.cos(theta)
            + kappa2 * np.sin(theta)
            - 2 * f * norm * np.cos(theta / 2) ** 2
            + self.steering_gain * np.sin(theta / 2)
        )  # docs/theory/level_curve.md, eq. level_curve.6

    def __call__(
        self, velocity: np.ndarray, z: np.ndarray, gradient: np.ndarray, hessian: np.ndarray
    ) -> np.ndarray:
        """Centre acceleration ``a_c = v_c x2 + α² u_c y2`` (L/T²), shape ``(..., 2)``.

        Parameters
        ----------
        velocity : ndarray, shape (..., 2)
            ``r_c'`` (L/T), nonzero.
        z, gradient, hessian : ndarray, shapes (...), (..., 2), (..., 2, 2)
            Field value and derivatives at the centre (true or estimated).
        """
        alpha, theta = heading_error(velocity, gradient)
        x2 = np.asarray(velocity, dtype=float) / alpha[..., None]
        v_c = -self.speed_gain * (alpha - self.speed)  # eq. level_curve.7 (α' = v_c, the paper's eq. 45)
        u_c = self.steering(z, gradient, hessian, theta)
        return v_c[..., None] * x2 + (alpha**2 * u_c)[..., None] * perp(x2)  # eqs. 44-47

    def lyapunov(self, theta: np.ndarray, z: np.ndarray) -> np.ndarray:
        """``V = −log cos²(θ/2) + h(z)`` (eq. level_curve.9; Zhang & Leonard (2010), Proposition 6.1)."""
        return -np.log(np.cos(np.asarray(theta) / 2) ** 2) + self.level_function.h(z)

    def lyapunov_rate(self, alpha: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """``V' = −α K4 sin²(θ/2)/cos(θ/2)`` along the closed loop (≤ 0)."""
        return -alpha * self.steering_gain * np.sin(theta / 2) ** 2 / np.cos(theta / 2)
