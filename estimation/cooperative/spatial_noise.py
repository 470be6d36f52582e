"""Spatially correlated Gaussian noise ``w(r)`` (docs/theory/cooperative.md §3): covariance kernels, W_k, V_k, samples.

A stationary isotropic kernel ``E[w(r) w(r')] = σ_w² ρ(‖r − r'‖ / ℓ)`` from :data:`KERNELS`
(``squared_exponential``, ``exponential`` = Matérn ½, ``matern32``) gives

* ``W_k = E[w_k w_k']`` and ``V_k = E[w_k w_{k−1}']`` at platform positions (:meth:`SpatialNoise.W`,
  :meth:`SpatialNoise.V`), and the Markov model of docs/theory/cooperative.md, eq. cooperative.11
  (:meth:`SpatialNoise.markov`);
* exact joint samples at any finite set of points (:meth:`SpatialNoise.sample`, Cholesky);
* sample *functions* evaluated on demand along trajectories decided as the mission goes
  (:meth:`SpatialNoise.realisation`, random Fourier features: ``w(r) = σ √(2/F) Σ cos(ω_f·r + φ_f)`` with
  ``ω_f`` drawn from the kernel's spectral density — its covariance over realisations is the kernel
  exactly, its marginals Gaussian as ``F → ∞``).

A new kernel subclasses :class:`Kernel` (``correlation`` and ``sample_frequencies``) and is added with
:func:`register_kernel`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from ...core.config import PositiveFloat, StrictModel
from ...core.registry import Registry

__all__ = [
    "Kernel",
    "KERNELS",
    "KernelName",
    "register_kernel",
    "SpatialNoise",
    "NoiseRealisation",
    "SpatialNoiseConfig",
]


class Kernel(ABC):
    """Isotropic correlation ``ρ(d)`` of unit length scale and its spectral density (Bochner)."""

    name: str = ""

    @abstractmethod
    def correlation(self, d: np.ndarray) -> np.ndarray:
        """``ρ(d)`` for distances ``d ≥ 0`` in length-scale units, ``ρ(0) = 1``."""

    @abstractmethod
    def sample_frequencies(self, rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
        """Frequencies ``ω`` (shape ``shape + (2,)``) with density the 2-D Fourier transform of ρ."""


#: kernel name -> Kernel instance
KERNELS: Registry[Kernel] = Registry("spatial covariance kernel")
#: the schema type of a field naming a kernel
KernelName = KERNELS.choice()


def register_kernel(cls: type[Kernel]) -> type[Kernel]:
    """Class decorator adding a kernel to :data:`KERNELS`."""
    KERNELS.register(cls.name, cls())
    return cls


@register_kernel
class SquaredExponential(Kernel):
    """``ρ(d) = exp(−d²/2)``; spectral density ``N(0, I)``."""

    name = "squared_exponential"

    def correlation(self, d: np.ndarray) -> np.ndarray:
        """Gaussian correlation."""
        return np.exp(-0.5 * d**2)

    def sample_frequencies(self, rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
        """Standard normal frequencies."""
        return rng.standard_normal(shape + (2,))


class _Matern(Kernel):
    """Matérn ν: spectral density a bivariate Student t with 2ν degrees of freedom, scaled by √(2ν)."""

    nu: float = 0.5

    def sample_frequencies(self, rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
        """``ω = z √(2ν / g)``, ``z ~ N(0, I)``, ``g ~ χ²(2ν)``."""
        g = rng.chisquare(2 * self.nu, size=shape)
        return rng.standard_normal(shape + (2,)) * np.sqrt(2 * self.nu / g)[..., None]


@register_kernel
class Exponential(_Matern):
    """``ρ(d) = exp(−d)`` (Matérn ½; rough sample paths)."""

    name = "exponential"
    nu = 0.5

    def correlation(self, d: np.ndarray) -> np.ndarray:
        """Exponential correlation."""
        return np.exp(-d)


@register_kernel
class Matern32(_Matern):
    """``ρ(d) = (1 + √3 d) exp(−√3 d)`` (Matérn 3/2)."""

    name = "matern32"
    nu = 1.5

    def correlation(self, d: np.ndarray) -> np.ndarray:
        """Matérn 3/2 correlation."""
        a = np.sqrt(3.0) * d
        return (1.0 + a) * np.exp(-a)


@dataclass(frozen=True)
class NoiseRealisation:
    """One (or a batch of) sample function(s) ``w(r)`` built from random Fourier features.

    Attributes
    ----------
    frequencies : ndarray, shape (*batch, F, 2)
        ``ω_f`` (1/L).
    phases : ndarray, shape (*batch, F)
    std : float
        ``σ_w`` (field unit).
    """

    frequencies: np.ndarray
    phases: np.ndarray
    std: float

    def __call__(self, r: np.ndarray) -> np.ndarray:
        """``w(r)`` for positions ``r`` of shape ``(*batch, ..., 2)`` → ``(*batch, ...)``."""
        r = np.asarray(r, dtype=float)
        batch = self.phases.shape[:-1]
        n_features = self.phases.shape[-1]
        flat = r.reshape(batch + (-1, 2)) if batch else r.reshape(-1, 2)
        arg = flat @ np.swapaxes(self.frequencies, -1, -2) + self.phases[..., None, :]  # (*batch, P, F)
        w = self.std * np.sqrt(2.0 / n_features) * np.cos(arg).sum(axis=-1)
        return w.reshape(r.shape[:-1])


@dataclass(frozen=True)
class SpatialNoise:
    """Stationary spatially correlated noise field ``w(r)``.

    Parameters
    ----------
    std : float
        ``σ_w`` (field unit).
    length_scale : float
        ``ℓ`` (L).
    kernel : str
        Key of :data:`KERNELS`.
    """

    std: float
    length_scale: float
    kernel: str = "squared_exponential"

    def __post_init__(self) -> None:
        if not (self.std >= 0 and self.length_scale > 0):
            raise ValueError(f"std must be >= 0 and length_scale > 0, got {self.std}, {self.length_scale}")
        if self.kernel not in KERNELS:
            raise ValueError(f"kernel: {KERNELS.unknown(self.kernel)}")

    def covariance(self, r1: np.ndarray, r2: np.ndarray) -> np.ndarray:
        """Cross-covariance ``E[w(r1_i) w(r2_j)]``: ``(..., n, 2), (..., m, 2)`` → ``(..., n, m)``."""
        d = np.linalg.norm(np.asarray(r1, float)[..., :, None, :] - np.asarray(r2, float)[..., None, :, :], axis=-1)
        return self.std**2 * KERNELS[self.kernel].correlation(d / self.length_scale)

    def W(self, positions: np.ndarray) -> np.ndarray:
        """``W_k = E[w_k w_k']`` at platform positions ``(..., N, 2)`` → ``(..., N, N)`` (eq. cooperative.10)."""
        return self.covariance(positions, positions)

    def V(self, positions: np.ndarray, previous_positions: np.ndarray) -> np.ndarray:
        """``V_k = E[w_k w_{k−1}']`` for a static field sampled at successive positions (eq. cooperative.10)."""
        return self.covariance(positions, previous_positions)

    def markov(self, positions: np.ndarray, previous_positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """First-order model ``w_k = A^w w_{k−1} + η`` (docs/theory/cooperative.md, eq. cooperative.11).

        Returns
        -------
        A_w : ndarray, shape (..., N, N)
            ``V_k W_{k−1}⁻¹``.
        Q_w : ndarray, shape (..., N, N)
            ``W_k − A^w W_{k−1} A^w'`` (the conditional covariance of ``w_k`` given ``w_{k−1}``).

        Raises
        ------
        ValueError
            ``W_{k−1}`` is singular (two platforms at one point).
        """
        W_prev = self.W(previous_positions)
        V = self.V(positions, previous_positions)
        # docs/theory/cooperative.md, eq. cooperative.11
        try:
            A_w = np.swapaxes(np.linalg.solve(W_prev, np.swapaxes(V, -1, -2)), -1, -2)
        except np.linalg.LinAlgError:
            raise ValueError(
                "positions: the spatial-noise covariance W of the previous positions is singular (two platforms "
                "at one point?): the coloured-noise model needs distinct platform positions"
            ) from None
        # docs/theory/cooperative.md, eq. cooperative.11
        Q_w = self.W(positions) - A_w @ W_prev @ np.swapaxes(A_w, -1, -2)
        return A_w, 0.5 * (Q_w + np.swapaxes(Q_w, -1, -2))

    def sample(self, positions: np.ndarray, rng: np.random.Generator, size: tuple[int, ...] = ()) -> np.ndarray:
        """Exact joint Gaussian samples of ``w`` at all points of ``positions`` ``(..., 2)``.

        Returns shape ``size + positions.shape[:-1]``. Cost O(P³) in the number of points P; a jitter of
        ``1e-10 σ_w²`` on the diagonal keeps the Cholesky factorisation defined for repeated points.
        """
        positions = np.asarray(positions, dtype=float)
        flat = positions.reshape(-1, 2)
        cov = self.covariance(flat, flat) + 1e-10 * self.std**2 * np.eye(len(flat))
        L = np.linalg.cholesky(cov)
        z = rng.standard_normal(tuple(size) + (len(flat),))
        return (z @ L.T).reshape(tuple(size) + positions.shape[:-1])

    def realisation(
        self, rng: np.random.Generator, batch: tuple[int, ...] = (), n_features: int = 400
    ) -> NoiseRealisation:
        """Draw independent sample functions (one per batch entry) with ``n_features`` Fourier features."""
        omega = KERNELS[self.kernel].sample_frequencies(rng, tuple(batch) + (n_features,)) / self.length_scale
        phases = rng.uniform(0.0, 2 * np.pi, size=tuple(batch) + (n_features,))
        return NoiseRealisation(omega, phases, self.std)


class SpatialNoiseConfig(StrictModel):
    """YAML form: ``{std: 0.2, length_scale: 3.0, kernel: squared_exponential}``."""

    std: PositiveFloat
    length_scale: PositiveFloat
    kernel: KernelName = "squared_exponential"

    def to_noise(self) -> SpatialNoise:
        """The corresponding :class:`SpatialNoise`."""
        return SpatialNoise(self.std, self.length_scale, self.kernel)
