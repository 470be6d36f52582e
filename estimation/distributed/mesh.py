"""Sensor networks in cells (docs/theory/distributed.md §2): polygons of sensors, shared edges, neighbours, boundary.

A :class:`SensorMesh` is the fixed communication graph of Assumption 2.1: cell ``j`` is a polygon whose
vertices are the sensors listed in ``cells[j]``; two cells are neighbours when they share an edge
(Definition 2.4); an edge used by one cell only lies on the boundary ∂Ω_r of the network. The geometry
(centres, areas) moves with the sensors and is evaluated from positions on demand, vectorised over
cells (positions have shape ``(..., N, 2)``, length unit L).

Vertices are stored counter-clockwise (a clockwise input is reversed), so edge ``s`` of a cell runs from
vertex ``s`` to vertex ``s + 1`` with the cell on its left and the outward normal on its right.

Example
-------
>>> import numpy as np
>>> from mobisense.estimation.distributed.mesh import SensorMesh
>>> square = np.array([[0, 0], [1, 0], [2, 0], [0, 1], [1, 1], [2, 1]], dtype=float)
>>> mesh = SensorMesh([[0, 1, 4, 3], [1, 2, 5, 4]], square)
>>> mesh.neighbours(0), mesh.edges(0)[1]
((1,), CellEdge(start=1, end=4, neighbour=1))
>>> mesh.centres(square)
array([[0.5, 0.5],
       [1.5, 0.5]])
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

__all__ = ["CellEdge", "MeshError", "SensorMesh", "following", "polygon_area", "grid_network", "paper_network"]


class MeshError(ValueError):
    """The cells do not form a valid mesh (too few sensors, an edge in three cells, overlapping cells…)."""


@dataclass(frozen=True)
class CellEdge:
    """Edge of a cell from sensor ``start`` to sensor ``end`` (counter-clockwise around the cell).

    ``neighbour`` is the cell sharing the edge, ``None`` on the network boundary.
    """

    start: int
    end: int
    neighbour: int | None


@lru_cache(maxsize=64)
def _successors(n: int) -> np.ndarray:
    return np.arange(1, n + 1) % n


def following(values: np.ndarray, axis: int = 0) -> np.ndarray:
    """``values`` shifted cyclically by one along ``axis``: entry s holds entry s + 1 (edge s's end)."""
    return np.take(values, _successors(values.shape[axis]), axis=axis)


def polygon_area(vertices: np.ndarray) -> np.ndarray:
    """Signed area of polygons by the shoelace formula (> 0 counter-clockwise).

    Parameters
    ----------
    vertices : ndarray, shape (..., n, 2)
        Vertices in order (L).

    Returns
    -------
    ndarray, shape (...)
        Signed area (L²).
    """
    x, y = vertices[..., 0], vertices[..., 1]
    return 0.5 * np.sum(x * following(y, -1) - following(x, -1) * y, axis=-1)


class SensorMesh:
    """Cells of sensors with their shared edges, neighbour relations and boundary edges.

    Parameters
    ----------
    cells : sequence of sequences of int
        ``cells[j]`` lists the sensor indices (0-based) at the vertices of cell ``j`` in polygon order
        (either orientation); at least 3 distinct sensors per cell.
    positions : ndarray, shape (N, 2)
        Sensor positions (L) used to orient the cells and to check the mesh: every cell must have
        non-zero area (Assumption 2.2), every edge belongs to at most two cells traversed in opposite
        directions (no overlap, Assumption 2.3), and every sensor belongs to a cell.

    Raises
    ------
    MeshError
        Naming the offending cell or edge.
    """

    def __init__(self, cells: Sequence[Sequence[int]], positions: np.ndarray) -> None:
        positions = np.asarray(positions, dtype=float)
        if positions.ndim != 2 or positions.shape[1] != 2:
            raise MeshError(f"positions: expected shape (N, 2), got {positions.shape}")
        n_sensors = positions.shape[0]
        oriented = []
        for j, cell in enumerate(cells):
            cell = [int(i) for i in cell]
            if len(cell) < 3 or len(set(cell)) != len(cell):
                raise MeshError(f"cell {j}: expected at least 3 distinct sensors, got {cell}")
            if min(cell) < 0 or max(cell) >= n_sensors:
                raise MeshError(f"cell {j}: sensor indices must lie in 0..{n_sensors - 1}, got {cell}")
            area = float(polygon_area(positions[cell]))
            if area == 0.0:
                raise MeshError(f"cell {j}: sensors {cell} enclose zero area")
            oriented.append(tuple(cell) if area > 0 else tuple(reversed(cell)))
        self.cells: tuple[tuple[int, ...], ...] = tuple(oriented)
        self.n_sensors = n_sensors
        self.n_cells = len(self.cells)
        unused = sorted(set(range(n_sensors)) - {i for cell in self.cells for i in cell})
        if unused:
            raise MeshError(f"sensors {unused} belong to no cell")
        self._edges = self._link_edges()
        #: membership matrix M[i, j] = 1 if sensor i is a vertex of cell j, shape (N, n_cells)
        self.membership = np.zeros((n_sensors, self.n_cells))
        for j, cell in enumerate(self.cells):
            self.membership[list(cell), j] = 1.0

    def _link_edges(self) -> tuple[tuple[CellEdge, ...], ...]:
        owner: dict[tuple[int, int], int] = {}
        for j, cell in enumerate(self.cells):
            for start, end in zip(cell, cell[1:] + cell[:1], strict=True):
                if (start, end) in owner:
                    raise MeshError(
                        f"cells {owner[(start, end)]} and {j} both run along edge {start}->{end} in the same "
                        "direction: they overlap"
                    )
                owner[(start, end)] = j
        for (start, end), j in owner.items():
            if (end, start) in owner and owner[(end, start)] == j:
                raise MeshError(f"cell {j} runs along edge {start}-{end} twice")
        return tuple(
            tuple(
                CellEdge(start, end, owner.get((end, start)))
                for start, end in zip(cell, cell[1:] + cell[:1], strict=True)
            )
            for cell in self.cells
        )

    def edges(self, cell: int) -> tuple[CellEdge, ...]:
        """Edges of ``cell`` counter-clockwise; edge ``s`` joins vertex ``s`` to vertex ``s + 1``."""
        return self._edges[cell]

    def neighbours(self, cell: int) -> tuple[int, ...]:
        """Cells sharing an edge with ``cell`` (Definition 2.4), in edge order."""
        return tuple(e.neighbour for e in self._edges[cell] if e.neighbour is not None)

    @property
    def edge_pairs(self) -> np.ndarray:
        """Every distinct mesh edge ``(i, i')`` with ``i < i'``, shape (E, 2)."""
        pairs = {tuple(sorted((e.start, e.end))) for cell_edges in self._edges for e in cell_edges}
        return np.array(sorted(pairs), dtype=int).reshape(-1, 2)

    @property
    def cell_pairs(self) -> np.ndarray:
        """Every distinct pair of sensors sharing a cell (intra-cell links, diagonals included), (L, 2)."""
        pairs = {(min(a, b), max(a, b)) for cell in self.cells for a in cell for b in cell if a != b}
        return np.array(sorted(pairs), dtype=int).reshape(-1, 2)

    @property
    def boundary_edges(self) -> list[tuple[int, int]]:
        """Edges ``(start, end)`` on the network boundary ∂Ω_r, counter-clockwise around their cell."""
        return [(e.start, e.end) for cell_edges in self._edges for e in cell_edges if e.neighbour is None]

    def centres(self, positions: np.ndarray) -> np.ndarray:
        """Cell centres ``r_c = mean of the cell's sensors`` (Zhang et al. (2023), §2.1), shape ``(..., n_cells, 2)``.

        Parameters
        ----------
        positions : ndarray, shape (..., N, 2)
            Sensor positions (L).
        """
        counts = self.membership.sum(axis=0)
        return (
            np.einsum("ij,...id->...jd", self.membership, np.asarray(positions, dtype=float))
            / counts[:, None]
        )

    def areas(self, positions: np.ndarray) -> np.ndarray:
        """Signed cell areas A(C_j) (L²), shape ``(..., n_cells)``; negative means a cell has folded over."""
        positions = np.asarray(positions, dtype=float)
        return np.stack([polygon_area(positions[..., list(cell), :]) for cell in self.cells], axis=-1)

    def __repr__(self) -> str:
        return f"SensorMesh(n_sensors={self.n_sensors}, cells={[list(c) for c in self.cells]})"


def grid_network(
    nx: int, ny: int, spacing: tuple[float, float] = (1.0, 1.0), origin: tuple[float, float] = (0.0, 0.0)
) -> tuple[np.ndarray, list[list[int]]]:
    """Sensors on a regular ``(nx + 1) × (ny + 1)`` lattice forming ``nx × ny`` rectangular cells.

    Parameters
    ----------
    nx, ny : int
        Number of cells along x and y.
    spacing : (float, float)
        Cell width and height (L).
    origin : (float, float)
        Position of sensor 0, the lower-left corner (L).

    Returns
    -------
    positions : ndarray, shape ((nx + 1)(ny + 1), 2)
        Sensor ``i (ny + 1) + j`` sits at ``origin + (i dx, j dy)``.
    cells : list of list of int
        Cell ``i ny + j`` is ``[(i, j), (i+1, j), (i+1, j+1), (i, j+1)]``, counter-clockwise.
    """
    xs = origin[0] + spacing[0] * np.arange(nx + 1)
    ys = origin[1] + spacing[1] * np.arange(ny + 1)
    positions = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)

    def index(i: int, j: int) -> int:
        return i * (ny + 1) + j

    cells = [
        [index(i, j), index(i + 1, j), index(i + 1, j + 1), index(i, j + 1)]
        for i in range(nx)
        for j in range(ny)
    ]
    return positions, cells


