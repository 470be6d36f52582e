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

from ..checks import check_non_negative, check_positive
from .information_model import cross_formation, taylor_matrices
from .noise_config import CooperativeNoise

__all__ = [
    "SteadyState",
    "steady_state",
    "steady_state_bytes",
    "steady_state_seconds",
    "MAX_POSITIONS",
    "MIN_ASPECT",
    "cross_steady_state",
    "cross_trace",
    "cross_trace_function",
    "cross_information",
    "measurement_information",
]

#: the narrowest formation :func:`steady_state` accepts, as its width over its length (singular values of the
#: centred positions): the error of the steady state grows as the formation narrows — against an 80-digit
#: reference, 7e-12 at 5e-5, 2e-8 at 5e-7, 1e-6 at 5e-9, 1e-3 at 5e-11 (docs/theory/steady_state.md §1)
MIN_ASPECT = 1e-6
#: most platforms :func:`steady_state` accepts: its ``D U D' + R`` is N × N (memory N², Cholesky time N³);
#: 5000 platforms need ~1 GB and a few seconds
MAX_POSITIONS = 5000


@dataclass(frozen=True)
class SteadyState:
    """Steady state of the cooperative filter for one formation shape.

    Attributes
    ----------
    positions : ndarray, shape (N, 2)
        Platform positions as given (L); their mean is the formation centre.
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
        Platform positions (their mean is the centre), 3 ≤ N ≤ :data:`MAX_POSITIONS`, no narrower than
        :data:`MIN_ASPECT` of their length.
    noise : CooperativeNoise

    Returns
    -------
    SteadyState

    Raises
    ------
    ValueError
        ``positions: …`` for too many, too few, collinear or nearly collinear positions (checked before
        anything of size N² is allocated); ``noise.process: …`` for a process noise ``M`` that is not
        positive definite; ``numpy.linalg.LinAlgError`` (a ``ValueError``) when ``D U D' + R``
        is not positive definite.
    RuntimeError
        When the Riccati equation has no stabilising solution to working precision: noise levels that leave
        the information ``C' S⁻¹ C`` singular to round-off, or positions and noise levels so many orders of
        magnitude apart that ``D U D' + R`` overflows.

    Notes
    -----
    The filter Riccati equation is the dual of the control one, ``control.dare(A', C', M, S)`` with ``A = I``
    and ``S = D U D' + R`` (N × N). Its information form ``P⁻ ↦ (P⁻⁻¹ + J)⁻¹ + M`` depends on the measurements
    only through the 3 × 3 information ``J = C' S⁻¹ C`` (Woodbury), so the same prior ``P∞(−)`` solves
    ``control.dare(I, L, M, I_3)`` with ``J = L L'``: a 3 × 3 problem instead of an (N + 6)-dimensional
    pencil, with exactly symmetric weights. ``J`` and ``C' S⁻¹`` come from :func:`measurement_information`
    (``R`` factorised once, N³/3 flops and a few N × N arrays: :func:`steady_state_bytes`, then a QR of an
    (N + 4) × 7 matrix); ``J`` is judged (singular or not) and factorised after scaling by its diagonal, so that
    the units of the positions and noise levels do not matter; then ``P∞(+) = (P∞(−)⁻¹ + J)⁻¹`` and
    ``K∞ = P∞(+) C' S⁻¹``.
    """
    import control

    positions = np.asarray(positions, dtype=float)
    n = positions.shape[0] if positions.ndim == 2 else 0
    if positions.ndim != 2 or positions.shape[1] != 2 or not 3 <= n <= MAX_POSITIONS:
        raise ValueError(
            f"positions: expected 3 … {MAX_POSITIONS} platforms as [x, y] rows (the steady state costs N² memory "
            f"and N³ time), got an array of shape {positions.shape}"
        )
    if not np.all(np.isfinite(positions)):
        raise ValueError("positions: expected finite numbers")
    process = 0.5 * (noise.process + noise.process.T)
    if not np.linalg.eigvalsh(process)[0] > 0:
        raise ValueError(
            "noise.process: expected a positive definite M: a direction without process noise is learnt without "
            "bound (its covariance falls like 1/k), so the Riccati equation has no stabilising solution"
        )
    C, D = taylor_matrices(positions)
    if np.linalg.matrix_rank(C) < 3:
        raise ValueError(
            "positions: collinear formation, the steady state is unbounded (docs/theory/cooperative.md §4, Cd5)"
        )
    spread = np.linalg.svd(positions - positions.mean(axis=0), compute_uv=False)
    if not spread[1] >= MIN_ASPECT * spread[0]:
        raise ValueError(
            f"positions: nearly collinear formation (width {spread[1] / spread[0]:.1e} of its length, at least "
            f"{MIN_ASPECT:g} needed): the gradient across it is so poorly observed that its steady state cannot be "
            "computed to working precision (docs/theory/cooperative.md §4, Cd5)"
        )
    information, weights = measurement_information(C, D, noise)  # J = C' S⁻¹ C and C' S⁻¹
    information = 0.5 * (information + information.T)  # J = C' S⁻¹ C
    # J's entries carry the units of the value, gradient and their noise (a formation of size a gives
    # J ~ diag(1, a², a²)/σ²): judged and factorised after scaling by its diagonal, J = Δ Ĵ Δ, so that only
    # the geometry (how far from collinear) decides, not the units
    scale = np.sqrt(np.diag(information))
    if not np.all(scale > 0):
        raise RuntimeError(
            "positions: the measurements carry no information about the value or a gradient component "
            "(docs/theory/cooperative.md §4, Cd5)"
        )
    eigenvalues, vectors = np.linalg.eigh(information / np.outer(scale, scale))
    if not eigenvalues[0] > 1e-15 * eigenvalues[-1]:  # below, eigh's smallest eigenvalue is round-off
        raise RuntimeError(
            "the information C'(DUD' + R)⁻¹C is singular to working precision: the noise levels leave the value "
            "or a gradient component unobserved (docs/theory/cooperative.md §4, Cd5)"
        )
    root = scale[:, None] * (vectors * np.sqrt(eigenvalues))  # J = L L', L = Δ V Λ^½
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
    # P∞(+) = (P∞(−)⁻¹ + J)⁻¹: two inverses of positive definite 3 × 3 matrices, no difference of large terms
    # (the Woodbury form P − P L (L' P L + I)⁻¹ L' P lost 1.7e-6 relative on a 1000-L cross, 8.6e-5 with one
    # platform 1e13 times less noisy than the others)
    with np.errstate(all="ignore"):
        posterior = np.linalg.inv(np.linalg.inv(prior) + information)
    posterior = 0.5 * (posterior + posterior.T)
    if not (np.all(np.isfinite(prior)) and np.all(np.isfinite(posterior))):
        raise RuntimeError(
            "the steady-state covariance is not finite: the noise levels make the Riccati equation degenerate"
        )
    return SteadyState(positions, prior, posterior, posterior @ weights)


