"""Gradient-based adaptive formation of a sensor mesh (docs/theory/distributed.md §7), vectorised over sensors.

The equation numbers below are those of Zhang et al. (2023), eqs. 38-44.

Every sensor ``i`` combines the gradient estimates of the cells it belongs to, weighted by inverse
squared distance to their centres (eq. 38), ``v_i = Σ_{j∋i} ∇̂z(c_j)/‖r_i − c_j‖²``, by default divided by
``Σ_{j∋i} 1/‖r_i − c_j‖²`` (``weighting: mean``): the printed sum has units field/L³ and grows as the
formation shrinks and with the number of cells a sensor belongs to, so the inner and outer sensors of the
paper's mesh would get desired distances up to ~3 times apart in a uniform gradient. Its heading is
``w_i = v_i/‖v_i‖`` (eq. 41) and ``w_i^⊥`` is ``w_i`` turned by +90°. Each link ``(i, i')`` — every pair of
sensors sharing a cell, the sensors a sensor talks to (eq. 3) — gets the desired spacing (eq. 39)

    ρ_ii' = ε₁ / (½‖v_i + v_i'‖² + ε₂) + ε₃  ∈ (ε₃, ε₁/ε₂ + ε₃),

small where the field is steep and large where it is flat, and the desired distance ``d_ii' = ℓ_ii' ρ_ii'``
with ``ℓ ≡ 1`` (the paper) or, with ``keep_shape``, ``ℓ`` the initial link lengths divided by their mean:
equal distances cannot be met by a rectangle's sides and diagonals, nor by the 20 edges of the paper's mesh
of 4 triangles and 5 rectangles (the angles at its four inner vertices would sum to 1320°, not 1440°).
Including the diagonals makes the paper's mesh rigid (30 links, rank 21 = 2·12 − 3).

Velocity (eqs. 42, 40): ``u_i = a w_i + b w_i^⊥ + c f_i`` (source seeking) or, for contour following
(SUSD, eq. 44), ``u_i = a (z_d − p_i) w_i + b w_i^⊥ + c f_i``; ``r_i ← r_i + Δt u_i``. The spacing term is

    f_i = Σ_{i'} (‖r_i − r_i'‖ − d_ii') (r_i' − r_i)/‖r_i' − r_i‖ = −∂V/∂r_i,
    V = ½ Σ_links (‖r_i − r_i'‖ − d_ii')²,

which pulls neighbours together when they are farther apart than ``d`` and pushes them apart when closer:
the stable direction (the paper's sentence states the reverse, which would make V grow). With eq. 44 as
printed, ``(p_i − z_d)``, a sensor above the level would climb further; ``(z_d − p_i)`` with ``a > 0`` is
the convergent sign (equivalently eq. 44 with ``a < 0``). Units: positions L, time s, ``a, b`` in L/s
(SUSD: ``a`` in L/s per field unit), ``c`` in 1/s, ``ε₁`` in L·(field unit/L)², ``ε₂`` in
(field unit/L)² (with ``weighting: sum``: L·(field unit/L³)² and (field unit/L³)²), ``ε₃`` in L.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from ...core.config import FiniteFloat, InvalidValue, NonNegativeFloat, PositiveFloat, StrictModel
from ...estimation.distributed.mesh import SensorMesh

__all__ = [
    "FormationOptions",
    "GradientFormation",
    "weighted_gradients",
    "headings",
    "desired_spacing",
    "spacing_term",
    "spacing_potential",
]


class FormationOptions(StrictModel):
    """Gains of the gradient-based formation law (Zhang et al. (2023), eqs. 39, 42, 44)."""

    law: Literal["source_seeking", "susd"] = "source_seeking"
    a: FiniteFloat = Field(1.0, description="gain along w (L/s; SUSD: L/s per field unit)")
    b: FiniteFloat = Field(0.0, description="gain along w⊥ (L/s)")
    c: NonNegativeFloat = Field(
        0.1, description="spacing gain (1/s); stable if c Δt < 2/λmax(link stiffness): 0.32 (paper's mesh)"
    )
    epsilon1: PositiveFloat
    epsilon2: PositiveFloat
    epsilon3: PositiveFloat
    desired_level: FiniteFloat | None = Field(None, description="z_d of the SUSD law (field unit)")
    keep_shape: bool = Field(True, description="scale the initial edge lengths instead of equal distances")
    weighting: Literal["mean", "sum"] = Field(
        "mean", description="eq. 38 as a weighted mean or the paper's sum"
    )

    @model_validator(mode="after")
    def _level_for_susd(self) -> FormationOptions:
        if self.law == "susd" and self.desired_level is None:
            raise InvalidValue("desired_level", "required by law 'susd' (the level z_d to follow)")
        return self

    @property
    def spacing_bounds(self) -> tuple[float, float]:
        """The open interval ``(ε₃, ε₁/ε₂ + ε₃)`` of the desired spacing ρ (L)."""
        return self.epsilon3, self.epsilon1 / self.epsilon2 + self.epsilon3


def weighted_gradients(
    positions: np.ndarray,
    centres: np.ndarray,
    gradients: np.ndarray,
    membership: np.ndarray,
    normalise: bool = True,
) -> np.ndarray:
    """``v_i = Σ_{j∋i} ∇̂z(c_j)/‖r_i − c_j‖²``, by default divided by ``Σ_{j∋i} 1/‖r_i − c_j‖²`` (eq. distributed.14).

    Source: Zhang et al. (2023), eq. 38 (the weighted sum).

    Parameters
    ----------
    positions : ndarray, shape (N, 2)
        Sensor positions (L).
    centres : ndarray, shape (n_cells, 2)
        Cell centres (L).
    gradients : ndarray, shape (n_cells, 2)
        Gradient estimates at the centres (field unit / L).
    membership : ndarray, shape (N, n_cells)
        1 where sensor i is a vertex of cell j (``SensorMesh.membership``).
    normalise : bool
        Return the weighted mean (field unit / L) instead of the paper's weighted sum (field unit / L³).

    Returns
    -------
    ndarray, shape (N, 2)
    """
    squared = np.sum(
        (positions[:, None, :] - centres[None, :, :]) ** 2, axis=-1
    )  # ‖r_i − c_j‖², (N, n_cells)
    weights = np.divide(membership, squared, out=np.zeros_like(squared), where=membership > 0)
    if normalise:
        weights /= weights.sum(axis=1, keepdims=True)
    return weights @ gradients  # docs/theory/distributed.md, eq. distributed.14


def headings(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit headings ``w = v/‖v‖`` (eq. 41) and ``w⊥`` (w turned +90°), shape (N, 2) each; 0 where v = 0."""
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    w = np.divide(v, norm, out=np.zeros_like(v), where=norm > 0)
    return w, np.stack([-w[..., 1], w[..., 0]], axis=-1)


