"""Distributed constrained cooperative Kalman filter (docs/theory/distributed.md §3–§6).

The algorithm is that of Zhang et al. (2023), §§3, 5, Algorithm 1, with their equation numbers. Each
:class:`CellFilter` estimates, at its own centre, the state (docs/theory/distributed.md, eq. distributed.4;
Zhang et al. (2023), eq. 13)

    x(k) = [z(c^{k−1}, k−1), ∇z(c^{k−1}, k−1)', z(c^{k−1}, k), ∇z(c^{k−1}, k)']'     (6 entries, 2-D)

from its own sensors only (intra-cell step, eqs. 28-32), then shares ``ẑ+(c^{k−1}, k−1)`` with the
cells across its edges and projects onto the PDE constraint using what it received (inter-cell step,
eq. 34). The only thing that crosses a cell boundary is a :class:`CentreEstimate` message, so the
cells could run on separate vehicles; :class:`DistributedFilter` merely delivers the messages.

Transition (docs/theory/distributed.md, eq. distributed.5, derived from Zhang et al. (2023), eqs. 9 and 12,
whose printed matrices are garbled). Write
``S(Δr) = [[1, Δr'], [0, I]]`` for the Taylor transport of ``(z, ∇z)`` by ``Δr = c^k − c^{k−1}`` and
``h = [½ Δr'ĤΔr, (ĤΔr)']'`` for its second-order term. Eq. 12 moves both time levels to the new centre,
``y_{k−1} = S x_{1:3} + h``, ``y_k = S x_{4:6} + h``; eq. 9 (``z(c^k, k+1) = 2 z(c^k, k) − z(c^k, k−1)``,
the value changes at a fixed point by the same amount in consecutive steps) is applied to the value and,
in the same way, to the gradient. Hence

    x(k+1) = [y_k; 2 y_k − y_{k−1}] = A x(k) + U,    A = [[0, S], [−S, 2S]],    U = [h; h].

The paper keeps only the ``ĤΔr`` part of ``U``; the ``½Δr'ĤΔr`` value terms make the transition exact
for quadratic fields and cost nothing. Measurements of both time levels are expanded about ``c^{k−1}``
(eqs. 14-16): rows ``[1, δ', 0, 0, 0]`` (time k−1) and ``[0, 0, 0, 1, δ']`` (time k) of ``C`` and
``½ kron(δ, δ)'`` of ``D``, with ``δ = r_i − c^{k−1}``. The Hessian is fitted to the residual
``P − C x̂`` by least squares (eq. 18; the minimum-norm solution, since the two middle columns of ``D``
are equal and ``D'D`` is always singular) or ridge regression (eq. 19). The covariance is propagated
by the Joseph form of :func:`mobisense.estimation.kalman.update`, which equals eq. 32 for the optimal gain. As in
the paper, the projection does not change the covariance, and the unconstrained filter (reported for
comparison) runs beside the constrained one with the same gain.

Two choices the paper leaves open or gets wrong for this state (docs/theory/departures.md):

* Projection metric. Eq. 34 is the Euclidean projection; the state mixes values and gradients, whose units
  differ, so its stability fed back through eq. 28 depends on the length unit (network error map: spectral
  radius 1.24 in metres at the shipped settings, 0.91 in units of 10 m; docs/theory/distributed.md §10.2). The
  default ``projection: covariance`` is Simon & Chia's minimum-variance projection
  ``x̃ = x̂ − P G'(G P G')⁻¹(G x̂ − ĝ)``, unit-independent and stable; ``euclidean`` reproduces eq. 34.
* Hessian. With all sensors at one distance from the centre (a square, a regular triangle) the centre
  value and the Hessian's trace enter the measurements identically, so the least-squares Hessian
  (eq. 18) absorbs value errors it cannot tell apart; ridge regression (eq. 19, the default) keeps the
  value observable at the price of a curvature bias.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field

from ...core.config import NonNegativeFloat, PositiveFloat, StrictModel, Vector2
from ..cooperative.information_model import transition_matrix, vec_to_hessian
from ..kalman import predict, update
from .fvm import far_points, laplacian_stencil, pde_constraint, project
from .mesh import CellEdge, SensorMesh

__all__ = [
    "AssumedPde",
    "ValueGradientStd",
    "HessianOptions",
    "FilterOptions",
    "PdeModel",
    "CentreEstimate",
    "CellFilter",
    "DistributedFilter",
    "cell_transition",
    "cell_measurement_matrices",
    "fit_hessian",
]

#: index of the two chains in the stacked state: the constrained filter drives the formation
CONSTRAINED, UNCONSTRAINED = 0, 1


class ValueGradientStd(StrictModel):
    """Standard deviations of a value (field unit) and of each gradient component (field unit / L)."""

    value: PositiveFloat
    gradient: PositiveFloat

    def covariance(self) -> np.ndarray:
        """Diagonal covariance for the 6-entry state ``[z, ∇z, z, ∇z]``, shape (6, 6)."""
        per_level = [self.value**2, self.gradient**2, self.gradient**2]
        return np.diag(per_level + per_level)


class HessianOptions(StrictModel):
    """Hessian estimate of a cell and the covariance ``Q = error_std² I₄`` of its error.

    Theory: docs/theory/distributed.md §3.4; source: Zhang et al. (2023), eqs. 18-19.
    """

    method: Literal["least_squares", "ridge"] = "ridge"
    ridge: PositiveFloat = Field(1.0, description="ε₀ of eq. 19 (L⁴); used by method 'ridge'")
    error_std: NonNegativeFloat = Field(0.0, description="std of each vec(H) entry error (field unit / L²)")


class AssumedPde(StrictModel):
    """The PDE the filter's constraint assumes, when it differs from the field's (docs/theory/distributed.md §10.1).

    The test field of Zhang et al. (2023), §8, is not a solution of ``∂z/∂t = θΔz + v·∇z`` with its own θ and v,
    but it is an exact solution with ``θ' = θ k₂/k₁²`` and ``v' = (k₂/k₁) v`` (eq. distributed.19: 0.08 m²/s and
    0.002 v for k₁ = 0.05, k₂ = 1e-4); ``assumed_pde`` lets the filter use either.
    """

    diffusivity: PositiveFloat = Field(description="θ assumed by the constraint (L²/s)")
    velocity: Vector2 = Field(description="v assumed by the constraint (L/s)")


class FilterOptions(StrictModel):
    """Noise model of the per-cell filter (Zhang et al. (2023), Assumption 5.1) and its initialisation."""

    process_std: ValueGradientStd = Field(description="W = diag of squared stds, per step")
    initial_std: ValueGradientStd = Field(description="prior std around the first plane fit")
    hessian: HessianOptions = HessianOptions()
    projection: Literal["covariance", "euclidean"] = Field(
        "covariance",
        description="metric of the constraint projection: P (minimum variance) or I (Zhang et al. (2023), eq. 34)",
    )
    assumed_pde: AssumedPde | None = Field(
        None, description="θ, v of the constraint if not the field's (default: the field's own)"
    )


@dataclass(frozen=True)
class PdeModel:
    """The known PDE ``∂z/∂t = θ Δz + v·∇z`` and the sampling interval.

    Parameters
    ----------
    diffusivity : float
        θ (L²/s).
    velocity : ndarray, shape (2,)
        v (L/s).
    time_step : float
        Δt (s).
    """

    diffusivity: float
    velocity: np.ndarray
    time_step: float


@dataclass(frozen=True)
class CentreEstimate:
    """The message a cell sends to the cells across its edges after its intra-cell update (Algorithm 1, 3).

    Attributes
    ----------
    sender : int
        Cell index.
    centre : ndarray, shape (2,)
        The sender's previous centre ``c^{k−1}`` (L).
    value : float
        Its estimate ``ẑ+(c^{k−1}, k−1)``, the first entry of ``x̂+(k)`` (field unit).
    """

    sender: int
    centre: np.ndarray
    value: float


def cell_transition(shift: np.ndarray, hessian: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Transition ``A`` and input ``U`` of a cell's state for a centre shift (module docstring).

    Parameters
    ----------
    shift : ndarray, shape (2,)
        ``Δr = c^k − c^{k−1}`` (L).
    hessian : ndarray, shape (..., 2, 2)
        Hessian estimate (field unit / L²); a leading axis gives one ``U`` per chain.

    Returns
    -------
    A : ndarray, shape (6, 6)
    U : ndarray, shape (..., 6)
    """
    S = transition_matrix(shift)  # [[1, Δr'], [0, I]], docs/theory/distributed.md, eq. distributed.5
    A = np.zeros((6, 6))
    A[:3, 3:] = S  # y_k
    A[3:, :3] = -S  # 2 y_k − y_{k−1}, docs/theory/distributed.md, eq. distributed.5
    A[3:, 3:] = 2.0 * S
    Hdr = np.asarray(hessian, dtype=float) @ shift  # Ĥ Δr
    h = np.concatenate([0.5 * (Hdr @ shift)[..., None], Hdr], axis=-1)  # [½ Δr'ĤΔr, (ĤΔr)']
    return A, np.concatenate([h, h], axis=-1)