def measurement_information(C: np.ndarray, D: np.ndarray, noise: CooperativeNoise) -> tuple[np.ndarray, np.ndarray]:
    """``J = C' S⁻¹ C`` (3 × 3) and ``C' S⁻¹`` (3 × N) for ``S = D U D' + R``, without forming ``S``.

    ``S`` is as ill-conditioned as the platforms are far apart (``D`` grows with the squared offsets: one
    platform 1e4 L from three at unit distance gives cond S ≈ 1e16, and ``J`` from a Cholesky solve with ``S``
    put the steady state 3.9e-5 off an 80-digit reference, python-control's DARE on the full ``S`` 20 %).
    Instead the Hessian error is kept as an unknown ``e = G f`` (``U = G G'``, ``f`` with unit covariance) of
    the whitened least-squares problem ``[L⁻¹ D G, L⁻¹ C; I, 0] [f; s] ≈ [L⁻¹ p; 0]`` (``R = L L'``), and
    eliminated by a QR factorisation of its (N + r) × (r + 3) matrix: the trailing 3 × 3 block ``T`` of the
    triangular factor gives ``J = T'T`` and ``C' S⁻¹ = T' Q₂' L⁻¹`` (``Q₂``: the factor's last three columns,
    first N rows). Orthogonal transformations only (rows sorted by decreasing norm first), so the spread of
    the offsets and of the noise levels costs little accuracy (7.5e-9 on that case). Falls back to a Cholesky
    factorisation of ``S`` when ``R`` alone is not
    positive definite (a platform without measurement noise).

    Raises
    ------
    numpy.linalg.LinAlgError
        ``D U D' + R`` is not positive definite.
    RuntimeError
        ``D U D' + R`` overflows.
    """
    import scipy.linalg

    n = C.shape[0]
    R = noise.measurement_matrix(n)
    R = 0.5 * (R + R.T)
    U = 0.5 * (noise.hessian_error + noise.hessian_error.T)
    with np.errstate(over="ignore", invalid="ignore"):
        finite = np.all(np.isfinite(D @ U)) and np.all(np.isfinite(R))
    if not finite:
        raise RuntimeError(
            "the measurement covariance D U D' + R overflows: the positions and noise levels are too "
            "far apart in scale (change the units)"
        )
    try:
        L = np.linalg.cholesky(R)
    except np.linalg.LinAlgError:  # R singular: S itself must be positive definite (Cholesky of S)
        S = noise.total_measurement_covariance(D)
        S = 0.5 * (S + S.T)
        if not np.all(np.isfinite(S)):
            raise RuntimeError(
                "the measurement covariance D U D' + R overflows: the positions and noise levels are too "
                "far apart in scale (change the units)"
            ) from None
        whitened = scipy.linalg.solve(S, C, assume_a="pos", check_finite=False)
        return C.T @ whitened, whitened.T
    lam, V = np.linalg.eigh(U)
    keep = lam > 1e-15 * max(float(lam[-1]), 0.0)
    G = V[:, keep] * np.sqrt(lam[keep])  # U = G G' (rank r ≤ 4)
    r = G.shape[1]
    solve = functools.partial(scipy.linalg.solve_triangular, L, lower=True, check_finite=False)
    top = np.hstack([solve(D @ G), solve(C)])
    A = np.vstack([top, np.hstack([np.eye(r), np.zeros((r, 3))])])
    # rows in decreasing norm: Householder QR is then accurate row by row (Powell & Reid), which matters when
    # one platform's noise is many orders of magnitude below the others'
    order = np.argsort(-np.linalg.norm(A, axis=1), kind="stable")
    Q_sorted, T = np.linalg.qr(A[order])  # (N + r) × (r + 3), (r + 3) × (r + 3)
    Q = np.empty_like(Q_sorted)
    Q[order] = Q_sorted
    T22 = T[r:, r:]
    weights = T22.T @ scipy.linalg.solve_triangular(L, Q[:n, r:], lower=True, trans="T", check_finite=False).T
    return T22.T @ T22, weights


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

    Raises
    ------
    ValueError
        Unless ``a, b, σ1, σ2`` are finite and > 0 and ``σ3`` finite and >= 0: ``a = 0`` or ``b = 0`` is a
        collinear formation (unbounded steady state, as :func:`steady_state` refuses), ``σ1 = 0`` has no
        stabilising solution and ``σ2 = 0`` divides by zero (the rules of
        :class:`~mobisense.estimation.cooperative.noise_config.NoiseConfig`).
    """
    a, b = check_positive("a", a), check_positive("b", b)
    sigma_process = check_positive("sigma_process", sigma_process)
    sigma_measurement = check_positive("sigma_measurement", sigma_measurement)
    sigma_hessian = check_non_negative("sigma_hessian", sigma_hessian)
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
