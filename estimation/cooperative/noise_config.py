"""Noise covariances of the cooperative filter (docs/theory/cooperative.md §1–§3): M, R and U, in Python and in YAML.

:class:`CooperativeNoise` holds the three covariances as arrays; :class:`NoiseConfig` is the YAML form
``noise: {sigma_process: 0.1, sigma_measurement: 0.5, sigma_hessian: 1.0}`` used by formation files
(docs/theory/steady_state.md §2: ``M = σ1² I_3``, ``R = σ2² I_N``, ``U = σ3² I_4``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...core.config import NonNegativeFloat, PositiveFloat, StrictModel
from ..kalman import congruence

__all__ = ["CooperativeNoise", "NoiseConfig"]


@dataclass(frozen=True)
class CooperativeNoise:
    """Covariances of the information model (docs/theory/cooperative.md, eqs. cooperative.4–5).

    Parameters
    ----------
    process : ndarray, shape (3, 3)
        ``M = E[ε ε']``, covariance of the state-equation noise per step (field units², see ``s``).
    measurement : float or ndarray, shape (N,) or (N, N)
        ``R = E[n n']``: a variance shared by all platforms, per-platform variances, or a full matrix
        (field unit²).
    hessian_error : ndarray, shape (4, 4)
        ``U = E[e e']``, covariance of the error of ``vec(Ĥ)`` ((field unit / L²)²).
    """

    process: np.ndarray
    measurement: np.ndarray | float
    hessian_error: np.ndarray

    def __post_init__(self) -> None:
        M = np.asarray(self.process, dtype=float)
        U = np.asarray(self.hessian_error, dtype=float)
        if M.shape != (3, 3):
            raise ValueError(f"process covariance M: expected shape (3, 3), got {M.shape}")
        if U.shape != (4, 4):
            raise ValueError(f"hessian_error covariance U: expected shape (4, 4), got {U.shape}")
        R = np.asarray(self.measurement, dtype=float)
        if R.ndim > 2 or R.size == 0:
            raise ValueError(
                f"measurement covariance R: expected a scalar, (N,) or (N, N) with N >= 1, got shape {R.shape}"
            )
        for name, matrix in (("process covariance M", M), ("hessian_error covariance U", U),
                             ("measurement covariance R", R if R.ndim == 2 else np.diag(np.atleast_1d(R)))):
            _check_covariance(name, matrix)
        object.__setattr__(self, "process", M)
        object.__setattr__(self, "hessian_error", U)
        object.__setattr__(self, "measurement", R)

    @classmethod
    def from_sigmas(cls, sigma_process: float, sigma_measurement: float, sigma_hessian: float) -> CooperativeNoise:
        """``M = σ1² I_3``, ``R = σ2² I_N``, ``U = σ3² I_4`` (docs/theory/steady_state.md §2)."""
        return cls(
            process=sigma_process**2 * np.eye(3),
            measurement=float(sigma_measurement) ** 2,
            hessian_error=sigma_hessian**2 * np.eye(4),
        )

    def measurement_matrix(self, n_platforms: int) -> np.ndarray:
        """``R`` as an ``(N, N)`` matrix."""
        R = self.measurement
        if R.ndim == 0:
            return float(R) * np.eye(n_platforms)
        if R.ndim == 1:
            if R.shape != (n_platforms,):
                raise ValueError(f"measurement variances: expected {n_platforms} values, got {R.shape[0]}")
            return np.diag(R)
        if R.shape != (n_platforms, n_platforms):
            raise ValueError(f"measurement covariance R: expected shape ({n_platforms}, {n_platforms}), got {R.shape}")
        return R

    def total_measurement_covariance(self, D: np.ndarray) -> np.ndarray:
        """``D U D' + R`` (docs/theory/cooperative.md §2), shape ``(..., N, N)`` for ``D`` of shape ``(..., N, 4)``."""
        return congruence(D, self.hessian_error) + self.measurement_matrix(D.shape[-2])


class NoiseConfig(StrictModel):
    """YAML form of :class:`CooperativeNoise` with isotropic covariances (standard deviations)."""

    sigma_process: PositiveFloat
    sigma_measurement: PositiveFloat
    sigma_hessian: NonNegativeFloat = 0.0

    def to_noise(self) -> CooperativeNoise:
        """The corresponding :class:`CooperativeNoise`."""
        return CooperativeNoise.from_sigmas(self.sigma_process, self.sigma_measurement, self.sigma_hessian)


def _check_covariance(name: str, matrix: np.ndarray) -> None:
    """Raise ``ValueError`` unless ``matrix`` is a finite, square, symmetric positive semidefinite matrix."""
    if matrix.shape[0] != matrix.shape[1] or not np.all(np.isfinite(matrix)):
        raise ValueError(f"{name}: expected a finite square matrix, got shape {matrix.shape}")
    scale = max(1.0, float(np.abs(matrix).max(initial=0.0)))
    if np.abs(matrix - matrix.T).max(initial=0.0) > 1e-12 * scale:
        raise ValueError(f"{name}: expected a symmetric matrix")
    smallest = float(np.linalg.eigvalsh(0.5 * (matrix + matrix.T))[0]) if matrix.size else 0.0
    if smallest < -1e-12 * scale:
        raise ValueError(f"{name}: expected a positive semidefinite matrix, smallest eigenvalue {smallest:g}")

