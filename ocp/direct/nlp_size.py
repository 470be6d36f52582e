"""Sizes of the direct-collocation NLP, computed from the problem's structure without building it.

Used by the pre-flight budget (:mod:`mobisense.ocp.sizes`) to refuse a problem too large for the machine before
anything is allocated; tested against the sizes CasADi reports for the built NLP.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..collocation import HULL_ELEVATION
from ..model import Structure

__all__ = ["TranscriptionSize", "transcription_size", "path_rows_size"]


@dataclass(frozen=True)
class TranscriptionSize:
    """Sizes of the NLP :class:`DirectCollocation` would build, computed without building it.

    ``variables`` and ``constraints`` are exact; ``jacobian_nnz`` and ``hessian_nnz`` (lower triangle of the
    Lagrangian Hessian) count the structural non-zeros of one collocation node times the nodes, and
    ``expression_nodes`` the SX nodes of the expanded NLP plus its Jacobian and Hessian functions, fitted to
    CasADi's counts for n = 1…10 states, N = 1…32 sensors, d = 3…9 (within −27 % … +30 %, mostly +10 %).
    """

    variables: int
    constraints: int
    jacobian_nnz: int
    hessian_nnz: int
    expression_nodes: int


def transcription_size(structure: Structure, degree: int, intervals: int, scheme: str = "radau") -> TranscriptionSize:
    """The :class:`TranscriptionSize` of the transcription of ``structure`` on ``intervals`` intervals of ``degree``.

    The layout is the eliminated one of docs/theory/direct.md §1.7 (eq. direct.2): per interval σ and u at the
    d nodes plus what the interval hands on — the sensors' (p, v) at its end with Radau, the whole state with
    Legendre (no node at τ = 1).
    """
    s, d, K = structure, degree, intervals
    n, N, nx, nu, ns = s.n, s.N, s.nx, s.nu, s.n_sigma
    nodes = K * d
    bounded = sum(s.bounded_control)
    terminal = 2 * (sum(s.fixed_position) + sum(s.fixed_velocity))
    handed_on = 4 * N if scheme == "radau" else nx
    variables = K * (d * ns + d * nu + handed_on)
    hull = d + HULL_ELEVATION  # bound rows per bounded sensor and interval (Bernstein coefficients of its control)
    constraints = K * (handed_on + d * ns + hull * bounded) + terminal
    # the sensors are condensed (eq. direct.11): a position at a node is a function of the interval's handed-on
    # (p, v) and all d controls, m = 4 + 2d values per sensor. A covariance residual depends on its entry at the
    # d + 1 values of the interval, a row and a column of Σ, and those m values of every sensor; a handed-on row on
    # its d + 1 values and its own variable (+ one for the velocity coupling); a bound row on the sensor's d controls
    m = 4 + 2 * d
    jacobian = (
        nodes * ns * (d + 1 + 2 * n + N * m) + K * handed_on * (d + 3) + K * hull * bounded * 2 * d + 2 * terminal
    )
    # Σ S(p) Σ couples the covariance entries of a node; each sensor's m values couple with each other and with
    # every covariance entry at the d nodes (lower triangle)
    hessian = K * (N * (m * (m + 1) // 2 + d * ns * m) + d * ns * (ns + 1) // 2)
    expression = nodes * (30 + 4 * d * nx + (180 * n**2 + 60) * N + 12 * n**3 + 24 * ns**2)
    rows, row_jacobian, pairs, row_nodes = path_rows_size(structure.path, N, m)
    constraints += nodes * rows
    jacobian += nodes * row_jacobian
    hessian += K * pairs * (m * m // 2)  # a separation row couples two sensors' m values (cross block, measured)
    expression += nodes * row_nodes
    return TranscriptionSize(variables, constraints, jacobian, hessian, expression)


def path_rows_size(path: tuple[tuple[Any, ...], ...], N: int, m: int) -> tuple[int, int, int, int]:
    """Per collocation node: path-constraint rows, their Jacobian non-zeros, sensor pairs they couple, SX nodes.

    Rows by group (:func:`~mobisense.ocp.path_constraints.path_rows`): a disc, a polygon and the speed limit one per
    sensor, the workspace four, the separation one per pair. A row depends on its sensor's ``m`` condensed values
    (a workspace row on half: one coordinate), a separation row on two sensors'. A sensor's own rows add no
    Hessian entries beyond its block; a separation row adds the pair's cross block (half of it non-zero,
    measured). SX nodes (the row with its Jacobian and Hessian): 20 for a disc, a separation or a speed row, 10 for
    a workspace row, 10 + 10 per vertex for a polygon's smoothed maximum over its edges — an upper fit, as the rest
    of the count: 20 discs or 10 polygons of 32 vertices on 4 sensors at K = 20 built in +7 and +107 MB over the
    unconstrained NLP, estimated +33 and +280 MB; 190 separation pairs at K = 20 are counted exactly in rows and
    within 3 % in non-zeros (``tests/core/test_budget_and_output.py``).
    """
    rows = jacobian = pairs = sx = 0
    for item in path:
        kind = item[0]
        if kind == "min_separation":
            count = N * (N - 1) // 2
            rows, jacobian, pairs, sx = rows + count, jacobian + 2 * m * count, pairs + count, sx + 20 * count
        elif kind == "workspace":
            rows, jacobian, sx = rows + 4 * N, jacobian + 2 * m * N, sx + 40 * N
        else:  # disc, polygon (item[1] vertices), max_speed: one row per sensor
            rows, jacobian, sx = rows + N, jacobian + m * N, sx + N * (10 + 10 * item[1] if kind == "polygon" else 20)
    return rows, jacobian, pairs, sx