def desired_spacing(v: np.ndarray, links: np.ndarray, epsilon1: float, epsilon2: float, epsilon3: float):
    """Desired spacing ``ρ_ii' = ε₁/(½‖v_i + v_i'‖² + ε₂) + ε₃`` of each link (eq. distributed.15), shape (E,)."""
    pair_sum = v[links[:, 0]] + v[links[:, 1]]
    # docs/theory/distributed.md, eq. distributed.15
    return epsilon1 / (0.5 * np.sum(pair_sum**2, axis=-1) + epsilon2) + epsilon3


def spacing_term(positions: np.ndarray, links: np.ndarray, desired: np.ndarray) -> np.ndarray:
    """Stable spacing term ``f_i = Σ_i' (‖r_i − r_i'‖ − d_ii')(r_i' − r_i)/‖r_i' − r_i‖`` (eq. 43), (N, 2)."""
    diff = positions[links[:, 1]] - positions[links[:, 0]]  # r_i' − r_i
    dist = np.linalg.norm(diff, axis=-1)
    # docs/theory/distributed.md, eq. distributed.17 (attractive when too far)
    pull = ((dist - desired) / dist)[:, None] * diff
    f = np.zeros_like(positions)
    np.add.at(f, links[:, 0], pull)
    np.add.at(f, links[:, 1], -pull)
    return f


def spacing_potential(positions: np.ndarray, links: np.ndarray, desired: np.ndarray) -> float:
    """``V = ½ Σ_links (‖r_i − r_i'‖ − d_ii')²`` (L²), whose negative gradient is :func:`spacing_term`."""
    dist = np.linalg.norm(positions[links[:, 1]] - positions[links[:, 0]], axis=-1)
    return 0.5 * float(np.sum((dist - desired) ** 2))


class GradientFormation:
    """The formation controller of a sensor mesh.

    Parameters
    ----------
    mesh : SensorMesh
    options : FormationOptions
    initial_positions : ndarray, shape (N, 2)
        Reference shape for ``keep_shape`` (L).
    """

    def __init__(self, mesh: SensorMesh, options: FormationOptions, initial_positions: np.ndarray) -> None:
        self.mesh = mesh
        self.options = options
        self.links = mesh.cell_pairs
        lengths = np.linalg.norm(
            initial_positions[self.links[:, 1]] - initial_positions[self.links[:, 0]], axis=-1
        )
        #: ℓ_ii', the shape ratios multiplying the spacing ρ, shape (E,)
        self.shape_ratios = lengths / lengths.mean() if options.keep_shape else np.ones(len(self.links))

    def desired_distances(self, positions: np.ndarray, gradients: np.ndarray) -> np.ndarray:
        """Desired distances ``d = ℓ ρ`` of every link (L), shape (E,), from the cells' gradient estimates."""
        return self._desired(self._weighted(positions, gradients))

    def _weighted(self, positions: np.ndarray, gradients: np.ndarray) -> np.ndarray:
        centres = self.mesh.centres(positions)
        normalise = self.options.weighting == "mean"
        return weighted_gradients(positions, centres, gradients, self.mesh.membership, normalise)

    def _desired(self, v: np.ndarray) -> np.ndarray:
        o = self.options
        return self.shape_ratios * desired_spacing(v, self.links, o.epsilon1, o.epsilon2, o.epsilon3)

    def velocities(
        self, positions: np.ndarray, gradients: np.ndarray, measurements: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Sensor velocities (eq. 42 or 44) and the desired distances used.

        Parameters
        ----------
        positions : ndarray, shape (N, 2)
            Sensor positions (L).
        gradients : ndarray, shape (n_cells, 2)
            Gradient estimates at the cell centres (field unit / L).
        measurements : ndarray, shape (N,), optional
            The sensors' measurements p_i, required by the SUSD law.

        Returns
        -------
        u : ndarray, shape (N, 2)
            Velocities (L/s).
        desired : ndarray, shape (E,)
            Desired distances of ``links`` (L).
        """
        o = self.options
        v = self._weighted(positions, gradients)
        w, w_perp = headings(v)
        desired = self._desired(v)
        f = spacing_term(positions, self.links, desired)
        if o.law == "susd":
            if measurements is None:
                raise ValueError("the SUSD law needs the sensors' measurements")
            along = (
                o.a * (o.desired_level - np.asarray(measurements))[:, None]
            )  # docs/theory/distributed.md, eq. distributed.18 (stable sign)
        else:
            along = o.a
        return along * w + o.b * w_perp + o.c * f, desired  # docs/theory/distributed.md, eq. distributed.16
