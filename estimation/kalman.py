"""Kalman predict/update kernels shared by every filter of :mod:`estimation` (one implementation each).

The kernels are written once with ``@``, ``+`` and the helpers :func:`transpose`, :func:`solve`,
:func:`inverse` and :func:`identity`, so they evaluate on numpy arrays with leading batch dimensions (state
``(..., n, 1)``, covariance ``(..., n, n)``; broadcasting lets a covariance shared by all Monte Carlo runs
stay unbatched), on CasADi ``SX`` matrices, from which :mod:`mobisense.estimation.cooperative.rollouts`
compiles a whole-trajectory rollout, and on :class:`~mobisense.estimation.components.ComponentMatrix`
(one array over the batch per entry: many tiny filters, one numpy operation per scalar formula). Vectors
are columns inside the kernels.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from .components import ComponentMatrix

__all__ = [
    "transpose",
    "solve",
    "inverse",
    "identity",
    "congruence",
    "whiten",
    "predict",
    "innovation",
    "update",
    "gain",
    "joseph_covariance",
    "state_map",
    "information_contribution",
    "information_update",
    "symmetrize",
]


_NUMERIC = (np.ndarray, float, int, np.floating)


def _is_numeric(x: Any) -> bool:
    return type(x) is np.ndarray or isinstance(x, _NUMERIC)


def transpose(X: Any) -> Any:
    """Swap the last two axes (numpy, batched) or transpose (CasADi, component matrices)."""
    return X.swapaxes(-1, -2) if type(X) is np.ndarray else np.swapaxes(X, -1, -2) if _is_numeric(X) else X.T


def solve(S: Any, Y: Any) -> Any:
    """``S⁻¹ Y`` for a symmetric positive definite ``S`` (numpy batched, component matrices or CasADi)."""
    if _is_numeric(S) and _is_numeric(Y):
        return np.linalg.solve(S, Y)  # batch dimensions broadcast
    if isinstance(S, ComponentMatrix):
        return S.solve(Y)
    import casadi as ca

    return ca.solve(S, Y)


def inverse(S: Any) -> Any:
    """``S⁻¹`` of a small symmetric positive definite matrix (numpy batched, component matrices or CasADi)."""
    if _is_numeric(S):
        return np.linalg.inv(S)
    if isinstance(S, ComponentMatrix):
        return S.inverse()
    import casadi as ca

    return ca.inv(S)


def identity(n: int, like: Any) -> Any:
    """``I_n`` as numpy array (read-only, shared), component matrix or CasADi ``SX`` matching ``like``."""
    if _is_numeric(like):
        return _eye(n)
    if isinstance(like, ComponentMatrix):
        return ComponentMatrix.identity(n)
    import casadi as ca

    return ca.SX.eye(n)


@functools.lru_cache(maxsize=32)
def _eye(n: int) -> np.ndarray:
    eye = np.eye(n)
    eye.flags.writeable = False
    return eye


def symmetrize(P: Any) -> Any:
    """``(P + P')/2``: removes round-off asymmetry after an update."""
    if isinstance(P, ComponentMatrix):
        return P.symmetrize()  # the same average, skipping entries that are symmetric by construction
    return 0.5 * (P + transpose(P))


def congruence(A: Any, M: Any) -> Any:
    """``A M A'`` for a symmetric ``M`` (component matrices compute one triangle of the symmetric result)."""
    if isinstance(A, ComponentMatrix):
        return A.congruence(M)
    return A @ M @ transpose(A)


def whiten(R: Any, Y: Any) -> Any:
    """``L⁻¹ Y`` with ``R = L L'`` the Cholesky factorisation of a symmetric positive definite ``R``."""
    if isinstance(R, ComponentMatrix):
        return R.whiten(Y)
    if _is_numeric(R):
        return np.linalg.solve(np.linalg.cholesky(R), Y)  # batch dimensions broadcast
    import casadi as ca

    return ca.solve(ca.chol(R).T, Y)  # CasADi's chol is the upper factor


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
    P_prior = congruence(F, P) + Q  # F P F' + Q, docs/theory/cooperative.md, eq. cooperative.6
    return x_prior, P_prior


def innovation(x: Any, P: Any, y: Any, H: Any, R: Any) -> tuple[Any, Any]:
    """Innovation ``ν = y − H x`` and its covariance ``S = H P H' + R`` (docs/theory/cooperative.md §2.2)."""
    return y - H @ x, congruence(H, P) + R


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
    K = gain(P, H, S)
    x_post = x + K @ nu  # docs/theory/cooperative.md, eq. cooperative.7
    return x_post, joseph_covariance(P, K, H, R), nu, S


def gain(P: Any, H: Any, S: Any) -> Any:
    """Kalman gain ``K = P H' S⁻¹``, computed as ``K' = S⁻¹ (H P)`` (docs/theory/cooperative.md, eq. cooperative.7).

    ``P`` is the prior covariance ``(..., n, n)``, ``H`` the measurement matrix ``(..., m, n)`` and ``S`` the
    innovation covariance ``(..., m, m)`` of :func:`innovation`; returns ``(..., n, m)``.
    """
    return transpose(solve(S, H @ P))  # S and P symmetric, docs/theory/cooperative.md, eq. cooperative.7


def joseph_covariance(P: Any, K: Any, H: Any, R: Any) -> Any:
    """Posterior covariance ``(I − K H) P (I − K H)' + K R K'`` (docs/theory/cooperative.md, eq. cooperative.8)."""
    I_KH = identity(P.shape[-1], P) - K @ H
    return congruence(I_KH, P) + congruence(K, R)  # docs/theory/cooperative.md, eq. cooperative.8


def state_map(F: Any, u: Any, K: Any, H: Any) -> tuple[Any, Any]:
    """The posterior state as an affine map ``x⁺ = A x + K y + b`` of the previous posterior (eq. cooperative.16).

    :func:`predict` then the state part of :func:`update` with a given gain: ``x⁺ = x⁻ + K (y − H x⁻)``,
    ``x⁻ = F x + u``, so ``A = (I − K H) F`` and ``b = (I − K H) u``. The gains of a filter whose
    covariance recursion is shared by many runs (one trajectory, many measurement sequences) are the same
    for all runs, and so are ``A`` and ``b``: each step of the batch is then one small matrix product.

    Returns
    -------
    A : array, shape (..., n, n)
    b : array, shape (..., n, 1)
    """
    I_KH = identity(K.shape[-2], K) - K @ H
    return I_KH @ F, I_KH @ u  # docs/theory/cooperative.md, eq. cooperative.16


def information_contribution(y: Any, H: Any, R: Any) -> tuple[Any, Any]:
    """Information carried by one measurement: ``J = H' R⁻¹ H`` and ``j = H' R⁻¹ y`` (docs/theory/cooperative.md §2.3).

    Computed as ``J = W' W``, ``j = W' w`` with ``[W | w] = L⁻¹ [H | y]``, ``R = L L'`` (:func:`whiten`).
    Independent of the state, so it is computed for all steps of a trajectory at once (numpy batched).
    """
    n = H.shape[-1]
    white = whiten(R, _hcat(H, y))
    W = white[..., :n]
    Wt = transpose(W)
    return Wt @ W, Wt @ white[..., n:]


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
    if isinstance(A, ComponentMatrix):
        return ComponentMatrix.hcat(A, B)
    if _is_numeric(A):
        batch = np.broadcast_shapes(A.shape[:-2], B.shape[:-2])
        return np.concatenate(
            [np.broadcast_to(A, batch + A.shape[-2:]), np.broadcast_to(B, batch + B.shape[-2:])], axis=-1
        )
    import casadi as ca

    return ca.horzcat(A, B)
