"""The estimator in the replay loop: cooperative Kalman filter + Hessian source, and what the controller sees.

:class:`ClosedLoopEstimator` wraps :class:`~mobisense.estimation.cooperative.filter.CooperativeKalmanFilter`
(docs/theory/replay.md §2.2, docs/theory/cooperative.md §2) for one mission: at each sample it predicts to the new
formation centre, asks its Hessian source for ``Ĥ_{c,k}`` (docs/theory/hessian.md §5) and fuses the platforms'
measurements. With spatially correlated noise ``w`` the measurement covariance is ``R_k = σ2² I + W(r_k)`` (the kernel
at the platform positions): ``w`` is treated as white with its true marginal covariance, its correlation along the path
is ignored (the w = 0 filter of Zhang & Leonard (2010), §III-A, made consistent at each instant; eq. replay.6).

Between samples the controllers see the filter's Taylor prediction at the moving centre
(:meth:`ClosedLoopEstimator.derivatives`): ``s(r) = A(Δr) s_k(+) + h(Ĥ_k, Δr)`` with ``Δr = r − r_{c,k}``
(docs/theory/replay.md, eq. replay.7) — the same model the next prediction uses. :class:`TrueField` gives the exact
value and derivatives instead (``derivatives: true_field``).

Hessian feedback: ``Ĥ`` enters the next prediction (``h = [½Δr'ĤΔr, ĤΔr]``), so a noisy snapshot
estimate (the curvature method divides measurement noise by ``a²``) is fed back into ``∇ẑ`` and from
there into the next curvature estimate; on the ocean field this loop diverges within an hour with
the raw estimates. Two options break it: ``warmup`` (keep the initial ``Ĥ`` for the first samples, while
the prior is still vague) and ``smoothing`` β (``Ĥ ← Ĥ + β (Ĥ_raw − Ĥ)``, a first-order low-pass with time
constant ``Δt/β``).

:class:`WindowHessian` is the Hessian source for formations without the cross's geometry (a rotating
pair): a joint quadratic fit (:func:`~mobisense.estimation.cooperative.hessian.least_squares_hessian`, six
unknowns) to all measurements of the last ``window`` samples, about their centroid.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ...estimation.cooperative.filter import CooperativeKalmanFilter
from ...estimation.cooperative.hessian import CurvatureHessian, LeastSquaresHessian, least_squares_hessian
from ...estimation.cooperative.information_model import formation_center, hessian_drift, transition_matrix
from ...estimation.cooperative.noise_config import CooperativeNoise
from ...estimation.cooperative.spatial_noise import SpatialNoise
from ...estimation.fields.base import Field

__all__ = ["TrueField", "WindowHessian", "ClosedLoopEstimator"]


@dataclass(frozen=True)
class TrueField:
    """Exact ``(z, ∇z, ∇²z)`` of a field at a point (the ``derivatives: true_field`` mode)."""

    field: Field

    def derivatives(self, r: np.ndarray, t: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Value (), gradient (2,), Hessian (2, 2) at ``r`` (2,)."""
        return self.field.value(r, t), self.field.gradient(r, t), self.field.hessian(r, t)


