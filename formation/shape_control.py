"""Formation shape and orientation controllers on the Jacobi vectors (docs/theory/formation_control.md §2–§3).

Source: Zhang & Leonard (2010), §V, eqs. 41-43.

After the Jacobi transform (:mod:`mobisense.formation.jacobi`) the shape dynamics are N − 1 decoupled double
integrators ``q_j'' = u_j``, independent of the centre. Two controllers:

* :class:`FixedShapeController` — ``u_j = q_j^d'' − K2 (q_j − q_j^d) − K3 (q_j' − q_j^d')``: the paper's
  law ``u_j = −K2 (q_j − q_j^d) − K3 q_j'`` plus a feed-forward of the desired motion (zero for a constant
  shape). The error ``e = q − q^d`` obeys ``e'' + K3 e' + K2 e = 0`` exactly — exponential for
  ``K2, K3 > 0``.
* :class:`RotatingShapeController` — a formation turning at a prescribed angular speed (eqs. 42-43).
  The controller carries the frame angle ψ and angular speed Ω as its own states (``ψ' = Ω``), writes
  ``q_j = g(ψ) p_j`` with the planar rotation ``g``, imposes ``p_j'' = −K4 (p_j − p_j^d) − K5 p_j'`` and
  ``Ω' = −K6 (Ω − Ω^d) + Ω^d'``, and recovers ``u_j = g (p_j'' + 2Ω × p_j' + Ω × (Ω × p_j) + Ω' × p_j)``
  (eq. 42; in the plane ``Ω × p = Ω J p``, ``Ω × (Ω × p) = −Ω² p``). Keeping ψ as a controller state
  (rather than the measured angle of one Jacobi vector) avoids the redundancy of 2(N − 1) coordinates
  ``p`` plus one angle for 2(N − 1) degrees of freedom; the p-errors then follow the linear system
  ``e'' + K5 e' + K4 e = 0`` exactly and ``q_j → g(ψ(t)) p_j^d``.

Shapes: ``(..., N−1, 2)`` for Jacobi vectors and their derivatives (length L, time T).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..estimation.checks import check_finite, check_finite_array, check_positive
from ..estimation.cooperative.information_model import rotation

__all__ = [
    "perp",
    "FixedShapeController",
    "RotatingShapeController",
    "rotating_frame_state",
    "shape_error",
]


def perp(x: np.ndarray) -> np.ndarray:
    """``J x`` with ``J = [[0, −1], [1, 0]]``: vectors turned by +90° (``Ω × x = Ω J x`` in the plane)."""
    x = np.asarray(x, dtype=float)
    return np.stack([-x[..., 1], x[..., 0]], axis=-1)


def shape_error(q: np.ndarray, q_desired: np.ndarray) -> np.ndarray:
    """``‖q − q^d‖`` over all Jacobi vectors (Frobenius norm, L), shape ``(...)``."""
    return np.sqrt(np.sum((np.asarray(q) - np.asarray(q_desired)) ** 2, axis=(-2, -1)))


@dataclass(frozen=True)
class FixedShapeController:
    """PD control of the Jacobi vectors to a desired shape (docs/theory/formation_control.md §2).

    Source: Zhang & Leonard (2010), §V-A after eq. 41.

    Parameters
    ----------
    stiffness : float
        ``K2`` (1/T²).
    damping : float
        ``K3`` (1/T).
    """

    stiffness: float
    damping: float

    def __post_init__(self) -> None:
        for name in ("stiffness", "damping"):
            object.__setattr__(self, name, check_positive(name, getattr(self, name)))

    def __call__(
        self,
        q: np.ndarray,
        dq: np.ndarray,
        q_desired: np.ndarray,
        dq_desired: np.ndarray | float = 0.0,
        ddq_desired: np.ndarray | float = 0.0,
    ) -> np.ndarray:
        """Shape forces ``u`` ``(..., N−1, 2)`` for ``q``, ``q'`` and the desired ``q^d`` (and its rates)."""
        K2, K3 = self.stiffness, self.damping
        # docs/theory/formation_control.md, eq. formation_control.6
        return ddq_desired - K2 * (q - q_desired) - K3 * (dq - dq_desired)


