"""Sliding-window controllability and observability Gramians of the information model (docs/theory/cooperative.md §4).

For a trajectory of formation positions, :func:`gramians` evaluates at every step k ≥ τ

    C(k, k−τ) = Σ_{j=k−τ}^{k} Φ(k, j) M Φ(k, j)'                                  (Definition 3.3)
    J(k, k−τ) = Σ_{j=k−τ}^{k} Φ(j, k)' C_j' (D_j U D_j' + R)⁻¹ C_j Φ(j, k)        (Definition 3.4)

with ``Φ(k, j) = [[1, (r_{c,k} − r_{c,j})'], [0, I]]`` (Lemma 3.1), and their smallest eigenvalues.
Uniform complete controllability/observability — hence convergence of the cooperative filter
(Theorem 3.12) — needs these minima bounded away from zero along the whole trajectory: a collinear
formation that never rotates (violating Cd5) shows an observability minimum of zero.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .information_model import formation_center, taylor_matrices, transition_matrix
from .noise_config import CooperativeNoise

__all__ = ["Gramians", "gramians"]


@dataclass(frozen=True)
class Gramians:
    """Gramians along a trajectory; steps before the first full window hold NaN.

    Attributes
    ----------
    controllability, observability : ndarray, shape ([B,] K, 3, 3)
    controllability_min, observability_min : ndarray, shape ([B,] K)
        Smallest eigenvalues.
    window : int
        τ (steps).
    """

    controllability: np.ndarray
    observability: np.ndarray
    controllability_min: np.ndarray
    observability_min: np.ndarray
    window: int

    def to_dataset(self) -> Any:
        """The minimum eigenvalues as an ``xarray.Dataset`` over ``step``."""
        import xarray as xr

        dims = ("run", "step") if self.observability_min.ndim == 2 else ("step",)
        return xr.Dataset(
            {
                "controllability_min_eigenvalue": (dims, self.controllability_min),
                "observability_min_eigenvalue": (dims, self.observability_min),
            },
            attrs={"window": self.window},
        )


def gramians(positions: np.ndarray, noise: CooperativeNoise, window: int) -> Gramians:
    """Controllability and observability Gramians over a sliding window (docs/theory/cooperative.md §4).

    Parameters
    ----------
    positions : ndarray, shape ([B,] K, N, 2)
        Platform positions along the trajectory (L).
    noise : CooperativeNoise
        ``M`` (controllability) and ``R``, ``U`` (observability).
    window : int
        τ ≥ 0: each Gramian sums steps ``k − τ … k``.

    Returns
    -------
    Gramians
    """
    positions = np.asarray(positions, dtype=float)
    K = positions.shape[-3]
    if not 0 <= window < K:
        raise ValueError(f"window: expected 0 <= window < number of steps ({K}), got {window}")
    centers = formation_center(positions)  # (..., K, 2)
    C, D = taylor_matrices(positions)
    R_total = noise.total_measurement_covariance(D)
    information = np.swapaxes(C, -1, -2) @ np.linalg.solve(R_total, C)  # C_j' (D U D' + R)⁻¹ C_j
    ctrb = np.zeros(centers.shape[:-1] + (3, 3))
    obsv = np.zeros_like(ctrb)
    now = centers[..., window:, :]
    for lag in range(window + 1):  # j = k − lag, vectorised over k
        then = centers[..., window - lag : K - lag, :]
        Phi_kj = transition_matrix(now - then)  # Φ(k, j), Lemma 3.1
        Phi_jk = transition_matrix(then - now)  # Φ(j, k)
        ctrb[..., window:, :, :] += Phi_kj @ noise.process @ np.swapaxes(Phi_kj, -1, -2)  # Definition 3.3
        obsv[..., window:, :, :] += (
            np.swapaxes(Phi_jk, -1, -2) @ information[..., window - lag : K - lag, :, :] @ Phi_jk
        )  # Definition 3.4
    ctrb[..., :window, :, :] = np.nan
    obsv[..., :window, :, :] = np.nan

    def min_eig(G: np.ndarray) -> np.ndarray:
        out = np.full(G.shape[:-2], np.nan)
        out[..., window:] = np.linalg.eigvalsh(G[..., window:, :, :])[..., 0]
        return out

    return Gramians(ctrb, obsv, min_eig(ctrb), min_eig(obsv), window)