@dataclass
class WindowHessian:
    """Hessian from a joint quadratic fit to the measurements of the last ``window`` samples.

    Parameters
    ----------
    window : int
        Number of samples kept (all platforms of each).
    history : deque
        ``(positions (N, 2), measurements (N,))`` of past samples (filled by :meth:`__call__`).
    """

    window: int
    history: deque = field(default_factory=deque)

    def fit(self, positions: np.ndarray, measurements: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """Add one sample and fit; ``([z, ∇z] at the current centre (3,), Ĥ (2, 2))``, or None.

        The fit is about the centroid of the window's points and moved to the current formation centre by the
        quadratic model (eq. 9 of Zhang & Leonard (2010); docs/theory/cooperative.md §1.3). None while the
        window does not yet determine the six unknowns (rank 6).
        """
        self.history.append((np.asarray(positions, float), np.asarray(measurements, float)))
        while len(self.history) > self.window:
            self.history.popleft()
        points = np.concatenate([p for p, _ in self.history])
        values = np.concatenate([m for _, m in self.history])
        try:
            fitted, hessian = least_squares_hessian(points, values)
        except ValueError:  # not yet six well-spread points
            return None
        shift = formation_center(positions) - points.mean(axis=0)
        return transition_matrix(shift) @ fitted + hessian_drift(hessian, shift), hessian

    def __call__(
        self, positions: np.ndarray, measurements: np.ndarray, state_prior: np.ndarray,
        covariance_prior: np.ndarray, previous_hessian: np.ndarray,
    ) -> np.ndarray:  # fmt: skip
        """``Ĥ_{c,k}`` (2, 2); the previous estimate until the window determines the fit (rank 6)."""
        fitted = self.fit(positions, measurements)
        return previous_hessian if fitted is None else fitted[1]


class ClosedLoopEstimator:
    """Cooperative filter of one replay, started at the first sample.

    Parameters
    ----------
    noise : CooperativeNoise
        ``M, R = σ2² I, U`` (docs/theory/steady_state.md §2).
    spatial_noise : SpatialNoise or None
        Kernel of ``w``; adds ``W(r_k)`` to ``R`` at every sample.
    hessian : {"curvature", "least_squares", "window", "true_field", "fixed"}
        Source of ``Ĥ_{c,k}``.
    field : Field
        The true field (only for ``hessian="true_field"``).
    window : int
        Samples of the ``window`` source.
    smoothing, warmup : float, int
        Exponential smoothing factor β of ``Ĥ`` and samples before the source is first used.
    relative_error : float
        ρ of the Hessian-error model :meth:`hessian_error` (0: constant ``U = σ3² I``).
    estimator : {"kalman", "window_fit"}
        What the controllers see: the filter, or (no filter) the joint quadratic fit to the last ``fit_window``
        samples moved to the current centre (docs/theory/replay.md §2.6). The filter runs in both cases.
    fit_window : int
        Samples of the ``window_fit`` estimator.
    """

    def __init__(
        self,
        noise: CooperativeNoise,
        spatial_noise: SpatialNoise | None,
        hessian: str,
        field: Field,
        window: int = 10,
        smoothing: float = 1.0,
        warmup: int = 0,
        relative_error: float = 0.0,
        estimator: str = "kalman",
        fit_window: int = 6,
    ) -> None:
        if estimator not in ("kalman", "window_fit"):
            raise ValueError(f"estimator: expected 'kalman' or 'window_fit', got {estimator!r}")
        self.estimator = estimator
        self.window_fit = WindowHessian(fit_window) if estimator == "window_fit" else None
        self.fitted: tuple[np.ndarray, np.ndarray] | None = None  # the last window fit (state, Hessian)
        if relative_error < 0:
            raise ValueError(f"relative_error: expected ρ >= 0, got {relative_error}")
        self.relative_error = float(relative_error)
        if not 0 < smoothing <= 1 or warmup < 0:
            raise ValueError(f"smoothing: expected 0 < β <= 1, warmup >= 0; got {smoothing}, {warmup}")
        self.base_noise, self.spatial_noise, self.field = noise, spatial_noise, field
        self.smoothing, self.warmup, self.samples = smoothing, warmup, 0
        sources = {
            "curvature": lambda: CurvatureHessian(noise, spatial_noise),
            "least_squares": lambda: LeastSquaresHessian(noise, spatial_noise),
            "window": lambda: WindowHessian(window),
            "true_field": lambda: self._true_hessian,
            "fixed": lambda: None,
        }
        if hessian not in sources:
            raise ValueError(f"hessian: expected one of {sorted(sources)}, got {hessian!r}")
        self.source = sources[hessian]()
        self.filter: CooperativeKalmanFilter | None = None
        self.prior_covariance = np.full((3, 3), np.nan)

    def _true_hessian(self, positions: np.ndarray, *_: np.ndarray) -> np.ndarray:
        return self.field.hessian(formation_center(positions))

    def hessian_error(self, hessian: np.ndarray | None = None, gradient: np.ndarray | None = None) -> np.ndarray:
        """Hessian-error covariance ``U_k`` (4, 4): ``σ3² I``, plus a relative error model when ρ > 0.

        With ``relative_error`` ρ > 0 (docs/theory/replay.md, eq. replay.10)::

            U_k = σ3² I + (F⊗F) diag(ρ² vec(Ĥ_F)²) (F⊗F)',   Ĥ_F = F' Ĥ F,

        in the level-curve frame ``F = [x1, y1]`` of the gradient estimate (x1 tangent, y1 = ∇ẑ/‖∇ẑ‖): each
        entry of the Frenet-frame Hessian is uncertain in proportion to its size (ρ = 1: 100 %). Along the
        level curve ``Ĥ_F,11 = −‖∇ẑ‖ κ̂``, so the error of the platforms 1-2 term follows the curvature
        (Zhang & Leonard (2010), §III-E: "U_k determined by the accuracy of the Hessian estimation algorithm").

        Parameters
        ----------
        hessian : ndarray, shape (2, 2), optional
            ``Ĥ`` (default: the filter's).
        gradient : ndarray, shape (2,), optional
            ``∇ẑ`` that fixes the frame (default: the current estimate's).
        """
        U0 = self.base_noise.hessian_error
        if self.relative_error == 0.0 or (self.filter is None and (hessian is None or gradient is None)):
            return U0
        H = self.filter.hessian if hessian is None else np.asarray(hessian, float)
        g = self.state[1:] if gradient is None else np.asarray(gradient, float)
        norm = float(np.linalg.norm(g))
        if not norm > 0 or not np.all(np.isfinite(H)):
            return U0
        y1 = g / norm
        F = np.column_stack([[y1[1], -y1[0]], y1])  # columns x1 (tangent), y1 (normal): lab = F @ Frenet
        H_F = F.T @ H @ F
        vec_F = H_F.T.reshape(4)  # [H11, H21, H12, H22] (column-major, as hessian_to_vec)
        T = np.kron(F, F)  # vec(F X F') = (F ⊗ F) vec(X)
        return U0 + T @ np.diag((self.relative_error * vec_F) ** 2) @ T.T

    def design_noise(self) -> CooperativeNoise:
        """``M, R = σ2² I, U_k`` for the shape design of step 3A (no spatial-noise term; docs/theory/replay.md §2.5)."""
        if self.relative_error == 0.0:
            return self.base_noise
        return CooperativeNoise(self.base_noise.process, self.base_noise.measurement, self.hessian_error())

    def _noise_at(self, positions: np.ndarray, hessian: np.ndarray | None = None) -> CooperativeNoise:
        U = self.hessian_error(hessian) if self.filter is not None else self.base_noise.hessian_error
        if self.spatial_noise is None:
            if self.relative_error == 0.0:
                return self.base_noise
            return CooperativeNoise(self.base_noise.process, self.base_noise.measurement, U)
        R = self.base_noise.measurement_matrix(len(positions)) + self.spatial_noise.W(positions)
        return CooperativeNoise(self.base_noise.process, R, U)

    def start(
        self, positions: np.ndarray, measurements: np.ndarray, state: np.ndarray, covariance: np.ndarray,
        hessian: np.ndarray,
    ) -> None:  # fmt: skip
        """First sample: fuse ``measurements`` at ``positions`` (N, 2) into the prior (state, covariance)."""
        self.filter = CooperativeKalmanFilter(
            self._noise_at(positions), state, covariance, positions, hessian
        )
        self.prior_covariance = np.asarray(covariance, float)
        self._fuse(positions, measurements, state, covariance)

    def step(self, positions: np.ndarray, measurements: np.ndarray) -> None:
        """A later sample: predict to the new centre (eqs. 13-14), estimate ``Ĥ``, update (eqs. 15-17)."""
        if self.filter is None:
            raise RuntimeError("ClosedLoopEstimator.step: call start() at the first sample first")
        state_prior, covariance_prior = self.filter.predict(positions)
        self.prior_covariance = covariance_prior
        self._fuse(positions, measurements, state_prior, covariance_prior)

    def _fuse(self, positions: np.ndarray, measurements: np.ndarray, xm: np.ndarray, Pm: np.ndarray) -> None:
        filt = self.filter
        self.last_measurements = np.asarray(measurements, dtype=float)
        H = None
        if self.source is not None and self.samples >= self.warmup:
            raw = self.source(positions, measurements, xm, Pm, filt.hessian)
            if np.all(np.isfinite(raw)):  # else degenerate geometry this step: keep the previous estimate
                H = filt.hessian + self.smoothing * (raw - filt.hessian)  # exponential smoothing, factor β
        self.samples += 1
        filt.noise = self._noise_at(positions, H)
        filt.update(measurements, H)
        if self.window_fit is not None:  # until the window determines the fit the filter's estimate is used
            self.fitted = self.window_fit.fit(positions, measurements) or self.fitted

    @property
    def state(self) -> np.ndarray:
        """Posterior ``s_k(+) = [z, ∂z/∂x, ∂z/∂y]`` at the last centre, shape (3,) (the fit for window_fit)."""
        if self.fitted is not None:
            return self.fitted[0]
        return self.filter.state[..., 0]

    @property
    def covariance(self) -> np.ndarray:
        """``P_k(+)``, shape (3, 3)."""
        return self.filter.covariance

    @property
    def hessian(self) -> np.ndarray:
        """``Ĥ_{c,k}``, shape (2, 2) (the fit's for window_fit)."""
        if self.fitted is not None:
            return self.fitted[1]
        return self.filter.hessian

    @property
    def center(self) -> np.ndarray:
        """Centre of the last sample, shape (2,)."""
        return formation_center(self.filter.positions)

    def derivatives(self, r: np.ndarray, t: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Predicted ``(z, ∇z, Ĥ)`` at ``r`` (2,) from the last posterior (docs/theory/replay.md, eq. replay.7)."""
        shift = np.asarray(r, float) - self.center
        s = transition_matrix(shift) @ self.state + hessian_drift(self.hessian, shift)
        return s[0], s[1:], self.hessian