def rotating_frame_state(
    q: np.ndarray, dq: np.ndarray, psi: np.ndarray, omega: np.ndarray
) -> tuple[np.ndarray, ...]:
    """Body-frame coordinates ``p = g(ψ)⁻¹ q`` and ``p' = g⁻¹ q' − Ω × p`` (from ``q' = g (p' + Ω × p)``)."""
    g_inv = rotation(-np.asarray(psi, dtype=float))[..., None, :, :]
    p = (g_inv @ np.asarray(q, dtype=float)[..., None])[..., 0]
    dp = (g_inv @ np.asarray(dq, dtype=float)[..., None])[..., 0] - np.asarray(omega)[..., None, None] * perp(
        p
    )
    return p, dp


@dataclass(frozen=True)
class RotatingShapeController:
    """A formation rotating about its centre at a prescribed angular speed (docs/theory/formation_control.md §3).

    Source: Zhang & Leonard (2010), eqs. 42-43.

    Parameters
    ----------
    p_desired : ndarray, shape (N−1, 2)
        ``p_j^d``, the desired Jacobi vectors in the rotating frame (L).
    angular_speed : float or callable
        ``Ω^d`` (rad/T), or ``t ↦ (Ω^d(t), Ω^d'(t))``.
    shape_stiffness, shape_damping : float
        ``K4`` (1/T²), ``K5`` (1/T).
    angular_gain : float
        ``K6`` (1/T).
    """

    p_desired: np.ndarray
    angular_speed: float | Callable[[float], tuple[float, float]]
    shape_stiffness: float
    shape_damping: float
    angular_gain: float

    def __post_init__(self) -> None:
        p_desired = check_finite_array("p_desired", self.p_desired, "(N−1, 2) with N >= 2",
                                       lambda s: len(s) == 2 and s[0] >= 1 and s[1] == 2)  # fmt: skip
        object.__setattr__(self, "p_desired", p_desired)
        for name in ("shape_stiffness", "shape_damping", "angular_gain"):
            object.__setattr__(self, name, check_positive(name, getattr(self, name)))
        if not callable(self.angular_speed):
            object.__setattr__(self, "angular_speed", check_finite("angular_speed", self.angular_speed))

    def desired_rate(self, t: float) -> tuple[float, float]:
        """``(Ω^d(t), Ω^d'(t))``."""
        if callable(self.angular_speed):
            return self.angular_speed(t)
        return float(self.angular_speed), 0.0

    def __call__(
        self, t: float, q: np.ndarray, dq: np.ndarray, psi: float, omega: float
    ) -> tuple[np.ndarray, float, float]:
        """Shape forces and the frame's rates.

        Parameters
        ----------
        t : float
            Time (T).
        q, dq : ndarray, shape (N−1, 2)
            Jacobi vectors and their rates.
        psi, omega : float
            The controller's frame angle ψ (rad) and angular speed Ω (rad/T).

        Returns
        -------
        u : ndarray, shape (N−1, 2)
            ``q'' = u`` (eq. 42).
        dpsi, domega : float
            ``ψ' = Ω`` and ``Ω' = −K6 (Ω − Ω^d) + Ω^d'`` (eq. 43).
        """
        p, dp = rotating_frame_state(q, dq, psi, omega)
        omega_d, domega_d = self.desired_rate(t)
        ddp = -self.shape_stiffness * (p - self.p_desired) - self.shape_damping * dp  # eq. formation_control.9
        domega = -self.angular_gain * (omega - omega_d) + domega_d  # eq. formation_control.9
        body = ddp + 2 * omega * perp(dp) - omega**2 * p + domega * perp(p)  # eq. formation_control.8 (planar)
        u = (rotation(psi) @ body[..., None])[..., 0]
        return u, omega, domega
