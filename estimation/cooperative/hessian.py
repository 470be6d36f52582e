"""Cooperative Hessian estimation (docs/theory/hessian.md): one-step filter, least squares, level-curve curvature.

* :func:`one_step_filter` — eq. 33: blend the predicted platform values with new measurements;
* :func:`least_squares_hessian` — the Hessian from the Taylor equations when the formation allows it;
* :func:`curvature_hessian` — algorithm (s.1)-(s.8) for the four-platform cross: curvature of the level
  curve through the centre and the arc-length derivative of ``‖∇z‖`` give the Hessian in the Frenet
  frame (eqs. 35-37), the Taylor equations give the rest;
* :class:`CurvatureHessian`, :class:`LeastSquaresHessian` — the two as closed-loop
  :class:`~mobisense.estimation.cooperative.filter.HessianSource` for :func:`run_cooperative_filter`.

All functions are batched over leading dimensions.

Choices where Zhang & Leonard (2010) is ambiguous (documented and tested; see docs/theory/departures.md):

* The prediction in eq. 33 uses ``s_k(−)`` and ``P_k(−)`` at the *new* centre (the paper writes
  ``s_{k−1}(+)``, which is biased by ``Δr·∇z`` when the formation moves; both agree when it does not),
  and its error covariance includes the Hessian term: ``G = C P(−) C' + D U D'`` (the paper's ``C P C'``
  would trust a poor previous ``Ĥ`` as exact, and the Hessian estimate could never move away from it).
* The paper's ``D'D`` (§IV-B) is singular for every N because ``vec(H)`` repeats ``H12``; the least squares here
  solve for the three distinct entries ``(H11, H12, H22)`` and need the ``N × 3`` design
  ``[x²/2, xy, y²/2]`` to have rank 3 (not true for the cross, whose platforms sit on two axes — hence
  the curvature method) or, without a state estimate, ``N ≥ 6`` for the joint fit of ``z, ∇z, H``.
* (s.3) moves along the gradient to the level curve by solving the *quadratic* Taylor model along that
  line (the paper's linear step leaves an O(a²) offset); (s.6)-(s.7) use signed angles and arc positions
  and the three-point derivative through ``r_J, r_c, r_K`` (equal to the paper's averages for a symmetric
  formation, second-order accurate otherwise).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..fields.base import level_curve_frame
from .information_model import hessian_to_vec, relative_positions, taylor_matrices
from .noise_config import CooperativeNoise
from .spatial_noise import SpatialNoise

__all__ = [
    "one_step_filter",
    "least_squares_hessian",
    "curvature_hessian",
    "CurvatureHessian",
    "LeastSquaresHessian",
]


def one_step_filter(
    predicted: np.ndarray, prediction_covariance: np.ndarray, measurements: np.ndarray, noise_covariance: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Noise-reduced platform values (docs/theory/hessian.md, eq. hessian.2; Zhang & Leonard (2010), eq. 33).

    Parameters
    ----------
    predicted : ndarray, shape (..., N)
        ``ẑ_k = C_k s_k(−) + D_k Ĥ``.
    prediction_covariance : ndarray, shape (..., N, N)
        ``G_k = C_k P_k(−) C_k'`` (may be singular).
    measurements : ndarray, shape (..., N)
        ``p_k``.
    noise_covariance : ndarray, shape (..., N, N)
        ``W_k + R_k``.

    Returns
    -------
    filtered : ndarray, shape (..., N)
        ``z̃ = (I + G Σ⁻¹)⁻¹ ẑ + (I + Σ G⁻¹)⁻¹ p`` with ``Σ = W + R``.
    covariance : ndarray, shape (..., N, N)
        ``(I + G Σ⁻¹)⁻¹ G`` (Prop. 4.1).

    Notes
    -----
    Evaluated as ``Σ (G + Σ)⁻¹ ẑ + G (G + Σ)⁻¹ p`` — algebraically identical, and defined when ``G`` is
    singular (always, for ``N > 3``, since ``rank G ≤ 3``).
    """
    G, Sigma = prediction_covariance, noise_covariance
    total = G + Sigma
    weights_pred = np.linalg.solve(total, np.stack([predicted, measurements], axis=-1))  # (G + Σ)⁻¹ [ẑ, p]
    # docs/theory/hessian.md, eq. hessian.2
    filtered = (Sigma @ weights_pred[..., :1] + G @ weights_pred[..., 1:])[..., 0]
    covariance = Sigma @ np.linalg.solve(total, G)  # docs/theory/hessian.md, eq. hessian.3
    return filtered, 0.5 * (covariance + np.swapaxes(covariance, -1, -2))


