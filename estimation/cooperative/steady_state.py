"""Steady-state error covariance of the cooperative filter along a level curve (docs/theory/steady_state.md).

With ``A → I`` (the centre moves along a level curve), constant noise and a fixed formation shape, the
covariance converges to the solution of the discrete algebraic Riccati equation (docs/theory/steady_state.md,
eq. steady_state.1)

    P(+)⁻¹ = (P(+) + M)⁻¹ + C' (D U D' + R)⁻¹ C .

* :func:`steady_state` — any formation (N ≤ :data:`MAX_POSITIONS` platforms at given offsets): python-control
  ``dare`` on the 3 × 3 information form;
* :func:`cross_steady_state` — the cross (Prop. 3.14) in closed form, numerically;
* :func:`cross_trace_function` — the same closed form as a CasADi function of ``(a, b)`` with symbolic noise
  parameters, differentiated by CasADi (gradient, Hessian) for
  :mod:`mobisense.estimation.cooperative.formation_design`.

Each returns or feeds a :class:`SteadyState` with prior and posterior covariances and the constant gain
``K∞ = P∞(−) C' (C P∞(−) C' + D U D' + R)⁻¹ = P∞(+) C' (D U D' + R)⁻¹``. (Zhang & Leonard (2010), §III-D,
write ``P∞`` in this formula for the posterior; with the posterior it is not the optimal gain, so the prior is
used here — the second form shows the two are reconciled by replacing ``C P C' + DUD' + R`` with ``DUD' + R``.)
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

from .information_model import cross_formation, taylor_matrices
from .noise_config import CooperativeNoise

__all__ = [
    "SteadyState",
    "steady_state",
    "steady_state_bytes",
    "steady_state_seconds",
    "MAX_POSITIONS",
    "cross_steady_state",
    "cross_trace",
    "cross_trace_function",
    "cross_information",
]

#: most platforms :func:`steady_state` accepts: its ``D U D' + R`` is N × N (memory N², Cholesky time N³);
#: 5000 platforms need ~1 GB and a few seconds
MAX_POSITIONS = 5000


@dataclass(frozen=True)
class SteadyState:
    """Steady state of the cooperative filter for one formation shape.

    Attributes
    ----------
    positions : ndarray, shape (N, 2)
        Platform offsets from the centre (L).
    prior, posterior : ndarray, shape (3, 3)
        ``P∞(−) = P∞(+) + M`` and ``P∞(+)``.
    gain : ndarray, shape (3, N)
        ``K∞``.
    """

    positions: np.ndarray
    prior: np.ndarray
    posterior: np.ndarray
    gain: np.ndarray

    @property
    def trace(self) -> float:
        """``tr P∞(+)``, the design objective of docs/theory/steady_state.md §3."""
        return float(np.trace(self.posterior))


def _gain(posterior: np.ndarray, C: np.ndarray, R_total: np.ndarray) -> np.ndarray:
    """``K∞ = P∞(+) C' (D U D' + R)⁻¹`` (= ``P∞(−) C' S⁻¹``), shape (3, N)."""
    return np.linalg.solve(R_total, C @ posterior).T


def steady_state(positions: np.ndarray, noise: CooperativeNoise) -> SteadyState:
    """Steady state for an arbitrary formation by the DARE (python-control ``dare``), docs/theory/steady_state.md §1.

    Parameters
    ----------
    positions : ndarray, shape (N, 2)
        Platform positions (their mean is the centre), 3 ≤ N ≤ :data:`MAX_POSITIONS` and not collinear.
    noise : CooperativeNoise

    Returns
    -------
    SteadyState

    Raises
    ------
    ValueError
        ``positions: …`` for too many, too few or collinear positions (checked before anything of size N² is
        allocated); ``numpy.linalg.LinAlgError`` (a ``ValueError``) when ``D U D' + R`` is not positive definite.
    RuntimeError
        When the Riccati equation has no stabilising solution to working precision: positions so nearly
        collinear that the information ``C' S⁻¹ C`` is singular to round-off, or positions and noise levels
        many orders of magnitude apart.

    Notes
    -----
    The filter Riccati equation is the dual of the control one, ``control.dare(A', C', M, S)`` with ``A = I``
    and ``S = D U D' + R`` (N × N). Its information form ``P⁻ ↦ (P⁻⁻¹ + J)⁻¹ + M`` depends on the measurements
    only through the 3 × 3 information ``J = C' S⁻¹ C`` (Woodbury), so the same prior ``P∞(−)`` solves
    ``control.dare(I, L, M, I_3)`` with ``J = L L'``: a 3 × 3 problem instead of an (N + 6)-dimensional
    pencil, with exactly symmetric weights. ``S`` is factorised once (Cholesky, N³/3 flops, a few N × N
    arrays: :func:`steady_state_bytes`); then ``P∞(+) = (P∞(−)⁻¹ + J)⁻¹`` and ``K∞ = P∞(+) (S⁻¹ C)'``.
    """
    import control
    import scipy.linalg

    positions = np.asarray(positions, dtype=float)
    n = positions.shape[0] if positions.ndim == 2 else 0
    if positions.ndim != 2 or positions.shape[1] != 2 or not 3 <= n <= MAX_POSITIONS:
        raise ValueError(
            f"positions: expected 3 … {MAX_POSITIONS} platforms as [x, y] rows (the steady state costs N² memory "
            f"and N³ time), got an array of shape {positions.shape}"
        )
    if not np.all(np.isfinite(positions)):
        raise ValueError("positions: expected finite numbers")
    C, D = taylor_matrices(positions)
    if np.linalg.matrix_rank(C) < 3:
        raise ValueError(
            "positions: collinear formation, the steady state is unbounded (docs/theory/cooperative.md §4, Cd5)"
        )
    R_total = noise.total_measurement_covariance(D)
    R_total = 0.5 * (R_total + R_total.T)  # D U D' in floating point is symmetric only to round-off
    if not np.all(np.isfinite(R_total)):
        raise RuntimeError(
            "the measurement covariance D U D' + R overflows: the positions and noise levels are too "
            "far apart in scale (change the units)"
        )
    # S⁻¹ C by Cholesky (LinAlgError, a ValueError, if S is not positive definite)
    whitened = scipy.linalg.solve(R_total, C, assume_a="pos", check_finite=False)
    del R_total
    information = C.T @ whitened
    information = 0.5 * (information + information.T)  # J = C' S⁻¹ C
    eigenvalues, vectors = np.linalg.eigh(information)
    if not eigenvalues[0] > 1e-13 * eigenvalues[-1]:  # below, eigh's smallest eigenvalue is round-off
        raise RuntimeError(
            "positions: nearly collinear formation, the information C'(DUD' + R)⁻¹C is singular to working "
            "precision and the steady state unbounded (docs/theory/cooperative.md §4, Cd5)"
        )
    root = vectors * np.sqrt(eigenvalues)  # J = L L'
    process = 0.5 * (noise.process + noise.process.T)
    # docs/theory/steady_state.md, eq. steady_state.1 (dual, information form)
    try:
        prior, _, _ = control.dare(np.eye(3), root, process, np.eye(3))
    except (control.ControlArgument, ValueError, ArithmeticError) as exc:  # ControlArgument is a TypeError
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise RuntimeError(
            f"the steady-state Riccati equation has no stabilising solution to working precision ({reason}); "
            "the positions may be nearly collinear or the noise levels too far apart"
        ) from exc
    prior = 0.5 * (prior + prior.T)
    # P∞(+) = P∞(−) − P∞(−) L (L' P∞(−) L + I)⁻¹ L' P∞(−)  (= (P∞(−)⁻¹ + J)⁻¹)
    PL = prior @ root
    posterior = prior - PL @ np.linalg.solve(root.T @ PL + np.eye(3), PL.T)
    posterior = 0.5 * (posterior + posterior.T)
    if not (np.all(np.isfinite(prior)) and np.all(np.isfinite(posterior))):
        raise RuntimeError(
            "the steady-state covariance is not finite: the noise levels make the Riccati equation degenerate"
        )
    return SteadyState(positions, prior, posterior, posterior @ whitened.T)


def steady_state_bytes(n_platforms: int) -> float:
    """Peak memory (bytes) of :func:`steady_state` for ``n_platforms`` positions: ~5 N × N float arrays."""
    return 5 * 8.0 * float(n_platforms) ** 2


def steady_state_seconds(n_platforms: int) -> float:
    """A low estimate of the time (s) of :func:`steady_state`: forming and factorising ``S`` (N³/3 flops)."""
    return float(n_platforms) ** 3 / 3 / 2e10 + 8.0 * float(n_platforms) ** 2 / 5e9


def cross_information(a: Any, b: Any, sigma_measurement: Any, sigma_hessian: Any) -> tuple[Any, Any, Any]:
    """``diag(c1, c2, c3) = C' (D U D' + R)⁻¹ C`` of the cross (eq. steady_state.3); numpy or CasADi."""
    s2, s3 = sigma_measurement**2, sigma_hessian**2
    c1 = 2 / (s2 + s3 * a**4 / 2) + 2 / (s2 + s3 * b**4 / 2)  # docs/theory/steady_state.md, eq. steady_state.3
    c2 = 2 * a**2 / s2
    c3 = 2 * b**2 / s2
    return c1, c2, c3


def _posterior_diagonal(c: Any, sigma_process: Any, sqrt: Any) -> Any:
    """``p = −σ1²/2 + ½ √(σ1⁴ + 4 σ1²/c)``, the positive root of ``c p² + c σ1² p − σ1² = 0`` (eq. 30)."""
    s1 = sigma_process**2
    return -s1 / 2 + 0.5 * sqrt(s1**2 + 4 * s1 / c)


def cross_trace(
    a: np.ndarray, b: np.ndarray, sigma_process: float, sigma_measurement: float, sigma_hessian: float
) -> np.ndarray:
    """``tr P∞(a, b)`` of the cross (eq. steady_state.5), vectorised over arrays ``a, b`` (e.g. a grid)."""
    c = cross_information(np.asarray(a, float), np.asarray(b, float), sigma_measurement, sigma_hessian)
    return sum(_posterior_diagonal(ci, sigma_process, np.sqrt) for ci in c)


def cross_steady_state(
    a: float, b: float, sigma_process: float, sigma_measurement: float, sigma_hessian: float
) -> SteadyState:
    """Closed-form steady state of the cross formation (docs/theory/steady_state.md §2).

    Parameters
    ----------
    a, b : float
        Half-distances of pairs (1, 2) and (3, 4) (L).
    sigma_process, sigma_measurement, sigma_hessian : float
        ``σ1, σ2, σ3`` of ``M = σ1² I_3``, ``R = σ2² I_4``, ``U = σ3² I_4``.

    Returns
    -------
    SteadyState
        ``posterior = diag(p1, p2, p3)``.
    """
    c = np.array(cross_information(a, b, sigma_measurement, sigma_hessian))
    # docs/theory/steady_state.md, eq. steady_state.4
    posterior = np.diag(_posterior_diagonal(c, sigma_process, np.sqrt))
    positions = cross_formation(a, b)
    C, D = taylor_matrices(positions)
    noise = CooperativeNoise.from_sigmas(sigma_process, sigma_measurement, sigma_hessian)
    prior = posterior + noise.process
    return SteadyState(positions, prior, posterior, _gain(posterior, C, noise.total_measurement_covariance(D)))


@functools.lru_cache(maxsize=1)
def cross_trace_function() -> Any:
    """CasADi function ``(x = [a, b], sigmas = [σ1, σ2, σ3]) → (tr P∞, ∇_x tr, ∇²_x tr)`` (eq. steady_state.5).

    Built symbolically from the closed form; gradient and Hessian by CasADi's algorithmic
    differentiation.
    """
    import casadi as ca

    x = ca.SX.sym("x", 2)
    sigmas = ca.SX.sym("sigmas", 3)
    c = cross_information(x[0], x[1], sigmas[1], sigmas[2])
    # docs/theory/steady_state.md, eq. steady_state.5
    trace = sum(_posterior_diagonal(ci, sigmas[0], ca.sqrt) for ci in c)
    hessian, gradient = ca.hessian(trace, x)
    return ca.Function("cross_trace", [x, sigmas], [trace, gradient, hessian], ["x", "sigmas"], ["f", "g", "H"])
