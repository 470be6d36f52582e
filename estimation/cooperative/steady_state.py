"""Steady-state error covariance of the cooperative filter along a level curve (docs/theory/steady_state.md).

With ``A → I`` (the centre moves along a level curve), constant noise and a fixed formation shape, the
covariance converges to the solution of the discrete algebraic Riccati equation (docs/theory/steady_state.md,
eq. steady_state.1)

    P(+)⁻¹ = (P(+) + M)⁻¹ + C' (D U D' + R)⁻¹ C .

* :func:`steady_state` — any formation (N platforms at given offsets): python-control ``dare``; *
  :func:`cross_steady_state` — the cross (Prop. 3.14) in closed form, numerically; * :func:`cross_trace_function` — the
  same closed form as a CasADi function of ``(a, b)`` with symbolic noise parameters, differentiated by CasADi
  (gradient, Hessian) for :mod:`mobisense.estimation.cooperative.formation_design`.

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
    "cross_steady_state",
    "cross_trace",
    "cross_trace_function",
    "cross_information",
]


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
        Platform positions (their mean is the centre), N ≥ 3 and not collinear.
    noise : CooperativeNoise

    Returns
    -------
    SteadyState

    Notes
    -----
    The filter Riccati equation is the dual of the control one: ``control.dare(A', C', M, DUD' + R)``
    with ``A = I`` returns the prior ``P∞(−)``; then ``P∞(+) = P∞(−) − P∞(−) C' S⁻¹ C P∞(−)``.
    """
    import control

    positions = np.asarray(positions, dtype=float)
    C, D = taylor_matrices(positions)
    R_total = noise.total_measurement_covariance(D)
    if np.linalg.matrix_rank(C) < 3:
        raise ValueError(
            "positions: collinear formation, the steady state is unbounded (docs/theory/cooperative.md §4, Cd5)"
        )
    # docs/theory/steady_state.md, eq. steady_state.1 (dual form)
    prior, _, _ = control.dare(np.eye(3), C.T, noise.process, R_total)
    prior = 0.5 * (prior + prior.T)
    S = C @ prior @ C.T + R_total
    posterior = prior - prior @ C.T @ np.linalg.solve(S, C @ prior)
    posterior = 0.5 * (posterior + posterior.T)
    return SteadyState(positions, prior, posterior, _gain(posterior, C, R_total))


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
