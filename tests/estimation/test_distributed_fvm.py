"""Sensor mesh topology and the finite-volume Laplacian / PDE constraint.

Theory: docs/theory/distributed.md §2, §5; source: Zhang et al. (2023), eqs. 20-27, 34.
"""

from __future__ import annotations

import numpy as np
import pytest

from mobisense.estimation.distributed.fvm import far_points, laplacian_stencil, mesh_laplacian, pde_constraint, project
from mobisense.estimation.distributed.mesh import MeshError, SensorMesh, grid_network, paper_network

H = np.array([[1.3, 0.4], [0.4, -0.7]])  # a generic symmetric Hessian (trace 0.6)
G0 = np.array([0.2, -0.5])


def quadratic(points: np.ndarray) -> np.ndarray:
    return 0.5 * np.einsum("...i,ij,...j->...", points, H, points) + points @ G0 + 3.0


def laplacian_of(mesh: SensorMesh, positions: np.ndarray, field) -> np.ndarray:
    return mesh_laplacian(mesh, positions, field(positions), field(mesh.centres(positions)))


def triangle_lattice(n: int) -> tuple[np.ndarray, list[list[int]]]:
    """Equilateral triangles filling an n × n rhombus of unit side (2 n² cells)."""
    a1, a2 = np.array([1.0, 0.0]), np.array([0.5, np.sqrt(3) / 2])
    positions = np.array([i * a1 + j * a2 for i in range(n + 1) for j in range(n + 1)])

    def index(i: int, j: int) -> int:
        return i * (n + 1) + j

    cells = []
    for i in range(n):
        for j in range(n):
            cells.append([index(i, j), index(i + 1, j), index(i, j + 1)])
            cells.append([index(i + 1, j), index(i + 1, j + 1), index(i, j + 1)])
    return positions, cells


def interior(mesh: SensorMesh) -> list[int]:
    return [j for j in range(mesh.n_cells) if all(e.neighbour is not None for e in mesh.edges(j))]


# ---------------------------------------------------------------------------------------------- mesh
def test_paper_network_topology() -> None:
    positions, cells = paper_network()
    mesh = SensorMesh(cells, positions)
    # Euler: V − E + F = 2 with 12 vertices and 9 + 1 faces gives 20 edges; 4·3 + 5·4 = 2·12 + 8
    assert len(mesh.edge_pairs) == 20 and len(mesh.boundary_edges) == 8
    assert [len(mesh.neighbours(j)) for j in range(9)] == [4, 3, 3, 3, 3, 2, 2, 2, 2]
    assert len(mesh.cell_pairs) == 20 + 5 * 2  # plus the two diagonals of each quadrilateral
    assert np.allclose(mesh.areas(positions), [900.0] + [720.0] * 4 + [288.0] * 4)
    assert np.allclose(mesh.centres(positions)[0], [0.0, 0.0])
    for j in range(9):  # neighbour relations are symmetric
        assert all(j in mesh.neighbours(n) for n in mesh.neighbours(j))


def test_clockwise_cells_are_reoriented() -> None:
    positions, cells = grid_network(2, 1)
    mesh = SensorMesh([list(reversed(c)) for c in cells], positions)
    assert np.all(mesh.areas(positions) > 0)
    assert mesh.neighbours(0) == (1,)


@pytest.mark.parametrize(
    ("cells", "message"),
    [
        ([[0, 1]], "at least 3 distinct"),
        ([[0, 1, 1, 3]], "at least 3 distinct"),
        ([[0, 1, 4, 9]], "must lie in 0..5"),
        ([[0, 1, 4, 3]], r"sensors \[2, 5\] belong to no cell"),
        ([[0, 1, 4, 3], [1, 2, 5, 4], [0, 1, 5, 3]], "overlap"),
        ([[0, 1, 2], [3, 4, 5]], "zero area"),
    ],
)
def test_invalid_meshes_are_rejected(cells: list[list[int]], message: str) -> None:
    positions = np.array([[0, 0], [1, 0], [2, 0], [0, 1], [1, 1], [2, 1]], dtype=float)
    with pytest.raises(MeshError, match=message):
        SensorMesh(cells, positions)