def paper_network(
    square: float = 30.0, depth: float = 24.0, origin: tuple[float, float] = (0.0, 0.0)
) -> tuple[np.ndarray, list[list[int]]]:
    """The 12-sensor, 9-cell network of Zhang et al. (2023), §8, Fig. 4A: a square, 4 rectangles, 4 corner triangles.

    Parameters
    ----------
    square : float
        Side of the central square cell 0 (L).
    depth : float
        Depth of the rectangles 1-4 on its sides, i.e. the legs of the right triangles 5-8 (L).
    origin : (float, float)
        Centre of the network (L).

    Returns
    -------
    positions : ndarray, shape (12, 2)
        Sensors 0-3 are the square's corners (counter-clockwise from lower left), 4-11 the outer ring.
    cells : list of list of int
        Counter-clockwise; 20 edges of which 8 lie on the boundary.
    """
    h, w = 0.5 * square, depth
    corners = [(-h, -h), (h, -h), (h, h), (-h, h)]
    ring = [
        (-h, -h - w),
        (h, -h - w),
        (h + w, -h),
        (h + w, h),
        (h, h + w),
        (-h, h + w),
        (-h - w, h),
        (-h - w, -h),
    ]
    positions = np.asarray(corners + ring, dtype=float) + np.asarray(origin, dtype=float)
    cells = [
        [0, 1, 2, 3],
        [4, 5, 1, 0],
        [1, 6, 7, 2],
        [3, 2, 8, 9],
        [11, 0, 3, 10],
        [1, 5, 6],
        [2, 7, 8],
        [3, 9, 10],
        [0, 11, 4],
    ]
    return positions, cells
