"""Van Loan's block exponential: a linear process sampled exactly (docs/theory/replay.md eq. replay.3).

``F = e^{AΔt}`` and ``Q_d = ∫_0^Δt e^{As} G e^{Aᵀs} ds`` from one matrix exponential. The plan replay samples
the process with it (``G = BQBᵀ``); the re-planning window's terminal weight (docs/theory/path_constraints.md
§5.1) is the same integral for ``Aᵀ`` and ``G = K``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["discretise_process"]


def discretise_process(A: np.ndarray, BQB: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``F = e^{AΔt}`` and ``Q_d = ∫_0^Δt e^{As} BQB' e^{A's} ds`` by Van Loan's block exponential."""
    from scipy.linalg import expm

    n = A.shape[0]
    block = np.zeros((2 * n, 2 * n))
    block[:n, :n], block[:n, n:], block[n:, n:] = -A, BQB, A.T
    E = expm(block * dt)
    F = E[n:, n:].T
    Qd = F @ E[:n, n:]
    return F, 0.5 * (Qd + Qd.T)