# ---------------------------------------------------------------------------------------------- Laplacian
@pytest.mark.parametrize("spacing", [(1.0, 1.0), (1.0, 2.5)])
def test_exact_for_quadratics_on_interior_cells_of_rectangular_grids(spacing: tuple[float, float]) -> None:
    positions, cells = grid_network(4, 3, spacing, origin=(-1.7, 0.4))
    mesh = SensorMesh(cells, positions)
    lap = laplacian_of(mesh, positions, quadratic)
    # every far point mirrors the centre in the edge midpoint: each edge flux is exact (round-off 1e-13)
    assert np.allclose(lap[interior(mesh)], np.trace(H), rtol=0, atol=1e-13)


def test_exact_for_quadratics_on_interior_cells_of_a_triangle_lattice() -> None:
    positions, cells = triangle_lattice(4)
    mesh = SensorMesh(cells, positions)
    inner = interior(mesh)
    assert len(inner) >= 8
    assert np.allclose(laplacian_of(mesh, positions, quadratic)[inner], np.trace(H), rtol=0, atol=1e-12)


def test_boundary_edges_on_squares() -> None:
    """Square of side h: a vertical boundary edge's flux errs by h²(H22 − H11)/4, a horizontal one by −that.

    So an isolated square and a grid's corner cells are exact (the errors cancel in pairs), a side cell misses
    Δz by |H11 − H22|/4, and with H11 = H22 every square cell is exact.
    """
    positions, cells = grid_network(3, 3, (2.0, 2.0))
    mesh = SensorMesh(cells, positions)
    lap = laplacian_of(mesh, positions, quadratic)
    corners = [0, 2, 6, 8]
    assert np.allclose(lap[corners], np.trace(H), rtol=0, atol=1e-13)
    side = 1  # left column, middle row: one vertical boundary edge
    assert abs(lap[side] - np.trace(H)) == pytest.approx(abs(H[1, 1] - H[0, 0]) / 4, rel=1e-12)
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float) * 3.0
    assert laplacian_of(SensorMesh([[0, 1, 2, 3]], square), square, quadratic)[0] == pytest.approx(
        np.trace(H), abs=1e-13
    )


def test_boundary_edges_are_inconsistent_on_an_isolated_equilateral_triangle() -> None:
    """The paper's boundary rule (midpoint value = mean of the vertex values) doubles Δz here, at any size.

    For z = ½|r|² about the centroid (Δz = 2): vertex mean of an edge R²/2 = 1/(6)·side², distance to the
    midpoint = inradius side/(2√3); three edges give 3·side·(side²/6)/(side/(2√3))/(√3 side²/4) = 4.
    """
    for side in (1.0, 0.01):
        tri = side * np.array([[0, 0], [1, 0], [0.5, np.sqrt(3) / 2]])
        tri -= tri.mean(axis=0)
        lap = laplacian_of(SensorMesh([[0, 1, 2]], tri), tri, lambda p: 0.5 * np.sum(p**2, axis=-1))
        assert lap[0] == pytest.approx(4.0, rel=1e-12)


def test_exact_for_linear_fields_on_any_cell() -> None:
    rng = np.random.default_rng(5)
    positions, cells = paper_network(30.0, 24.0)
    positions = positions + rng.uniform(-4, 4, size=positions.shape)  # irregular, still a valid mesh
    mesh = SensorMesh(cells, positions)
    lap = laplacian_of(mesh, positions, lambda p: p @ np.array([0.7, -1.9]) + 4.0)
    assert np.allclose(lap, 0.0, rtol=0, atol=1e-14)  # every step of eqs. 21-24 is exact for linear z


