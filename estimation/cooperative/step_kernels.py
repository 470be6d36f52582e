"""Compiled predict and update steps of one cooperative Kalman filter (numba, extra ``mobisense[fast]``).

The second implementation of docs/theory/cooperative.md eqs. cooperative.2–8 in the package, for one reason: the
step API (:class:`~mobisense.estimation.cooperative.filter.CooperativeKalmanFilter`) is called once per
measurement from Python, and on 3 × 3 matrices numpy's fixed cost per call (≈ 1–3 µs, about 30 calls per
step for the Taylor matrices, the drift, the noise and the Joseph update) is the whole cost: the
reference kernels (:mod:`mobisense.estimation.kalman` on numpy arrays) take ≈ 3x filterpy's time per
step, these loops ≈ 1/5 of it (``benchmarks/bench_filters.py``). A CasADi function does not help here:
one call from Python costs more than the whole numpy step.

The loops follow the reference operation by operation — the same Taylor rows, the same drift, the gain
as ``K' = S⁻¹ (C P)`` by Gaussian elimination with partial pivoting (LAPACK's ``gesv``, which
``np.linalg.solve`` calls), Joseph's covariance form and the final symmetrisation — so the two agree to
round-off (``tests/estimation/test_filter_kernels.py`` checks 1e-12 relative, step by step and over long
trajectories, for N = 2–6, full ``U`` and ``R``).

numba compiles the kernels on first use and caches the machine code on disk (``cache=True``). This module
imports numba: import it only when numba is installed (the filter does, when it picks the backend).
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np

__all__ = ["predict_step", "update_step"]


@numba.njit(cache=True)
def center(pos: Any) -> tuple[float, float]:  # docs/theory/cooperative.md §1.1
    n = pos.shape[0]
    cx = 0.0
    cy = 0.0
    for i in range(n):
        cx += pos[i, 0]
        cy += pos[i, 1]
    return cx / n, cy / n


@numba.njit(cache=True)
def predict_step(x: Any, P: Any, old: Any, new: Any, H: Any, M: Any, x_out: Any, P_out: Any) -> None:
    """Eqs. cooperative.5–6: ``x⁻ = A x + h``, ``P⁻ = A P A' + M`` for the centre shift old → new."""
    ox, oy = center(old)
    nx, ny = center(new)
    a = nx - ox
    b = ny - oy
    ha = H[0, 0] * a + H[0, 1] * b  # Ĥ Δr
    hb = H[1, 0] * a + H[1, 1] * b
    x_out[0, 0] = x[0, 0] + a * x[1, 0] + b * x[2, 0] + 0.5 * (a * ha + b * hb)
    x_out[1, 0] = x[1, 0] + ha
    x_out[2, 0] = x[2, 0] + hb
    AP = np.empty((3, 3))  # A = [[1, a, b], [0, 1, 0], [0, 0, 1]]
    for j in range(3):
        AP[0, j] = P[0, j] + a * P[1, j] + b * P[2, j]
        AP[1, j] = P[1, j]
        AP[2, j] = P[2, j]
    for i in range(3):
        P_out[i, 0] = AP[i, 0] + a * AP[i, 1] + b * AP[i, 2] + M[i, 0]
        P_out[i, 1] = AP[i, 1] + M[i, 1]
        P_out[i, 2] = AP[i, 2] + M[i, 2]


@numba.njit(cache=True)
def update_step(
    x: Any, P: Any, pos: Any, p: Any, H: Any, U: Any, R0: Any, x_out: Any, P_out: Any, nu: Any, S: Any
) -> None:
    """Eqs. cooperative.2–4, 7–8: Taylor rows at ``pos``, ``y = p − D vec Ĥ``, Joseph update, symmetrised."""
    n = pos.shape[0]
    cx, cy = center(pos)
    C = np.empty((n, 3))
    D = np.empty((n, 4))
    for i in range(n):
        dx = pos[i, 0] - cx
        dy = pos[i, 1] - cy
        C[i, 0] = 1.0
        C[i, 1] = dx
        C[i, 2] = dy
        D[i, 0] = 0.5 * dx * dx
        D[i, 1] = 0.5 * dx * dy
        D[i, 2] = 0.5 * dy * dx
        D[i, 3] = 0.5 * dy * dy
    # R = D U D' + R0 and S = C P C' + R
    DU = np.zeros((n, 4))
    for i in range(n):
        for k in range(4):
            for m in range(4):
                DU[i, m] += D[i, k] * U[k, m]
    R = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            s = R0[i, j]
            for k in range(4):
                s += DU[i, k] * D[j, k]
            R[i, j] = s
    CP = np.empty((n, 3))
    for i in range(n):
        for j in range(3):
            CP[i, j] = C[i, 0] * P[0, j] + C[i, 1] * P[1, j] + C[i, 2] * P[2, j]
    for i in range(n):
        for j in range(n):
            S[i, j] = CP[i, 0] * C[j, 0] + CP[i, 1] * C[j, 1] + CP[i, 2] * C[j, 2] + R[i, j]
        # eq. cooperative.3: vec(Ĥ) = [H11, H21, H12, H22]
        y = p[i] - (D[i, 0] * H[0, 0] + D[i, 1] * H[1, 0] + D[i, 2] * H[0, 1] + D[i, 3] * H[1, 1])
        nu[i, 0] = y - (C[i, 0] * x[0, 0] + C[i, 1] * x[1, 0] + C[i, 2] * x[2, 0])
    # K' = S⁻¹ (C P): Gaussian elimination with partial pivoting on [S | C P]
    A = S.copy()
    KT = CP.copy()
    for col in range(n):
        piv = col
        for r in range(col + 1, n):
            if abs(A[r, col]) > abs(A[piv, col]):
                piv = r
        if piv != col:
            for c in range(n):
                A[col, c], A[piv, c] = A[piv, c], A[col, c]
            for c in range(3):
                KT[col, c], KT[piv, c] = KT[piv, c], KT[col, c]
        for r in range(col + 1, n):
            f = A[r, col] / A[col, col]
            for c in range(col, n):
                A[r, c] -= f * A[col, c]
            for c in range(3):
                KT[r, c] -= f * KT[col, c]
    for r in range(n - 1, -1, -1):
        for c in range(3):
            s = KT[r, c]
            for k in range(r + 1, n):
                s -= A[r, k] * KT[k, c]
            KT[r, c] = s / A[r, r]
    # x⁺ = x + K ν; P⁺ = (I − K C) P (I − K C)' + K R K', symmetrised
    for a in range(3):
        s = x[a, 0]
        for i in range(n):
            s += KT[i, a] * nu[i, 0]
        x_out[a, 0] = s
    IKC = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            s = 1.0 if a == b else 0.0
            for i in range(n):
                s -= KT[i, a] * C[i, b]
            IKC[a, b] = s
    T = np.zeros((3, 3))  # (I − K C) P
    for a in range(3):
        for c in range(3):
            for b in range(3):
                T[a, b] += IKC[a, c] * P[c, b]
    RK = np.zeros((n, 3))  # R K'
    for i in range(n):
        for k in range(n):
            for b in range(3):
                RK[i, b] += R[i, k] * KT[k, b]
    J = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            s = 0.0
            for c in range(3):
                s += T[a, c] * IKC[b, c]
            for i in range(n):
                s += KT[i, a] * RK[i, b]
            J[a, b] = s
    for a in range(3):
        for b in range(3):
            P_out[a, b] = 0.5 * (J[a, b] + J[b, a])
