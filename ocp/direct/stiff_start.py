"""Whether the collocation grid is too coarse for the covariance's fastest decay (a hint for a failed solve).

Where a sensor is very informative (small noise variance ``r``, large prior ``Σ``) the Riccati equation
``Σ' = AΣ + ΣA' + BQB' − Σ S(p) Σ`` contracts Σ at the rate ``λ = 2 λ_max(Σ S(p))`` (the linearisation of
``−Σ S Σ``; scalar: ``2Σ/r``). On an interval ``h`` with ``h λ`` large the collocation equations of a decay
this fast have no real solution: measured on the default problem with a position-independent noise (Σ0 = 200,
Radau, degree 3, K = 30, h = 1/3), variance 8 (``h λ0`` = 16.7) solves and variance 6 (22) is reported
infeasible by Ipopt; the stage equations of the scalar decay ``y' = −y + 1 − y²/3`` from 200 have no real
solution at h = 1/3 (``h λ`` = 44) and only one with negative stage values at h = 0.2. No start can fix
that; more intervals can (:func:`coarse_grid_hint`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["STIFF_STEP", "riccati_rates", "coarse_grid_hint"]

#: ``h λ`` above which a failed solve is blamed on the grid (measured failing at 22, solving at 16.7)
STIFF_STEP = 16.0


def riccati_rates(tr: Any, trajectory: Any, P: np.ndarray) -> np.ndarray:
    """``λ(t) = 2 λ_max(Σ(t) S(p(t)))`` (1/T) along ``trajectory`` (states ``x`` of shape (T, nx)), shape (T,).

    ``tr`` is the :class:`~mobisense.ocp.direct.transcription.DirectCollocation` whose model gives the
    information ``S(p)`` and the state layout; ``P`` the packed parameters.
    """
    layout = tr.model.structure.state
    Sigma, p, _ = layout.split(trajectory.x)
    n = Sigma.shape[-1]
    rates = np.empty(len(Sigma))
    for j in range(len(Sigma)):
        S = np.asarray(tr.model.information(p[j].ravel(), P)).reshape(n, n, order="F")
        rates[j] = 2.0 * float(np.max(np.linalg.eigvals(Sigma[j] @ S).real))
    return rates


def coarse_grid_hint(tr: Any, trajectory: Any, P: np.ndarray, t0: float, tf: float) -> str | None:
    """A sentence for the message of a failed solve when ``h λ`` exceeds :data:`STIFF_STEP` along ``trajectory``.

    ``trajectory`` is the coasting solution (the start every strategy begins from); None when the grid
    resolves its decay.
    """
    rates = riccati_rates(tr, trajectory, P)
    h = (tf - t0) / tr.intervals
    j = int(np.argmax(rates))
    if not h * rates[j] > STIFF_STEP:
        return None
    needed = math.ceil((tf - t0) * rates[j] / STIFF_STEP)
    return (
        f"the intervals (h = {h:.3g}) are too long for the covariance's decay at t = {trajectory.t[j]:.4g} "
        f"(rate 2λ_max(ΣS) = {rates[j]:.3g}, h × rate = {h * rates[j]:.3g}; the collocation equations of a decay "
        f"this fast may have no real solution beyond ≈ {STIFF_STEP:g}): more intervals (K ≥ {needed})"
    )
