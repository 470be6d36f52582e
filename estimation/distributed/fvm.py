"""Finite-volume Laplacian of a sensor cell and the PDE constraint ``G x = g`` (docs/theory/distributed.md §5–§6).

Derivation (our notation; the printed symbols of Zhang et al. (2023), eqs. 20-27 and 34, are garbled). For a
cell C with vertices ``r_0..r_{n−1}`` counter-clockwise and centre ``c``, the divergence theorem gives
``∫_C Δz = Σ_s ∫_s ∇z·ν_s``. On edge ``s`` (from ``r_s`` to ``r_{s+1}``, length ``ℓ_s``, unit tangent
``τ_s``, outward normal ``ν_s = (τ_y, −τ_x)``) let ``f_s`` be the far point: the neighbour's centre across
the edge, or the edge midpoint on the boundary, and ``t_s = (f_s − c)/d_s``, ``d_s = |f_s − c|``. Split
the normal into the two directions in which differences are available (eq. 21),

    ν_s = α_s τ_s + β_s t_s,    β_s = 1/(t_s·ν_s) = 1/cos θ_s,    α_s = −(t_s·τ_s)/(t_s·ν_s) = ∓tan θ_s,

so that, with ``∫_s ∇z·τ_s = z(r_{s+1}) − z(r_s)`` (exact) and ``∫_s ∇z·t_s ≈ ℓ_s (z(f_s) − z(c))/d_s``
(eq. 23; on a boundary edge ``z(f_s) ≈ ½(z(r_s) + z(r_{s+1}))``),

    Δz(c) ≈ (1/A) Σ_s [ α_s (z_{s+1} − z_s) + b_s (z(f_s) − z(c)) ],     b_s = β_s ℓ_s / d_s.     (eq. 24)

It is exact for linear fields on any cell and, on interior cells, for quadratic fields when every far
point is the mirror image of ``c`` in the edge midpoint (regular meshes: uniform rectangles, uniform
triangles); on smoothly distorted meshes the interior error falls at about h² (measured orders 1.70 and 1.87
on a smoothly warped grid; the test requires > 1.6). The boundary rule is not
consistent: its difference quotient is centred between ``c`` and the midpoint, and the vertex mean misses
``z`` at the midpoint by ⅛ℓ²τ'Hτ, so a boundary cell's Laplacian errs by O(‖H‖) at any size (an
isolated equilateral triangle returns twice Δz of a quadratic; isolated squares happen to be exact) — see the
tests. The constraint multiplies it by θΔt, which keeps the bias small for smooth fields.

Substituting into the explicit discretisation of ``∂z/∂t = θΔz + v·∇z`` about the previous centre
(eq. 20), with the state ``x = [z(c, k−1), ∇z(c, k−1)', z(c, k), ∇z(c, k)']'`` (eq. distributed.4):

    z(c, k) − z(c, k−1) = Δt v·∇z(c, k−1) + θΔt Δz(c, k−1)
    ⇒  G = [θΔt S/A − 1, −Δt v', 1, 0, 0],  S = Σ_s b_s,
       g = (θΔt/A) Σ_s [α_s (z_{s+1} − z_s) + b_s z(f_s)]                                    (eqs. 26-27)

(the paper prints the first entry as ``1 + θΔtS/A``; the sign above follows from eq. 24). The filter
uses ``ĝ`` (eq. 35): vertex values are the sensors' measurements and ``z(f_s)`` the neighbours' shared
centre estimates.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .mesh import MeshError, SensorMesh, following, polygon_area

__all__ = [
    "LaplacianStencil",
    "laplacian_stencil",
    "far_points",
    "pde_constraint",
    "project",
    "mesh_laplacian",
]


@dataclass(frozen=True)
class LaplacianStencil:
    """Weights of the finite-volume Laplacian of one cell (eq. 24).

    Attributes
    ----------
    area : float
        Cell area A (L²).
    tangent_weights : ndarray, shape (n,)
        α_s, multiplying ``z_{s+1} − z_s`` along edge s (dimensionless).
    centre_weights : ndarray, shape (n,)
        b_s = ℓ_s/(d_s cos θ_s), multiplying ``z(f_s) − z(c)`` (dimensionless).
    """

    area: float
    tangent_weights: np.ndarray
    centre_weights: np.ndarray

    def apply(self, vertex_values: np.ndarray, centre_value: float, far_values: np.ndarray) -> float:
        """Δz at the centre (field unit / L²) from the vertex, centre and far-point values (eq. 24)."""
        vertex_values = np.asarray(vertex_values, dtype=float)
        along = following(vertex_values) - vertex_values  # z_{s+1} − z_s
        across = np.asarray(far_values, dtype=float) - centre_value
        return float(self.tangent_weights @ along + self.centre_weights @ across) / self.area


def far_points(
    vertices: np.ndarray, vertex_values: np.ndarray, across: Sequence[tuple[np.ndarray, float] | None]
) -> tuple[np.ndarray, np.ndarray]:
    """Far point and its value for every edge: the neighbour's centre, or the midpoint on the boundary.

    Parameters
    ----------
    vertices : ndarray, shape (n, 2)
        Cell vertices counter-clockwise (L).
    vertex_values : ndarray, shape (n,)
        Field values (or measurements) at the vertices.
    across : sequence of length n
        For edge s, ``(neighbour_centre, neighbour_centre_value)`` or ``None`` on the boundary.

    Returns
    -------
    points : ndarray, shape (n, 2)
    values : ndarray, shape (n,)
        On a boundary edge the midpoint and the mean of its two vertex values (eq. 23).
    """
    vertices = np.asarray(vertices, dtype=float)
    vertex_values = np.asarray(vertex_values, dtype=float)
    points = 0.5 * (vertices + following(vertices))
    values = 0.5 * (vertex_values + following(vertex_values))
    for s, item in enumerate(across):
        if item is not None:
            points[s], values[s] = item
    return points, values


def laplacian_stencil(vertices: np.ndarray, centre: np.ndarray, far: np.ndarray) -> LaplacianStencil:
    """Weights of the finite-volume Laplacian (eqs. 21-24) of one cell.

    Parameters
    ----------
    vertices : ndarray, shape (n, 2)
        Cell vertices counter-clockwise (L).
    centre : ndarray, shape (2,)
        Cell centre c (L).
    far : ndarray, shape (n, 2)
        Far point f_s of every edge (see :func:`far_points`) (L).

    Raises
    ------
    MeshError
        If the cell is not counter-clockwise with positive area, or a centre line ``c → f_s`` does not
        cross its edge outward (``t_s·ν_s ≤ 0``: the cells overlap or fold).
    """
    vertices = np.asarray(vertices, dtype=float)
    area = float(polygon_area(vertices))
    if not area > 0:
        raise MeshError(
            f"cell with vertices {vertices.tolist()} has area {area:g} (expected > 0, counter-clockwise)"
        )
    edge = following(vertices) - vertices
    length = np.sqrt(np.einsum("sd,sd->s", edge, edge))
    tau = edge / length[:, None]  # unit tangent τ_s
    nu = np.stack([tau[:, 1], -tau[:, 0]], axis=1)  # outward normal ν_s
    link = np.asarray(far, dtype=float) - np.asarray(centre, dtype=float)
    d = np.sqrt(np.einsum("sd,sd->s", link, link))
    t = link / d[:, None]  # centre-line direction t_s
    cos_theta = np.einsum("sd,sd->s", t, nu)
    if np.any(cos_theta <= 0):
        bad = int(np.argmin(cos_theta))
        raise MeshError(f"centre line of edge {bad} does not cross it outward (cos θ = {cos_theta[bad]:.3g})")
    beta = 1.0 / cos_theta  # docs/theory/distributed.md, eq. distributed.10
    alpha = -np.einsum("sd,sd->s", t, tau) * beta  # docs/theory/distributed.md, eq. distributed.10
    return LaplacianStencil(area=area, tangent_weights=alpha, centre_weights=beta * length / d)


def pde_constraint(
    stencil: LaplacianStencil,
    vertex_values: np.ndarray,
    far_values: np.ndarray,
    time_step: float,
    diffusivity: float,
    velocity: np.ndarray,
) -> tuple[np.ndarray, float]:
    """Row ``G`` and right-hand side ``g`` of the PDE constraint ``G x = g`` of one cell (eqs. 26-27, 35).

    Parameters
    ----------
    stencil : LaplacianStencil
        Geometry of the cell at the previous step k−1.
    vertex_values : ndarray, shape (n,)
        Field values at the vertices at k−1 (the filter passes the measurements, eq. 35).
    far_values : ndarray, shape (n,)
        Values at the far points at k−1 (neighbours' centre estimates, boundary vertex means).
    time_step : float
        Δt (s).
    diffusivity : float
        θ (L²/s).
    velocity : ndarray, shape (2,)
        v (L/s).

    Returns
    -------
    G : ndarray, shape (6,)
        Acting on ``x = [z(c,k−1), ∇z(c,k−1)', z(c,k), ∇z(c,k)']'``.
    g : float
    """
    vertex_values = np.asarray(vertex_values, dtype=float)
    scale = diffusivity * time_step / stencil.area  # θΔt/A
    along = following(vertex_values) - vertex_values
    G = np.zeros(6)
    G[0] = scale * stencil.centre_weights.sum() - 1.0  # docs/theory/distributed.md, eq. distributed.12 (sign derived)
    G[1:3] = -time_step * np.asarray(velocity, dtype=float)  # docs/theory/distributed.md, eq. distributed.12
    G[3] = 1.0
    g = scale * float(
        stencil.tangent_weights @ along + stencil.centre_weights @ np.asarray(far_values)
    )  # eq. 27
    return G, g


def project(
    x: np.ndarray, G: np.ndarray, g: np.ndarray | float, metric: np.ndarray | None = None
) -> np.ndarray:
    """Projection onto ``{x : G x = g}``: ``x̃ = x − M G'(G M G')⁻¹(G x − g)`` (eq. distributed.13).

    ``M = I`` (the default) is the Euclidean projection of Zhang et al. (2023), eq. 34; ``M = P``, the error
    covariance, is the minimum-variance projection of Simon & Chia (2002), which does not depend on the units
    of the state.

    Parameters
    ----------
    x : ndarray, shape (..., n)
        Estimates (a leading batch axis projects several chains at once).
    G : ndarray, shape (n,) or (m, n)
        One constraint row, or m independent rows.
    g : float or ndarray, shape (...) for one row, (..., m) for m rows
    metric : ndarray, shape (n, n), optional
        Symmetric positive definite M (default I).

    Returns
    -------
    ndarray, shape (..., n)
    """
    G = np.asarray(G, dtype=float)
    g = np.asarray(g, dtype=float)
    if G.ndim == 1:  # one constraint row: g is a scalar per estimate
        G, g = G[None, :], g[..., None]
    MG = G.T if metric is None else metric @ G.T  # M G', shape (n, m)
    residual = x @ G.T - g  # G x − g, shape (..., m)
    # docs/theory/distributed.md, eq. distributed.13
    return x - np.linalg.solve(G @ MG, residual[..., None])[..., 0] @ MG.T


def mesh_laplacian(
    mesh: SensorMesh, positions: np.ndarray, vertex_values: np.ndarray, centre_values: np.ndarray
) -> np.ndarray:
    """Finite-volume Laplacian at every cell centre of a mesh (eq. 24), shape (n_cells,).

    Parameters
    ----------
    mesh : SensorMesh
    positions : ndarray, shape (N, 2)
        Sensor positions (L).
    vertex_values : ndarray, shape (N,)
        Field values at the sensors.
    centre_values : ndarray, shape (n_cells,)
        Field values at the cell centres ``mesh.centres(positions)``.
    """
    positions = np.asarray(positions, dtype=float)
    centres = mesh.centres(positions)
    out = np.empty(mesh.n_cells)
    for j, cell in enumerate(mesh.cells):
        across = [
            None if e.neighbour is None else (centres[e.neighbour], float(centre_values[e.neighbour]))
            for e in mesh.edges(j)
        ]
        points, values = far_points(positions[list(cell)], vertex_values[list(cell)], across)
        stencil = laplacian_stencil(positions[list(cell)], centres[j], points)
        out[j] = stencil.apply(vertex_values[list(cell)], float(centre_values[j]), values)
    return out