def cell_measurement_matrices(
    offsets_previous: np.ndarray, offsets_current: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Taylor matrices of both time levels expanded about the previous centre (eq. distributed.6).

    Source: Zhang et al. (2023), eq. 15.

    Parameters
    ----------
    offsets_previous, offsets_current : ndarray, shape (n, 2)
        ``r_i^{k−1} − c^{k−1}`` and ``r_i^k − c^{k−1}`` (L).

    Returns
    -------
    C : ndarray, shape (2n, 6)
        Rows ``[1, δ', 0, 0, 0]`` (time k−1) then ``[0, 0, 0, 1, δ']`` (time k).
    D : ndarray, shape (2n, 4)
        Rows ``½ kron(δ, δ)'``, so that ``D vec(H) = ½ δ'Hδ``.
    """
    n = offsets_previous.shape[0]
    C = np.zeros((2 * n, 6))
    C[:n, 0], C[:n, 1:3] = 1.0, offsets_previous  # docs/theory/distributed.md, eq. distributed.6
    C[n:, 3], C[n:, 4:6] = 1.0, offsets_current
    offsets = np.concatenate([offsets_previous, offsets_current])
    D = 0.5 * (offsets[:, :, None] * offsets[:, None, :]).reshape(2 * n, 4)  # ½ kron(δ, δ)', eq. 15
    return C, D


def fit_hessian(D: np.ndarray, residual: np.ndarray, options: HessianOptions) -> np.ndarray:
    """``vec Ĥ`` fitted to ``residual = P − C x̂`` by minimum-norm least squares or ridge (eq. distributed.7).

    Source: Zhang et al. (2023), eq. 18 (least squares) and eq. 19 (ridge).

    Parameters
    ----------
    D : ndarray, shape (m, 4)
        Quadratic Taylor matrix (:func:`cell_measurement_matrices`).
    residual : ndarray, shape (..., m)
        One residual per chain.
    options : HessianOptions

    Returns
    -------
    ndarray, shape (..., 4)
        ``[H11, H21, H12, H22]`` with ``H21 = H12``: both solutions treat the two equal columns of ``D``
        symmetrically.
    """
    if options.method == "ridge":
        return np.linalg.solve(D.T @ D + options.ridge * np.eye(4), D.T @ residual.T).T  # eq. 19
    return np.linalg.lstsq(D, residual.T, rcond=None)[0].T  # eq. 18 (pseudo-inverse)


class CellFilter:
    """The constrained and unconstrained cooperative filters of one cell (Zhang et al. (2023), Algorithm 1).

    Parameters
    ----------
    index : int
        Cell index (the ``sender`` of its messages).
    edges : sequence of CellEdge
        The cell's edges counter-clockwise (``SensorMesh.edges``): vertex order and who is across.
    options : FilterOptions
    measurement_std : float
        σ of each sensor's measurement noise (field unit).
    pde : PdeModel

    Notes
    -----
    The cell sees only its own sensors' positions and measurements (arrays ordered like ``sensors``) and
    the messages in its inbox. A neighbour whose message is missing is treated like the boundary (the edge
    midpoint and the mean of its vertex measurements).
    """

    def __init__(
        self,
        index: int,
        edges: Sequence[CellEdge],
        options: FilterOptions,
        measurement_std: float,
        pde: PdeModel,
    ) -> None:
        self.index = index
        self.edges = tuple(edges)
        self.sensors = tuple(e.start for e in self.edges)
        self.neighbours = tuple(e.neighbour for e in self.edges if e.neighbour is not None)
        self.options = options
        self.pde = pde
        self._Rn = measurement_std**2
        self._W = options.process_std.covariance()
        self._Q = options.hessian.error_std**2 * np.eye(4)

    # ------------------------------------------------------------------ intra-cell (eqs. 28-32)
    def start(self, positions: np.ndarray, measurements: np.ndarray) -> None:
        """Initialise from the first measurements by a plane fit about the centre (k = 0).

        Parameters
        ----------
        positions : ndarray, shape (n, 2)
            The cell's sensor positions (L), in ``sensors`` order.
        measurements : ndarray, shape (n,)
        """
        positions = np.asarray(positions, dtype=float)
        centre = positions.mean(axis=0)
        C = np.column_stack([np.ones(len(positions)), positions - centre])
        plane = np.linalg.lstsq(C, measurements, rcond=None)[0]  # [z, ∇z] at c^0
        self._x = np.tile(np.concatenate([plane, plane]), (2, 1))  # both chains, shape (2, 6)
        self._P = self.options.initial_std.covariance()
        self._hessian = np.zeros((2, 2, 2))
        self._centre, self._shift = centre, np.zeros(2)
        self._A, self._U = cell_transition(self._shift, self._hessian)
        self._positions, self._measurements = positions, np.asarray(measurements, dtype=float)
        self._first = True
        self.last_constraint: tuple[np.ndarray, float] | None = None

    def update(self, positions: np.ndarray, measurements: np.ndarray) -> CentreEstimate:
        """Steps 1-5: predict, fit the Hessian, Kalman update with both time levels; return the message.

        Parameters
        ----------
        positions : ndarray, shape (n, 2)
            The cell's sensor positions at step k (L).
        measurements : ndarray, shape (n,)
            Their measurements at step k (field unit).
        """
        if not hasattr(self, "_first"):
            raise RuntimeError("update() before start(): initialise the cell from its first measurements")
        positions = np.asarray(positions, dtype=float)
        if self._first:
            x_prior, P_prior = self._x, self._P
        else:
            x_prior, P_prior = predict(
                self._x[..., None], self._P, self._A, self._W, self._U[..., None]
            )  # eqs. 28-29
            x_prior = x_prior[..., 0]
        C, D = cell_measurement_matrices(self._positions - self._centre, positions - self._centre)
        p = np.concatenate([self._measurements, measurements])  # P(j, k), eq. 17
        vec_h = fit_hessian(D, p - x_prior @ C.T, self.options.hessian)  # eqs. 18-19, shape (2, 4)
        R = D @ self._Q @ D.T + self._Rn * np.eye(len(p))  # D Q D' + R_n, eq. 30
        y = (p - vec_h @ D.T)[..., None]  # P − D Ĥ, eq. 31
        x_post, self._P = update(x_prior[..., None], P_prior, y, C, R)[:2]  # eqs. 30-32
        self._x = x_post[..., 0]
        self._hessian = vec_to_hessian(vec_h)
        self._first = False
        self._measurements_previous, self._positions_previous = self._measurements, self._positions
        self._positions, self._measurements = positions, np.asarray(measurements, dtype=float)
        new_centre = positions.mean(axis=0)
        self._previous_centre, self._shift, self._centre = self._centre, new_centre - self._centre, new_centre
        self._A, self._U = cell_transition(
            self._shift, self._hessian
        )  # for the read-out and the next prediction
        return CentreEstimate(self.index, self._previous_centre, float(self._x[CONSTRAINED, 0]))

    # ------------------------------------------------------------------ inter-cell (eq. 34)
    def constrain(self, inbox: Mapping[int, CentreEstimate]) -> None:
        """Step 6: project the constrained chain onto ``G x = ĝ`` built from the neighbours' messages."""
        vertices = self._positions_previous
        across = []
        for edge in self.edges:
            message = inbox.get(edge.neighbour) if edge.neighbour is not None else None
            across.append(None if message is None else (message.centre, message.value))
        points, values = far_points(vertices, self._measurements_previous, across)  # eq. 23
        stencil = laplacian_stencil(vertices, self._previous_centre, points)
        G, g_hat = pde_constraint(
            stencil,
            self._measurements_previous,
            values,
            self.pde.time_step,
            self.pde.diffusivity,
            self.pde.velocity,
        )  # eq. 35
        metric = self._P if self.options.projection == "covariance" else None
        self._x[CONSTRAINED] = project(self._x[CONSTRAINED], G, g_hat, metric)  # eq. 34
        self.last_constraint = (G, g_hat)

    # ------------------------------------------------------------------ read-out
    def estimate(self, constrained: bool = True) -> tuple[float, np.ndarray]:
        """``(ẑ, ∇ẑ)`` at the current centre and time (field unit, field unit / L), by eq. 12."""
        chain = CONSTRAINED if constrained else UNCONSTRAINED
        y = self._A[:3] @ self._x[chain] + self._U[chain, :3]  # y_k: the first half of the next state
        return float(y[0]), y[1:]

    @property
    def state(self) -> np.ndarray:
        """Current estimates ``[x̃+, x̂+]`` of the two chains, shape (2, 6)."""
        return self._x.copy()

    @property
    def covariance(self) -> np.ndarray:
        """Error covariance ``R+(j, k)`` of the state (eq. 32), shape (6, 6)."""
        return self._P.copy()


class DistributedFilter:
    """All cells of a mesh, with the message passing of Algorithm 1 made explicit.

    Parameters
    ----------
    mesh : SensorMesh
    options : FilterOptions
    measurement_std : float
        σ of the sensor noise (field unit).
    pde : PdeModel
    """

    def __init__(
        self, mesh: SensorMesh, options: FilterOptions, measurement_std: float, pde: PdeModel
    ) -> None:
        self.mesh = mesh
        self.cells = [
            CellFilter(j, mesh.edges(j), options, measurement_std, pde) for j in range(mesh.n_cells)
        ]

    def start(self, positions: np.ndarray, measurements: np.ndarray) -> None:
        """Initialise every cell from the sensors' first positions (N, 2) and measurements (N,)."""
        for cell in self.cells:
            cell.start(positions[list(cell.sensors)], measurements[list(cell.sensors)])

    def step(self, positions: np.ndarray, measurements: np.ndarray) -> None:
        """One time step: every cell updates from its own sensors, then projects with its inbox."""
        outbox = {
            cell.index: cell.update(positions[list(cell.sensors)], measurements[list(cell.sensors)])
            for cell in self.cells
        }  # intra-cell communication
        for cell in self.cells:  # inter-cell communication: neighbours' messages only
            cell.constrain({n: outbox[n] for n in cell.neighbours})

    def estimates(self, constrained: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Values (n_cells,) and gradients (n_cells, 2) at the current centres."""
        pairs = [cell.estimate(constrained) for cell in self.cells]
        return np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
