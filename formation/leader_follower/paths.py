"""Path geometry for leader–follower path following (docs/theory/leader_follower.md §4.3, §5).

Source: Karasalo & Hu (2010), §8.3, Fig. 13 and eq. 54.

* :func:`chord_window` — the furthest point back on a recorded path whose chord to the path's end keeps the
  area between path and chord (the tinted area of the paper's Fig. 13) below a tolerance; it defines the
  dynamic formation parameters of :class:`~mobisense.formation.leader_follower.references.PathReference`.
* :func:`path_deviation` — the deviation of a follower from the path its predecessor has travelled (eq. 54).

Paths are arrays ``(m, 2)`` of positions (m), oldest first.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ChordPoint", "enclosed_areas", "chord_window", "path_deviation"]


@dataclass(frozen=True)
class ChordPoint:
    """A point on a recorded path, seen from the path's end.

    Attributes
    ----------
    point : ndarray, shape (2,)
        Position on the path (m).
    chord : float
        Distance from ``point`` to the path's end (m).
    area : float
        Area between the path and the chord (m²).
    tangent_heading : float
        Direction of travel of the path at ``point`` (rad).
    chord_heading : float
        Direction from ``point`` to the path's end (rad).
    """

    point: np.ndarray
    chord: float
    area: float
    tangent_heading: float
    chord_heading: float


def enclosed_areas(path: np.ndarray) -> np.ndarray:
    """Area between the path and the chord from each of its points to its end.

    Parameters
    ----------
    path : ndarray, shape (m, 2)
        Positions (m), oldest first.

    Returns
    -------
    ndarray, shape (m,)
        ``A_j`` (m²): absolute area of the polygon ``P_j, P_{j+1}, …, P_m`` closed by the chord ``P_m → P_j``.

    Notes
    -----
    Shoelace formula in coordinates relative to the end point ``Q = P − P_m`` (translation invariant and
    better conditioned); the closing edge and the last edge then contribute nothing::

        2 A_j = | Σ_{k=j}^{m−2} Q_k × Q_{k+1} |
    """
    q = np.asarray(path, dtype=float) - np.asarray(path, dtype=float)[-1]
    cross = q[:-1, 0] * q[1:, 1] - q[:-1, 1] * q[1:, 0]
    tail_sums = np.concatenate([np.cumsum(cross[::-1])[::-1], [0.0]])
    return 0.5 * np.abs(tail_sums)


def chord_window(path: np.ndarray, max_area: float, max_chord: float) -> ChordPoint | None:
    """Furthest point back on ``path`` with enclosed area ≤ ``max_area`` and chord ≤ ``max_chord``.

    Walking back from the end, the window stops at the first sample violating either bound; the returned
    point is interpolated on the segment that crosses the bound, so it moves continuously as the path grows.

    Parameters
    ----------
    path : ndarray, shape (m, 2)
        Positions (m), oldest first.
    max_area : float
        Tolerance ``A_max`` on the enclosed area (m²).
    max_chord : float
        Upper bound on the chord (m).

    Returns
    -------
    ChordPoint or None
        ``None`` if the path has fewer than two distinct points.
    """
    path = np.asarray(path, dtype=float)
    if len(path) < 2:
        return None
    q = path - path[-1]
    areas = enclosed_areas(path)
    chords = np.hypot(q[:, 0], q[:, 1])
    violating = np.flatnonzero((areas > max_area) | (chords > max_chord))
    first = int(violating[-1]) + 1 if violating.size else 0  # furthest-back admissible sample
    if first >= len(path) - 1:
        # the very last segment already violates a bound: interpolate on it
        first = len(path) - 1
    q_in = q[first]
    fraction = 0.0
    if first > 0:
        step = q[first - 1] - q_in  # towards the older, violating sample
        # area grows linearly along the segment: 2 A(s) = 2 A_first ± s (step × q_in)
        signed_twice = float(np.sum(q[first:-1, 0] * q[first + 1 :, 1] - q[first:-1, 1] * q[first + 1 :, 0]))
        slope = float(step[0] * q_in[1] - step[1] * q_in[0])
        fraction = min(1.0, _largest_admissible_linear(signed_twice, slope, 2.0 * max_area))
        # chord: |q_in + s step|² ≤ max_chord² (convex in s, admissible at s = 0)
        fraction = min(fraction, _largest_admissible_quadratic(q_in, step, max_chord))
        point_rel = q_in + fraction * step
        # tangent interpolated between the vertex tangents, so it turns continuously as the point moves
        tangent = (1.0 - fraction) * _vertex_tangent(q, first) + fraction * _vertex_tangent(q, first - 1)
    else:
        point_rel = q_in
        tangent = _vertex_tangent(q, 0)
    if np.hypot(*tangent) == 0.0 or np.hypot(*point_rel) == 0.0:
        return None
    chord_vec = -point_rel
    area = 0.5 * abs(
        float(np.sum(q[first:-1, 0] * q[first + 1 :, 1] - q[first:-1, 1] * q[first + 1 :, 0]))
        + float(point_rel[0] * q_in[1] - point_rel[1] * q_in[0])
    )
    return ChordPoint(
        point=point_rel + path[-1],
        chord=float(np.hypot(*chord_vec)),
        area=area,
        tangent_heading=float(np.arctan2(tangent[1], tangent[0])),
        chord_heading=float(np.arctan2(chord_vec[1], chord_vec[0])),
    )


def _vertex_tangent(q: np.ndarray, k: int) -> np.ndarray:
    """Unit direction of travel at sample ``k``: mean of the unit directions of its two segments."""
    total = np.zeros(2)
    for a, b in ((k - 1, k), (k, k + 1)):
        if 0 <= a and b < len(q):
            seg = q[b] - q[a]
            length = np.hypot(*seg)
            if length > 0:
                total += seg / length
    norm = np.hypot(*total)
    return total / norm if norm > 0 else total


def _largest_admissible_linear(value0: float, slope: float, bound: float) -> float:
    """Largest s ≥ 0 with |value0 + s slope| ≤ bound (given |value0| ≤ bound); ``inf`` if unbounded."""
    if slope > 0:
        return (bound - value0) / slope
    if slope < 0:
        return (-bound - value0) / slope
    return np.inf


def _largest_admissible_quadratic(q: np.ndarray, step: np.ndarray, bound: float) -> float:
    """Largest s ≥ 0 with |q + s step| ≤ bound (given |q| ≤ bound); ``inf`` if ``step`` is zero."""
    a = float(step @ step)
    if a == 0.0:
        return np.inf
    b = float(q @ step)
    c = float(q @ q) - bound**2
    return (-b + np.sqrt(max(b * b - a * c, 0.0))) / a


def path_deviation(predecessor: np.ndarray, follower: np.ndarray) -> np.ndarray:
    """Deviation of a follower from its predecessor's travelled path (eq. leader_follower.15).

    Source: Karasalo & Hu (2010), eq. 54.

    Parameters
    ----------
    predecessor, follower : ndarray, shape (N, 2)
        Positions (m) at the same N sample times.

    Returns
    -------
    ndarray, shape (N,)
        ``dev(t_k) = min_{τ ≤ t_k} ‖R_{i−1}(τ) − R_i(t_k)‖`` (m), with the predecessor's path between samples
        taken as the straight segments joining them (a finer reading of the minimum than over samples only).
    """
    predecessor = np.asarray(predecessor, dtype=float)
    follower = np.asarray(follower, dtype=float)
    start = predecessor[:-1]
    seg = predecessor[1:] - predecessor[:-1]
    seg_len2 = np.einsum("ij,ij->i", seg, seg)
    out = np.empty(len(follower))
    out[0] = np.hypot(*(follower[0] - predecessor[0]))
    for k in range(1, len(follower)):
        rel = follower[k] - start[:k]
        s = np.einsum("ij,ij->i", rel, seg[:k])
        s = np.clip(np.divide(s, seg_len2[:k], out=np.zeros_like(s), where=seg_len2[:k] > 0), 0.0, 1.0)
        gap = rel - s[:, None] * seg[:k]
        out[k] = np.sqrt(np.min(np.einsum("ij,ij->i", gap, gap)))
    return out
