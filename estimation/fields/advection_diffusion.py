"""Advection–diffusion fields (docs/theory/distributed.md §1): an exact solution and the paper's field.

The PDE is ``∂z/∂t = θ Δz + v·∇z`` (eq. distributed.1); the paper's field is the test field of
Zhang et al. (2023), §8.

Both are products of two travelling, decaying sine waves,

    z(r, t) = A sin(π (k x + ω_x t)) sin(π (k y + ω_y t)) e^{−λ t},     r = (x, y),

and differ only in the three rates ``(ω_x, ω_y, λ)``:

``variant="exact"`` (default)
    ``ω = k v``, ``λ = 2 θ π² k²``. With ``a = πk(x + v_x t)``, ``b = πk(y + v_y t)``:
    ``∂z/∂t = πk v_x cos a sin b e + πk v_y sin a cos b e − 2θπ²k² z = v·∇z + θ Δz`` because
    ``∇z = πk (cos a sin b, sin a cos b) e`` and ``Δz = −2π²k² z``. The sign matters: with ``+ v·∇z`` in
    docs/theory/distributed.md, eq. distributed.1, the pattern is ``f(r + v t)``, i.e. it drifts along **−v**
    (the usual advection equation ``∂z/∂t + u·∇z = θΔz`` has ``u = −v``).
``variant="paper"``
    The test field of Zhang et al. (2023), §8, ``sin(π(k₁x + v₁k₂t)) sin(π(k₁y + v₂k₂t)) e^{−2θπ²k₂t}``
    (``k₁ = wavenumber``, ``k₂ = temporal_wavenumber``): ``ω = k₂ v``, ``λ = 2θπ²k₂``. It does **not** satisfy the PDE
    (residual ``(k₂/k₁ − 1) v·∇z + 2θπ²(k₁² − k₂) z``), which :meth:`AdvectionDiffusionField.pde_residual`
    reports; it is offered to reproduce the paper's numbers.

Units: positions in the length unit L, time in s, θ in L²/s, v in L/s, k in 1/L (spatial period 2/k).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np

from .base import Field, register_field

__all__ = ["AdvectionDiffusionField"]


@register_field
class AdvectionDiffusionField(Field):
    """Travelling, decaying product of sines; an exact advection–diffusion solution by default.

    Parameters
    ----------
    diffusivity : float
        θ > 0 (L²/s).
    velocity : sequence of 2 floats
        v (L/s) in ``∂z/∂t = θ Δz + v·∇z``.
    wavenumber : float
        Spatial wavenumber k > 0 (1/L); the pattern repeats every ``2/k``.
    amplitude : float
        A (field unit).
    variant : {"exact", "paper"}
        ``"exact"`` solves the PDE; ``"paper"`` is the paper's field (see the module docstring).
    temporal_wavenumber : float
        k₂ of the paper's field (1/L); used only by ``variant="paper"``.

    Notes
    -----
    Every method also accepts an array ``t`` broadcasting against ``r.shape[:-1]`` (one time per point),
    and complex ``r`` or ``t`` (for complex-step differentiation).

    Examples
    --------
    >>> import numpy as np
    >>> from mobisense.estimation.fields.base import make_field
    >>> field = make_field("advection_diffusion", diffusivity=2.0, velocity=(0.5, 1.0), wavenumber=0.005)
    >>> float(field.value(np.array([100.0, 100.0]), 0.0))
    1.0
    >>> abs(float(field.pde_residual(np.array([3.0, 4.0]), 7.0))) < 1e-15
    True
    """

    kind = "advection_diffusion"

    def __init__(
        self,
        diffusivity: float = 2.0,
        velocity: Sequence[float] = (0.5, 1.0),
        wavenumber: float = 0.005,
        amplitude: float = 1.0,
        variant: Literal["exact", "paper"] = "exact",
        temporal_wavenumber: float = 1e-4,
    ) -> None:
        if not diffusivity > 0 or not wavenumber > 0 or not temporal_wavenumber > 0:
            raise ValueError(
                "diffusivity, wavenumber and temporal_wavenumber must be > 0, got "
                f"{diffusivity!r}, {wavenumber!r}, {temporal_wavenumber!r}"
            )
        velocity = np.asarray(velocity, dtype=float)
        if velocity.shape != (2,):
            raise ValueError(f"velocity: expected 2 components, got shape {velocity.shape}")
        if variant not in ("exact", "paper"):
            raise ValueError(f"variant: expected 'exact' or 'paper', got {variant!r}")
        self.diffusivity = float(diffusivity)
        self.velocity = velocity
        self.wavenumber = float(wavenumber)
        self.amplitude = float(amplitude)
        self.variant = variant
        self.temporal_wavenumber = float(temporal_wavenumber)
        k, theta = self.wavenumber, self.diffusivity
        if variant == "exact":
            self._omega = k * velocity  # phase rates ω = k v
            self._decay = 2.0 * theta * np.pi**2 * k**2  # λ = 2θπ²k²
        else:
            k2 = self.temporal_wavenumber
            self._omega = k2 * velocity  # Zhang et al. (2023), §8: ω = k₂ v
            self._decay = 2.0 * theta * np.pi**2 * k2  # Zhang et al. (2023), §8: λ = 2θπ²k₂

    def __repr__(self) -> str:
        return (
            f"AdvectionDiffusionField(diffusivity={self.diffusivity}, velocity={self.velocity.tolist()}, "
            f"wavenumber={self.wavenumber}, amplitude={self.amplitude}, variant={self.variant!r})"
        )

    def _parts(self, r: np.ndarray, t: complex | float) -> tuple[np.ndarray, ...]:
        """Phases' sines and cosines and the amplitude envelope ``A e^{−λt}``.

        Complex ``r`` or ``t`` pass through unchanged (tests differentiate by complex step).
        """
        r = np.asarray(r)
        k = self.wavenumber
        a = np.pi * (k * r[..., 0] + self._omega[0] * t)
        b = np.pi * (k * r[..., 1] + self._omega[1] * t)
        envelope = self.amplitude * np.exp(-self._decay * t)
        return np.sin(a), np.cos(a), np.sin(b), np.cos(b), envelope

    def value(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Field value z(r, t), shape ``r.shape[:-1]`` (field unit)."""
        sa, _, sb, _, e = self._parts(r, t)
        return sa * sb * e

    def gradient(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Gradient ∇z(r, t), shape ``r.shape`` (field unit / L)."""
        sa, ca, sb, cb, e = self._parts(r, t)
        pk = np.pi * self.wavenumber
        return np.stack([pk * ca * sb * e, pk * sa * cb * e], axis=-1)

    def hessian(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Hessian ∇²z(r, t), shape ``r.shape + (2,)`` (field unit / L²)."""
        sa, ca, sb, cb, e = self._parts(r, t)
        pk2 = (np.pi * self.wavenumber) ** 2
        diag = -pk2 * sa * sb * e
        off = pk2 * ca * cb * e
        return np.stack([np.stack([diag, off], -1), np.stack([off, diag], -1)], axis=-2)

    def laplacian(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Δz(r, t) = −2π²k² z, shape ``r.shape[:-1]`` (field unit / L²)."""
        return -2.0 * (np.pi * self.wavenumber) ** 2 * self.value(r, t)

    def time_derivative(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """∂z/∂t(r, t), shape ``r.shape[:-1]`` (field unit / s)."""
        sa, ca, sb, cb, e = self._parts(r, t)
        return np.pi * (self._omega[0] * ca * sb + self._omega[1] * sa * cb) * e - self._decay * sa * sb * e

    def pde_residual(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """``∂z/∂t − θ Δz − v·∇z`` (eq. distributed.3), shape ``r.shape[:-1]``: round-off for ``variant="exact"``."""
        advection = self.gradient(r, t) @ self.velocity
        return self.time_derivative(r, t) - self.diffusivity * self.laplacian(r, t) - advection
