"""Information dynamics of a formation (docs/theory/cooperative.md §1): the Taylor matrices C, D and the transition A.

The one implementation of the cooperative-exploration model used by every filter, Gramian and design
tool of :mod:`estimation`. All functions are vectorised with the batch dimensions first: platform
positions have shape ``(..., N, 2)`` (length unit L of the field, e.g. km), so a Monte Carlo batch of
trajectories ``(B, K, N, 2)`` goes through unchanged.

State ``s = [z(r_c), ∂z/∂x(r_c), ∂z/∂y(r_c)]`` (field unit, field unit / L); Hessians are stored either
as ``(..., 2, 2)`` matrices or in the 4-vector form of Zhang & Leonard (2010) ``vec(H) = [H11, H21, H12, H22]`` (eq. 5).

The model functions also take a :class:`~mobisense.estimation.components.ComponentMatrix` (positions
``(N, 2)``, shifts ``(2, 1)``, Hessians ``(2, 2)``, each entry an array over the batch): the same formulas
then run on one contiguous array per entry, which is how the filter treats thousands of runs with their
own trajectories (:mod:`mobisense.estimation.cooperative.rollouts`).

Example
-------
>>> import numpy as np
>>> from mobisense.estimation.cooperative.information_model import taylor_matrices
>>> C, D = taylor_matrices(np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, 2.0], [0.0, -2.0]]))
>>> C.shape, D.shape
((4, 3), (4, 4))
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..components import ComponentMatrix

__all__ = [
    "formation_center",
    "relative_positions",
    "taylor_matrices",
    "hessian_to_vec",
    "vec_to_hessian",
    "transition_matrix",
    "hessian_drift",
    "cross_formation",
    "rotation",
]


def formation_center(positions: np.ndarray) -> np.ndarray:
    """Formation centre ``r_c = mean_i r_i`` (docs/theory/cooperative.md §1.1).

    Parameters
    ----------
    positions : ndarray, shape (..., N, 2)
        Platform positions (L).

    Returns
    -------
    ndarray, shape (..., 2) (a ``(1, 2)`` component matrix for component positions)
    """
    if isinstance(positions, ComponentMatrix):
        n = positions.shape[0]
        return ComponentMatrix([[sum(row[j] for row in positions.rows) * (1.0 / n) for j in range(2)]])
    positions = np.asarray(positions, dtype=float)
    return np.add.reduce(positions, axis=-2) / positions.shape[-2]  # np.mean's arithmetic, without its overhead


def relative_positions(positions: np.ndarray) -> np.ndarray:
    """Offsets ``r_i − r_c`` of the platforms from the formation centre, shape ``(..., N, 2)``."""
    if isinstance(positions, ComponentMatrix):
        center = formation_center(positions).rows[0]
        return ComponentMatrix([[row[0] - center[0], row[1] - center[1]] for row in positions.rows])
    positions = np.asarray(positions, dtype=float)
    return positions - formation_center(positions)[..., None, :]


def taylor_matrices(positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Measurement matrices of the second-order Taylor model about the formation centre.

    Parameters
    ----------
    positions : ndarray, shape (..., N, 2)
        Platform positions (L).

    Returns
    -------
    C : ndarray, shape (..., N, 3)
        Row i is ``[1, (r_i − r_c)']`` (docs/theory/cooperative.md, eq. cooperative.2).
    D : ndarray, shape (..., N, 4)
        Row i is ``½ ((r_i − r_c) ⊗ (r_i − r_c))'`` so that ``D vec(H)`` is the quadratic term (eq. 6).
    """
    dr = relative_positions(positions)
    if isinstance(dr, ComponentMatrix):  # the same rows, entry by entry
        C = ComponentMatrix([[1.0, x, y] for x, y in dr.rows])  # docs/theory/cooperative.md, eq. cooperative.2
        D = []
        for x, y in dr.rows:
            xy = 0.5 * x * y  # x y = y x: one array for both entries
            D.append([0.5 * x * x, xy, xy, 0.5 * y * y])  # docs/theory/cooperative.md, eq. cooperative.2
        return C, ComponentMatrix(D)
    ones = np.ones(dr.shape[:-1] + (1,))
    C = np.concatenate([ones, dr], axis=-1)  # docs/theory/cooperative.md, eq. cooperative.2
    # docs/theory/cooperative.md, eq. cooperative.2
    D = 0.5 * (dr[..., :, None] * dr[..., None, :]).reshape(dr.shape[:-1] + (4,))
    return C, D


def hessian_to_vec(hessian: np.ndarray) -> np.ndarray:
    """``vec(H) = [H11, H21, H12, H22]`` of ``(..., 2, 2)`` matrices, shape ``(..., 4)`` (eq. cooperative.3).

    Column-major stacking; for the row-major ``kron(Δr, Δr) = [x², xy, yx, y²]`` used in ``D`` this gives
    ``D vec(H) = ½ Δr' H Δr`` for any (even non-symmetric) H. A ``(2, 2)`` component matrix gives a
    ``(4, 1)`` one.
    """
    if isinstance(hessian, ComponentMatrix):
        (h11, h12), (h21, h22) = hessian.rows
        return ComponentMatrix([[h11], [h21], [h12], [h22]])
    hessian = np.asarray(hessian, dtype=float)
    return np.swapaxes(hessian, -1, -2).reshape(hessian.shape[:-2] + (4,))