def test_converges_on_smoothly_distorted_cells() -> None:
    """Irregular quadrilaterals (a smooth warp of a grid): the error of interior cells falls at about h²."""

    def warp(p: np.ndarray) -> np.ndarray:
        x, y = p[:, 0], p[:, 1]
        return np.stack(
            [x + 0.15 * np.sin(1.3 * y) + 0.1 * x * y, y + 0.12 * np.sin(1.7 * x + 0.5) + 0.05 * x**2], 1
        )

    def z(p: np.ndarray) -> np.ndarray:
        return np.sin(1.1 * p[..., 0] + 0.3) * np.cos(0.7 * p[..., 1]) + 0.2 * p[..., 0] ** 2 * p[..., 1]

    def exact(p: np.ndarray) -> np.ndarray:
        return -(1.1**2 + 0.7**2) * np.sin(1.1 * p[..., 0] + 0.3) * np.cos(0.7 * p[..., 1]) + 0.4 * p[..., 1]

    errors = []
    for n in (8, 16, 32):
        grid, cells = grid_network(n, n, (1.0 / n, 1.0 / n))
        positions = warp(grid)
        mesh = SensorMesh(cells, positions)
        inner = interior(mesh)
        errors.append(
            np.max(np.abs(laplacian_of(mesh, positions, z) - exact(mesh.centres(positions)))[inner])
        )
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    # measured orders 1.70, 1.87 (→ 2): the centre line misses the edge midpoint by O(h²) on a smooth warp
    assert np.all(orders > 1.6), orders
    assert errors[-1] < 2e-4


# ---------------------------------------------------------------------------------------------- constraint
def test_constraint_holds_for_an_exact_solution_on_a_square_grid() -> None:
    """z = q(r + v t) + θ tr(H) t solves the PDE; with H11 = H22 and v'Hv = 0 eqs. 20-27 are exact."""
    theta, v, dt = 2.0, np.array([0.5, 1.0]), 1.0
    hess = np.array([[1.0, -1.25], [-1.25, 1.0]]) * 1e-3  # v'Hv = 1.25·1e-3 − 2·0.5·1.25·1e-3 = 0

    def z(p: np.ndarray, t: float) -> np.ndarray:
        s = p + v * t
        return 0.5 * np.einsum("...i,ij,...j->...", s, hess, s) + s @ G0 + theta * np.trace(hess) * t

    positions, cells = grid_network(3, 3, (20.0, 20.0), origin=(5.0, -7.0))
    mesh = SensorMesh(cells, positions)
    centres, t = mesh.centres(positions), 3.0
    for j, cell in enumerate(mesh.cells):
        across = [
            None if e.neighbour is None else (centres[e.neighbour], z(centres[e.neighbour], t))
            for e in mesh.edges(j)
        ]
        vertices = positions[list(cell)]
        points, values = far_points(vertices, z(vertices, t), across)
        stencil = laplacian_stencil(vertices, centres[j], points)
        G, g = pde_constraint(stencil, z(vertices, t), values, dt, theta, v)
        c = centres[j]
        x = np.concatenate(
            [[z(c, t)], hess @ (c + v * t) + G0, [z(c, t + dt)], hess @ (c + v * (t + dt)) + G0]
        )
        assert G @ x == pytest.approx(g, abs=1e-12)  # values ~10: 1e-12 is round-off


@pytest.mark.parametrize("with_metric", [False, True])
def test_projection_satisfies_the_constraint_and_minimises_the_metric(with_metric: bool) -> None:
    rng = np.random.default_rng(6)
    G, g = rng.normal(size=6), 0.7
    x = rng.normal(size=(5, 6))
    L = rng.normal(size=(6, 6))
    metric = L @ L.T + 0.1 * np.eye(6) if with_metric else None
    projected = project(x, G, g, metric)
    assert np.allclose(projected @ G, g, rtol=0, atol=1e-14)
    assert np.allclose(project(projected, G, g, metric), projected, atol=1e-14)  # idempotent
    # independent: the KKT system of min (x̃ − x)' M⁻¹ (x̃ − x) subject to G x̃ = g
    M_inv = np.eye(6) if metric is None else np.linalg.inv(metric)
    kkt = np.block([[2 * M_inv, G[:, None]], [G[None, :], np.zeros((1, 1))]])
    for xi, pi in zip(x, projected, strict=True):
        solution = np.linalg.solve(kkt, np.concatenate([2 * M_inv @ xi, [g]]))
        assert np.allclose(pi, solution[:6], atol=1e-12)


def test_stencil_rejects_a_folded_cell() -> None:
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    with pytest.raises(MeshError, match="area"):
        laplacian_stencil(square[::-1], square.mean(axis=0), square)
    far = far_points(square, np.zeros(4), [None] * 4)[0]
    far[1] = [0.2, 0.5]  # a "neighbour centre" on the wrong side of edge 1
    with pytest.raises(MeshError, match="edge 1"):
        laplacian_stencil(square, square.mean(axis=0), far)
