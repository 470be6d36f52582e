"""Kalman predict/update kernels shared by every filter of :mod:`estimation` (one implementation each).

The kernels are written once with ``@``, ``+`` and the two helpers :func:`transpose` and :func:`solve`,
so they evaluate either on numpy arrays with leading batch dimensions (state ``(..., n, 1)``,
covariance ``(..., n, n)``; broadcasting lets a covariance shared by all Monte Carlo runs stay
unbatched) or on CasADi ``SX`` matrices, from which :mod:`mobisense.estimation.cooperative.filter` compiles a
whole-trajectory rollout. Vectors are columns inside the kernels.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = [
    "transpose",
    "solve",
    "inverse",
    "identity",
    "predict",
    "innovation",
    "update",
    "information_contribution",
    "information_update",
    "symmetrize",
]


def _is_numeric(x: Any) -> bool:
    return isinstance(x, (np.ndarray, float, int, np.floating))


def transpose(X: Any) -> Any:
    """Swap the last two axes (numpy, batched) or transpose (CasADi)."""
    return np.swapaxes(X, -1, -2) if _is_numeric(X) else X.T


def solve(S: Any, Y: Any) -> Any:
    """``S⁻¹ Y`` for a symmetric positive definite ``S`` (numpy batched or CasADi)."""
    if _is_numeric(S) and _is_numeric(Y):
        return np.linalg.solve(S, Y)  # batch dimensions broadcast
    import casadi as ca

    return ca.solve(S, Y)


def inverse(S: Any) -> Any:
    """``S⁻¹`` of a small symmetric positive definite matrix (numpy batched or CasADi)."""
    if _is_numeric(S):
        return np.linalg.inv(S)
    import casadi as ca

    return ca.inv(S)


def identity(n: int, like: Any) -> Any:
    """``I_n`` as numpy array or CasADi ``SX`` matching ``like``."""
    if _is_numeric(like):
        return np.eye(n)
    import casadi as ca

    return ca.SX.eye(n)


def symmetrize(P: Any) -> Any:
    """``(P + P')/2``: removes round-off asymmetry after an update."""
    return 0.5 * (P + transpose(P))


def predict(x: Any, P: Any, F: Any, Q: Any, u: Any = 0.0) -> tuple[Any, Any]:
    """Time update ``x⁻ = F x + u``, ``P⁻ = F P F' + Q`` (docs/theory/cooperative.md, eq. cooperative.6).

    Parameters
    ----------
    x : array, shape (..., n, 1)
    P : array, shape (..., n, n)
    F : array, shape (..., n, n)
        Transition matrix.
    Q : array, shape (..., n, n)
        Process-noise covariance.
    u : array, shape (..., n, 1), optional
        Known input (the Hessian drift ``h``).
    """
    x_prior = F @ x + u  # docs/theory/cooperative.md, eq. cooperative.6
    P_prior = F @ P @ transpose(F) + Q  # docs/theory/cooperative.md, eq. cooperative.6
    return x_prior, P_prior


def innovation(x: Any, P: Any, y: Any, H: Any, R: Any) -> tuple[Any, Any]:
    """Innovation ``ν = y − H x`` and its covariance ``S = H P H' + R`` (docs/theory/cooperative.md §2.2)."""
    return y - H @ x, H @ P @ transpose(H) + R


def update(x: Any, P: Any, y: Any, H: Any, R: Any) -> tuple[Any, Any, Any, Any]:
    """Measurement update with the Joseph form (docs/theory/cooperative.md, eqs. cooperative.7–8).

    Parameters
    ----------
    x : array, shape (..., n, 1)
        Prior state.
    P : array, shape (..., n, n)
        Prior covariance.
    y : array, shape (..., m, 1)
        Measurement minus its known part (``p − D Ĥ``).
    H : array, shape (..., m, n)
        Measurement matrix (``C``).
    R : array, shape (..., m, m)
        Measurement-noise covariance (``D U D' + R``).

    Returns
    -------
    x_post, P_post, innovation, S
        Posterior state and covariance, innovation ``y − H x`` and its covariance ``S``.

    Notes
    -----
    The gain is computed as ``K' = S⁻¹ (H P)`` (a solve, never an inverse), and the covariance with
    Joseph's form ``(I − K H) P (I − K H)' + K R K'``, which stays symmetric positive semidefinite for any
    gain and equals eq. 17's information form for the optimal one.
    """
    nu, S = innovation(x, P, y, H, R)
    K = transpose(solve(S, H @ P))  # K = P H' S⁻¹ (S and P symmetric), docs/theory/cooperative.md, eq. cooperative.7
    x_post = x + K @ nu  # docs/theory/cooperative.md, eq. cooperative.7
    I_KH = identity(P.shape[-1], P) - K @ H
    # docs/theory/cooperative.md, eq. cooperative.8 (Joseph form)
    P_post = I_KH @ P @ transpose(I_KH) + K @ R @ transpose(K)
    return x_post, P_post, nu, S


def information_contribution(y: Any, H: Any, R: Any) -> tuple[Any, Any]:
    """Information carried by one measurement: ``J = H' R⁻¹ H`` and ``j = H' R⁻¹ y`` (docs/theory/cooperative.md §2.3).

    Independent of the state, so it is computed for all steps of a trajectory at once (numpy batched).
    """
    Rinv_H_y = solve(R, _hcat(H, y))
    Ht = transpose(H)
    n = H.shape[-1]
    return Ht @ Rinv_H_y[..., :n], Ht @ Rinv_H_y[..., n:]


def information_update(x: Any, P: Any, J: Any, j: Any) -> tuple[Any, Any]:
    """Measurement update in information form (docs/theory/cooperative.md, eq. cooperative.9).

    ``P⁺ = (P⁻¹ + J)⁻¹`` and ``x⁺ = P⁺ (P⁻¹ x + j)``, equal to :func:`update` for the optimal gain, with
    only ``n × n`` inverses left in the sequential recursion (``J, j`` from
    :func:`information_contribution`).
    """
    P_inv = inverse(P)
    P_post = symmetrize(inverse(P_inv + J))  # docs/theory/cooperative.md, eq. cooperative.9
    # docs/theory/cooperative.md, eq. cooperative.9 (eq. cooperative.7 with K = P⁺ H' R⁻¹)
    x_post = P_post @ (P_inv @ x + j)
    return x_post, P_post


def _hcat(A: Any, B: Any) -> Any:
    if _is_numeric(A):
        batch = np.broadcast_shapes(A.shape[:-2], B.shape[:-2])
        return np.concatenate(
            [np.broadcast_to(A, batch + A.shape[-2:]), np.broadcast_to(B, batch + B.shape[-2:])], axis=-1
        )
    import casadi as ca

    return ca.horzcat(A, B)