def vec_to_hessian(vec: np.ndarray) -> np.ndarray:
    """Inverse of :func:`hessian_to_vec`: ``(..., 4)`` → ``(..., 2, 2)``."""
    vec = np.asarray(vec, dtype=float)
    return np.swapaxes(vec.reshape(vec.shape[:-1] + (2, 2)), -1, -2)


def transition_matrix(center_shift: Any) -> Any:
    """State transition ``A = [[1, Δr'], [0, I_2]]`` for a centre shift Δr (eq. cooperative.5).

    Parameters
    ----------
    center_shift : ndarray, shape (..., 2), or CasADi or component column (2, 1)
        ``Δr = r_{c,k} − r_{c,j}`` (L). By Lemma 3.1 the same matrix is the transition ``Φ(k, j)`` for
        any ``k, j`` (either order), so Gramians use it directly.

    Returns
    -------
    ndarray, shape (..., 3, 3), or CasADi or component (3, 3) with structural zeros and ones
    """
    if isinstance(center_shift, ComponentMatrix):
        (dx,), (dy,) = center_shift.rows
        # docs/theory/cooperative.md, eq. cooperative.5
        return ComponentMatrix([[1.0, dx, dy], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    if not isinstance(center_shift, (np.ndarray, list, tuple)):  # CasADi symbol: same matrix, symbolically
        import casadi as ca

        # docs/theory/cooperative.md, eq. cooperative.5
        return ca.blockcat([[ca.DM(1), center_shift.T], [ca.DM.zeros(2, 1), ca.DM.eye(2)]])
    center_shift = np.asarray(center_shift, dtype=float)
    A = np.zeros(center_shift.shape[:-1] + (3, 3))
    A[..., 0, 0] = A[..., 1, 1] = A[..., 2, 2] = 1.0
    A[..., 0, 1:] = center_shift  # docs/theory/cooperative.md, eq. cooperative.5
    return A


def hessian_drift(hessian: np.ndarray, center_shift: np.ndarray) -> np.ndarray:
    """Known input ``h = [½ Δr' H Δr, (H Δr)']'`` of the state equation, shape ``(..., 3)`` (eq. cooperative.5).

    Parameters
    ----------
    hessian : ndarray, shape (..., 2, 2)
        Hessian estimate at the previous centre (field unit / L²).
    center_shift : ndarray, shape (..., 2)
        ``r_{c,k} − r_{c,k−1}`` (L).

    Notes
    -----
    Zhang & Leonard (2010), eq. 8, propagate the field value to first order only, ``h = [0; H Δr]``, leaving
    ``½ Δr' H Δr`` to the noise ``ε``. We keep that second-order term, known once ``Ĥ`` is: the state
    equation is then exact on quadratic fields (tested), and the two agree to O(‖Δr‖²).

    Component matrices (Hessian ``(2, 2)``, shift ``(2, 1)``) give a ``(3, 1)`` component column.
    """
    if isinstance(center_shift, ComponentMatrix):
        Hdr = hessian @ center_shift
        half_curvature = 0.5 * (center_shift.T @ Hdr)  # docs/theory/cooperative.md, eq. cooperative.5
        return ComponentMatrix(half_curvature.rows + Hdr.rows)
    center_shift = np.asarray(center_shift, dtype=float)
    Hdr = np.matmul(hessian, center_shift[..., None])[..., 0]
    half_curvature = 0.5 * np.sum(center_shift * Hdr, axis=-1, keepdims=True)  # ½ Δr' H Δr
    return np.concatenate([half_curvature, Hdr], axis=-1)  # docs/theory/cooperative.md, eq. cooperative.5


def rotation(angle: np.ndarray | float) -> np.ndarray:
    """Planar rotation matrices ``[[cos, −sin], [sin, cos]]``, shape ``(..., 2, 2)`` for angles (rad)."""
    angle = np.asarray(angle, dtype=float)
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([np.stack([c, -s], axis=-1), np.stack([s, c], axis=-1)], axis=-2)


def cross_formation(
    a: np.ndarray | float,
    b: np.ndarray | float,
    center: np.ndarray | None = None,
    orientation: np.ndarray | float = 0.0,
) -> np.ndarray:
    """Positions of the four-platform cross (docs/theory/steady_state.md §2): 1, 2 at ∓a along e1, 3, 4 at ±b along e2.

    Parameters
    ----------
    a, b : float or ndarray, shape (...)
        Half-distances of the pairs (1, 2) and (3, 4) (L).
    center : ndarray, shape (..., 2), optional
        Formation centre (L); the origin by default.
    orientation : float or ndarray, shape (...)
        Angle of e1 from the lab x axis (rad).

    Returns
    -------
    ndarray, shape (..., 4, 2)
    """
    a, b = np.broadcast_arrays(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
    zero = np.zeros_like(a)
    body = np.stack(
        [np.stack([-a, zero], -1), np.stack([a, zero], -1), np.stack([zero, b], -1), np.stack([zero, -b], -1)],
        axis=-2,
    )
    R = rotation(orientation)
    out = np.matmul(body, np.swapaxes(R, -1, -2))  # rows r_i' R' = (R r_i)'
    if center is not None:
        out = out + np.asarray(center, dtype=float)[..., None, :]
    return out