def _symmetric_design(offsets: np.ndarray) -> np.ndarray:
    """Rows ``[x²/2, xy, y²/2]`` so that ``row · (H11, H12, H22) = ½ Δr' H Δr``, shape ``(..., N, 3)``."""
    x, y = offsets[..., 0], offsets[..., 1]
    return np.stack([0.5 * x**2, x * y, 0.5 * y**2], axis=-1)


def _entries_to_matrix(h: np.ndarray) -> np.ndarray:
    return np.stack([np.stack([h[..., 0], h[..., 1]], -1), np.stack([h[..., 1], h[..., 2]], -1)], -2)


def _lstsq(A: np.ndarray, b: np.ndarray, what: str) -> np.ndarray:
    """Batched least squares with a rank check (relative singular-value threshold 1e-9)."""
    sv = np.linalg.svd(A, compute_uv=False)
    if np.any(sv[..., -1] <= 1e-9 * sv[..., 0]) or A.shape[-2] < A.shape[-1]:
        raise ValueError(
            f"{what}: the formation does not determine the Hessian (design matrix of rank < {A.shape[-1]}); "
            "use curvature_hessian for the cross or add platforms off its axes"
        )
    return (np.linalg.pinv(A) @ b[..., None])[..., 0]


def least_squares_hessian(
    positions: np.ndarray, values: np.ndarray, state: np.ndarray | None = None
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Hessian at the formation centre from the Taylor equations (docs/theory/hessian.md §2, eq. hessian.4).

    Parameters
    ----------
    positions : ndarray, shape (..., N, 2)
    values : ndarray, shape (..., N)
        Field values at the platforms (e.g. filtered by :func:`one_step_filter`).
    state : ndarray, shape (..., 3), optional
        ``[z_c, ∇z_c]``. Given: solve ``D_s h = z − C s`` for ``h = (H11, H12, H22)`` (rank 3 needed).
        Omitted: fit ``[z_c, ∇z_c, h]`` jointly (``N ≥ 6``, rank 6).

    Returns
    -------
    hessian : ndarray, shape (..., 2, 2)
        With ``state`` given; otherwise ``(state, hessian)`` with the fitted state ``(..., 3)``.
        Exact (to round-off) on quadratic fields with exact values.
    """
    C, _ = taylor_matrices(positions)
    Ds = _symmetric_design(relative_positions(positions))
    values = np.asarray(values, dtype=float)
    if state is not None:
        residual = values - (C @ np.asarray(state, float)[..., None])[..., 0]
        return _entries_to_matrix(_lstsq(Ds, residual, "least_squares_hessian"))
    theta = _lstsq(np.concatenate([C, Ds], axis=-1), values, "least_squares_hessian (joint fit)")
    return theta[..., :3], _entries_to_matrix(theta[..., 3:])


def _three_point_slope(s1: np.ndarray, f1: np.ndarray, s2: np.ndarray, f2: np.ndarray) -> np.ndarray:
    """``f'(0)`` of the parabola through ``(s1, f1), (0, 0), (s2, f2)`` (second-order accurate)."""
    return (f1 * s2**2 - f2 * s1**2) / (s1 * s2 * (s2 - s1))


#: the triangles of Zhang & Leonard (2010), Fig. 2: E = {1, 3, 4} and F = {2, 3, 4}, zero-based
_TRIANGLES = ((0, 2, 3), (1, 2, 3))


def _level_curve_point(
    positions: np.ndarray, values: np.ndarray, hessian: np.ndarray, z_center: np.ndarray, triangle: tuple[int, ...]
) -> tuple[np.ndarray, np.ndarray]:
    """Steps (s.2)-(s.4) for one triangle: the point ``r_J`` on the level curve and the gradient there."""
    pts = positions[..., triangle, :]
    center = pts.mean(axis=-2)
    C_T, D_T = taylor_matrices(pts)  # (s.2): z̃_i = z_E + d_E·(r_i − r_E) + ½ (r_i − r_E)' H (r_i − r_E)
    rhs = values[..., triangle] - (D_T @ hessian_to_vec(hessian)[..., None])[..., 0]
    z_T, d_T = np.split(np.linalg.solve(C_T, rhs[..., None])[..., 0], [1], axis=-1)
    g = np.linalg.norm(d_T, axis=-1)
    u = d_T / g[..., None]
    # (s.3) along ±d_E to z = z_c: solve ½ q t² + g t − Δ = 0 (stable root of the quadratic Taylor model)
    delta = z_center - z_T[..., 0]
    q = np.einsum("...i,...ij,...j->...", u, hessian, u)
    disc = np.maximum(g**2 + 2 * q * delta, 0.0)
    t = 2 * delta / (g + np.sqrt(disc))
    r_J = center + t[..., None] * u
    d_J = d_T + (hessian @ (r_J - center)[..., None])[..., 0]  # (s.4): gradient of the same quadratic at r_J
    return r_J, d_J


def curvature_hessian(
    positions: np.ndarray,
    values: np.ndarray,
    state: np.ndarray,
    initial_hessian: np.ndarray,
    iterations: int = 3,
) -> np.ndarray:
    """Hessian of a four-platform formation from level-curve curvature (docs/theory/hessian.md §4, steps s.1-s.8).

    Parameters
    ----------
    positions : ndarray, shape (..., 4, 2)
        Platforms in the paper's order: 1, 2 on one axis, 3, 4 on the other (the cross).
    values : ndarray, shape (..., 4)
        Filtered platform values ``z̃`` (eq. 33).
    state : ndarray, shape (..., 3)
        ``[z_c, ∇z_c]`` at the formation centre (s.1, from the filter prediction).
    initial_hessian : ndarray, shape (..., 2, 2)
        ``Hᵖ``, the previous estimate (starting point of the iteration).
    iterations : int
        Passes through (s.2)-(s.8), each restarting from the previous result.

    Returns
    -------
    ndarray, shape (..., 2, 2)
        Lab-frame Hessian estimate; where ``∇z_c = 0`` (no level curve) the initial Hessian is returned.
    """
    positions = np.asarray(positions, dtype=float)
    if positions.shape[-2:] != (4, 2):
        raise ValueError(
            f"positions: the curvature algorithm needs 4 platforms, shape (..., 4, 2); got {positions.shape}"
        )
    state = np.asarray(state, dtype=float)
    z_c, d_c = state[..., 0], state[..., 1:]
    r_c = positions.mean(axis=-2)
    x1, y1, g_c = level_curve_frame(d_c)
    offsets = positions - r_c[..., None, :]
    xi, eta = np.einsum("...ni,...i->...n", offsets, x1), np.einsum("...ni,...i->...n", offsets, y1)
    frame = np.stack([x1, y1], axis=-1)  # columns x1, y1: lab = frame @ Frenet
    H = np.asarray(initial_hessian, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        for _ in range(iterations):
            (r_J, d_J), (r_K, d_K) = (_level_curve_point(positions, values, H, z_c, tri) for tri in _TRIANGLES)
            s_J, s_K = np.einsum("...i,...i->...", r_J - r_c, x1), np.einsum("...i,...i->...", r_K - r_c, x1)
            # (s.6) signed angles of the gradient directions from y1: φ(s) with κ = dφ/ds (docs/theory/hessian.md §3)
            phi_J = np.arctan2(np.einsum("...i,...i->...", d_J, -x1), np.einsum("...i,...i->...", d_J, y1))
            phi_K = np.arctan2(np.einsum("...i,...i->...", d_K, -x1), np.einsum("...i,...i->...", d_K, y1))
            kappa = _three_point_slope(s_J, phi_J, s_K, phi_K)
            H_xx = -g_c * kappa  # docs/theory/hessian.md, eq. hessian.7
            # (s.7) H_xy = d‖∇z‖/ds, docs/theory/hessian.md, eq. hessian.5
            H_xy = _three_point_slope(s_J, np.linalg.norm(d_J, axis=-1) - g_c, s_K, np.linalg.norm(d_K, axis=-1) - g_c)
            # (s.8) ½ H_yy η_i² = z̃_i − z_c − ∇z_c·Δr_i − ½ H_xx ξ_i² − H_xy ξ_i η_i, least squares over i
            b = (
                values
                - z_c[..., None]
                - g_c[..., None] * eta
                - 0.5 * H_xx[..., None] * xi**2
                - H_xy[..., None] * xi * eta
            )
            H_yy = 2 * np.sum(eta**2 * b, axis=-1) / np.sum(eta**4, axis=-1)
            H_frenet = _entries_to_matrix(np.stack([H_xx, H_xy, H_yy], axis=-1))
            H_new = frame @ H_frenet @ np.swapaxes(frame, -1, -2)  # rotate back to the lab frame
            H = np.where(np.isfinite(H_new).all(axis=(-2, -1), keepdims=True), H_new, H)
    return H


@dataclass
class _FilteredHessian:
    """Common part of the closed-loop sources: eq. 33 applied to the new measurements."""

    noise: CooperativeNoise
    spatial_noise: SpatialNoise | None = None

    def filtered_values(
        self, positions: np.ndarray, measurements: np.ndarray, state_prior: np.ndarray, covariance_prior: np.ndarray,
        previous_hessian: np.ndarray,
    ) -> np.ndarray:  # fmt: skip
        """``z̃_k`` from :func:`one_step_filter` with ``G = C P(−) C' + D U D'`` and ``Σ = W + R``."""
        C, D = taylor_matrices(positions)
        predicted = (C @ state_prior[..., None] + D @ hessian_to_vec(previous_hessian)[..., None])[..., 0]
        G = C @ covariance_prior @ np.swapaxes(C, -1, -2) + D @ self.noise.hessian_error @ np.swapaxes(D, -1, -2)
        Sigma = self.noise.measurement_matrix(positions.shape[-2])
        if self.spatial_noise is not None:
            Sigma = Sigma + self.spatial_noise.W(positions)
        return one_step_filter(predicted, G, measurements, Sigma)[0]


@dataclass
class CurvatureHessian(_FilteredHessian):
    """Closed-loop Hessian source: one-step filter then :func:`curvature_hessian` (four platforms)."""

    iterations: int = 3

    def __call__(
        self, positions: np.ndarray, measurements: np.ndarray, state_prior: np.ndarray, covariance_prior: np.ndarray,
        previous_hessian: np.ndarray,
    ) -> np.ndarray:  # fmt: skip
        """Hessian estimate ``(..., 2, 2)`` at step k."""
        values = self.filtered_values(positions, measurements, state_prior, covariance_prior, previous_hessian)
        return curvature_hessian(positions, values, state_prior, previous_hessian, self.iterations)


@dataclass
class LeastSquaresHessian(_FilteredHessian):
    """Closed-loop Hessian source: one-step filter then :func:`least_squares_hessian` given ``s_k(−)``."""

    def __call__(
        self, positions: np.ndarray, measurements: np.ndarray, state_prior: np.ndarray, covariance_prior: np.ndarray,
        previous_hessian: np.ndarray,
    ) -> np.ndarray:  # fmt: skip
        """Hessian estimate ``(..., 2, 2)`` at step k."""
        values = self.filtered_values(positions, measurements, state_prior, covariance_prior, previous_hessian)
        return least_squares_hessian(positions, values, state_prior)
