"""Path constraints of the sensors: keep-out zones, separation, speed, workspace (docs/theory/path_constraints.md).

The ``constraints`` section of a problem file::

    constraints:
      keep_out: [{center: [x, y], radius: r}, {polygon: [[x, y], ...]}]   # discs and convex polygons
      min_separation: 1.0      # |p_i − p_j| ≥ d_min for every pair of sensors (L)
      max_speed: 2.0           # |v_i| ≤ v_max (L/T)
      workspace: {x: [xmin, xmax], y: [ymin, ymax]}

Every number is an NLP parameter (blocks ``keepout_k``, ``min_separation``, ``max_speed``, ``workspace``);
the structure (which constraints, how many vertices) is part of :class:`~mobisense.ocp.model.Structure`.
:func:`path_rows` gives the scaled rows ``g ≤ 0`` of one collocation node (eq. path.1–path.5), enforced by
the direct method at every collocation node; :func:`margins` the exact physical margins (numpy) used to
check the re-simulated path between the nodes (:mod:`mobisense.ocp.direct.path_report`).
"""

from __future__ import annotations

import sys
from typing import Annotated, Any

import numpy as np
from pydantic import Discriminator, Field, Tag, model_validator

from ..core.config import FiniteFloat, InvalidValue, PositiveFloat, StrictModel, Vector2
from ..core.errors import brief

__all__ = [
    "KeepOutDisc",
    "KeepOutPolygon",
    "Workspace",
    "PathConstraints",
    "POLYGON_MARGIN",
    "MAX_KEEP_OUT",
    "MAX_POLYGON_VERTICES",
    "path_structure",
    "path_parameter_blocks",
    "path_parameter_values",
    "path_rows",
    "margins",
    "constraint_sizes",
    "polygon_scale_outside",
    "group_names",
    "check_initial_state",
    "check_terminal_states",
]

#: the smooth outside-of-polygon row is conservative by at most this fraction of √area (eq. path.2)
POLYGON_MARGIN = 0.02
#: most keep-out zones and polygon vertices a problem may have: each zone adds a row per sensor at every
#: collocation node, each vertex terms to its row (2000 discs at K = 20 built for minutes before Ctrl-C could act)
MAX_KEEP_OUT = 100
MAX_POLYGON_VERTICES = 64


class KeepOutDisc(StrictModel):
    """A disc the sensors must stay out of: ``|p − c| ≥ r``."""

    center: Vector2
    radius: PositiveFloat


class KeepOutPolygon(StrictModel):
    """A convex polygon (vertices in order, either orientation) the sensors must stay out of."""

    polygon: list[Vector2] = Field(json_schema_extra={"minItems": 3})  # checked in _convex, with its message

    @model_validator(mode="after")
    def _convex(self) -> KeepOutPolygon:
        if len(self.polygon) < 3:
            raise InvalidValue("polygon", f"expected at least 3 vertices, got {len(self.polygon)}")
        V = np.asarray(self.polygon, float)
        e = np.roll(V, -1, axis=0) - V
        cross = e[:, 0] * np.roll(e, -1, axis=0)[:, 1] - e[:, 1] * np.roll(e, -1, axis=0)[:, 0]
        if np.any(np.abs(cross) <= 1e-12 * max(1.0, float(np.abs(V).max()) ** 2)) or not (
            np.all(cross > 0) or np.all(cross < 0)
        ):
            raise InvalidValue(
                "polygon", f"expected the vertices of a strictly convex polygon in order, got {self.polygon}"
            )
        return self

    @property
    def orientation(self) -> int:
        """+1 counter-clockwise, −1 clockwise."""
        return 1 if self._signed_area() > 0 else -1

    @property
    def area(self) -> float:
        """The polygon's area (L²)."""
        return abs(self._signed_area())

    def _signed_area(self) -> float:
        """The shoelace formula: positive counter-clockwise."""
        V = np.asarray(self.polygon, float)
        return 0.5 * float(np.sum(V[:, 0] * np.roll(V[:, 1], -1) - np.roll(V[:, 0], -1) * V[:, 1]))


class Workspace(StrictModel):
    """The rectangle the sensors must stay in (L)."""

    x: list[FiniteFloat] = Field(min_length=2, max_length=2)
    y: list[FiniteFloat] = Field(min_length=2, max_length=2)

    @model_validator(mode="after")
    def _ordered(self) -> Workspace:
        for name in ("x", "y"):
            lo, hi = getattr(self, name)
            if not hi > lo:
                raise InvalidValue(name, f"expected [min, max] with max > min, got [{lo:g}, {hi:g}]")
        return self


def _zone_kind(value: Any) -> str:
    """Which kind of zone an entry of ``keep_out`` is: a polygon when it has ``polygon``, else a disc.

    Told by its keys, so that a bad polygon is reported as a polygon (not as a disc missing ``center``).
    """
    if isinstance(value, dict):
        return "polygon" if "polygon" in value else "disc"
    return "polygon" if isinstance(value, KeepOutPolygon) else "disc"


#: a zone of ``keep_out``: a disc or a convex polygon
KeepOutZone = Annotated[
    Annotated[KeepOutDisc, Tag("disc")] | Annotated[KeepOutPolygon, Tag("polygon")], Discriminator(_zone_kind)
]


class PathConstraints(StrictModel):
    """Constraints on the sensors' paths, enforced at every collocation node (direct method only)."""

    keep_out: list[KeepOutZone] = Field(default_factory=list)
    min_separation: PositiveFloat | None = Field(None, description="smallest distance between two sensors (L)")
    max_speed: PositiveFloat | None = Field(None, description="largest sensor speed |v_i| (L/T)")
    workspace: Workspace | None = None

    @model_validator(mode="before")
    @classmethod
    def _zone_shapes(cls, data: Any) -> Any:
        """Each zone is a mapping of a disc's keys or a polygon's, not both and nothing else."""
        zones = data.get("keep_out") if isinstance(data, dict) else None
        if isinstance(zones, list) and len(zones) > MAX_KEEP_OUT:
            raise InvalidValue("keep_out", f"expected at most {MAX_KEEP_OUT} zones (each adds a row per sensor at "
                               f"every collocation node), got {len(zones)}")  # fmt: skip
        seen: dict[str, int] = {}
        for k, zone in enumerate(zones if isinstance(zones, list) else []):
            expected = "a disc {center: [x, y], radius: r} or a convex polygon {polygon: [[x, y], …]}"
            if isinstance(zone, dict):
                key = repr(sorted(_as_floats(zone).items()))  # radius 2 repeats radius 2.0
                if key in seen:  # its rows would duplicate another's: a degenerate NLP (Ipopt stalls on it)
                    raise InvalidValue(f"keep_out[{k}]", f"repeats keep_out[{seen[key]}]; give each zone once")
                seen[key] = k
            if not isinstance(zone, dict):
                raise InvalidValue(f"keep_out[{k}]", f"expected {expected}, got {brief(zone)}")
            if "polygon" in zone and ({"center", "radius"} & set(zone)):
                raise InvalidValue(f"keep_out[{k}]", f"expected {expected}, got both kinds' keys: {sorted(zone)}")
            polygon = zone.get("polygon")
            if isinstance(polygon, list) and len(polygon) > MAX_POLYGON_VERTICES:
                raise InvalidValue(f"keep_out[{k}].polygon", f"expected at most {MAX_POLYGON_VERTICES} vertices, "
                                   f"got {len(polygon)}")  # fmt: skip
        return data


def _as_floats(value: Any) -> Any:
    """``value`` with its integers (not booleans) as floats, in nested lists and mappings."""
    if isinstance(value, dict):
        return {k: _as_floats(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_as_floats(v) for v in value]
    return float(value) if isinstance(value, int) and not isinstance(value, bool) else value


# ---------------------------------------------------------------------- structure and parameters
def path_structure(constraints: PathConstraints | None, n_sensors: int) -> tuple[tuple[Any, ...], ...]:
    """The hashable shape of the constraints: ``("disc",)``, ``("polygon", m, ±1)``, ``("max_speed",)``, ...."""
    if constraints is None:
        return ()
    out: list[tuple[Any, ...]] = []
    for zone in constraints.keep_out:
        out.append(("disc",) if isinstance(zone, KeepOutDisc) else ("polygon", len(zone.polygon), zone.orientation))
    if constraints.min_separation is not None and n_sensors > 1:
        out.append(("min_separation",))
    if constraints.max_speed is not None:
        out.append(("max_speed",))
    if constraints.workspace is not None:
        out.append(("workspace",))
    return tuple(out)


def group_names(structure: tuple[tuple[Any, ...], ...]) -> list[str]:
    """The name of each constraint group: ``keep_out[k]``, ``min_separation``, ``max_speed``, ``workspace``."""
    names, k = [], 0
    for item in structure:
        if item[0] in ("disc", "polygon"):
            names.append(f"keep_out[{k}]")
            k += 1
        else:
            names.append(item[0])
    return names


def path_parameter_blocks(structure: tuple[tuple[Any, ...], ...]) -> list[tuple[str, tuple[int, ...]]]:
    """Parameter blocks of the constraints (appended to the :class:`~mobisense.ocp.model.ParameterLayout`)."""
    blocks: list[tuple[str, tuple[int, ...]]] = []
    for name, item in zip(group_names(structure), structure, strict=True):
        kind = item[0]
        if kind == "disc":
            blocks.append((name, (3,)))  # cx, cy, r
        elif kind == "polygon":
            blocks.append((name, (item[1], 2)))
        elif kind == "workspace":
            blocks.append((name, (4,)))  # xmin, xmax, ymin, ymax
        else:
            blocks.append((name, (1,)))
    return blocks


def path_parameter_values(constraints: PathConstraints | None, n_sensors: int) -> dict[str, Any]:
    """The numbers of the blocks of :func:`path_parameter_blocks`."""
    structure = path_structure(constraints, n_sensors)
    if not structure:
        return {}
    values: dict[str, Any] = {}
    for k, zone in enumerate(constraints.keep_out):  # type: ignore[union-attr]
        if isinstance(zone, KeepOutDisc):
            values[f"keep_out[{k}]"] = [*zone.center, zone.radius]
        else:
            values[f"keep_out[{k}]"] = np.asarray(zone.polygon, float)
    if ("min_separation",) in structure:
        values["min_separation"] = constraints.min_separation  # type: ignore[union-attr]
    if ("max_speed",) in structure:
        values["max_speed"] = constraints.max_speed  # type: ignore[union-attr]
    if ("workspace",) in structure:
        w = constraints.workspace  # type: ignore[union-attr]
        values["workspace"] = [*w.x, *w.y]
    return values


# ---------------------------------------------------------------------- the rows
def _smooth_max(values: list[Any], s: Any) -> Any:
    """Nested ``smax(a, b) = (a + b)/2 + √(((a − b)/2)² + s²)``: max ≤ smax ≤ max + (m − 1) s (eq. path.2)."""
    import casadi as ca  # here, not at import: validating a problem file needs no CasADi

    out = values[0]
    for v in values[1:]:
        out = 0.5 * (out + v) + ca.sqrt((0.5 * (out - v)) ** 2 + s**2)
    return out


def _polygon_edges(V: Any, m: int, orientation: int) -> list[tuple[Any, Any]]:
    """(vertex, outward unit normal) of each edge of a convex polygon (SX or numpy rows)."""
    ca = sys.modules.get("casadi")  # SX rows imply CasADi is loaded
    symbolic = ca is not None and isinstance(V, ca.SX)
    edges = []
    for j in range(m):
        a, b = V[j, :], V[(j + 1) % m, :]
        e = b - a
        length = ca.sqrt(e[0] ** 2 + e[1] ** 2) if symbolic else float(np.hypot(*e))
        normal = orientation * (ca.horzcat(e[1], -e[0]) if symbolic else np.array([e[1], -e[0]])) / length
        edges.append((a, normal))
    return edges


def _polygon_area(V: Any, m: int) -> Any:
    import casadi as ca

    return 0.5 * ca.fabs(sum(V[j, 0] * V[(j + 1) % m, 1] - V[(j + 1) % m, 0] * V[j, 1] for j in range(m)))


def path_rows(
    positions: list[Any], velocities: list[Any], b: dict[str, Any], structure: tuple[tuple[Any, ...], ...]
) -> tuple[list[Any], list[Any], list[tuple[str, str]]]:
    """Scaled rows ``g ≤ 0`` of one instant (eq. path.1–path.5), the physical size of one unit of each, labels.

    Parameters
    ----------
    positions, velocities : list of SX, each (2,)
        Sensor positions (L) and velocities (L/T).
    b : dict
        Unpacked parameter blocks (see :func:`path_parameter_blocks`, plus ``length_scale``, ``velocity_scale``).
    structure : tuple
        :func:`path_structure`.

    Returns
    -------
    rows : list of SX scalars
    scales : list of SX scalars
    labels : list of (group, description)
    """
    import casadi as ca

    L, V = b["length_scale"], b["velocity_scale"]
    N = len(positions)
    rows: list[Any] = []
    scales: list[Any] = []
    labels: list[tuple[str, str]] = []
    for name, item in zip(group_names(structure), structure, strict=True):
        kind = item[0]
        if kind == "disc":
            c, r = b[name][:2], b[name][2]
            for i, p in enumerate(positions):
                rows.append((r**2 - ca.sumsqr(p - c)) / L**2)  # eq. path.1
                labels.append((name, f"keep_out disc {name} of sensor {{{i}}}"))
                scales.append(L**2)
        elif kind == "polygon":
            m, orientation = item[1], item[2]
            Vx = b[name]
            s = POLYGON_MARGIN * ca.sqrt(_polygon_area(Vx, m)) / (m - 1)
            edges = _polygon_edges(Vx, m, orientation)
            for i, p in enumerate(positions):
                distances = [ca.dot(n.T, p - a.T) for a, n in edges]
                rows.append(((m - 1) * s - _smooth_max(distances, s)) / L)  # eq. path.2
                labels.append((name, f"keep_out polygon {name} of sensor {{{i}}}"))
                scales.append(L)
        elif kind == "min_separation":
            dmin = b[name]
            for i in range(N):
                for j in range(i + 1, N):
                    rows.append((dmin**2 - ca.sumsqr(positions[i] - positions[j])) / L**2)  # eq. path.3
                    labels.append((name, f"min_separation of sensors {{{i}}} and {{{j}}}"))
                    scales.append(L**2)
        elif kind == "max_speed":
            vmax = b[name]
            for i, v in enumerate(velocities):
                rows.append((ca.sumsqr(v) - vmax**2) / V**2)  # eq. path.4
                labels.append((name, f"max_speed of sensor {{{i}}}"))
                scales.append(V**2)
        else:  # workspace, eq. path.5
            w = b[name]
            for i, p in enumerate(positions):
                for row, what in (
                    (w[0] - p[0], "x ≥ xmin"),
                    (p[0] - w[1], "x ≤ xmax"),
                    (w[2] - p[1], "y ≥ ymin"),
                    (p[1] - w[3], "y ≤ ymax"),
                ):
                    rows.append(row / L)
                    labels.append((name, f"workspace {what} of sensor {{{i}}}"))
                    scales.append(L)
    return rows, scales, labels


def margins(
    constraints: PathConstraints, p: np.ndarray, v: np.ndarray, only: str | None = None
) -> dict[str, np.ndarray]:
    """Exact physical violation of each constraint group at each time (> 0: violated), numpy.

    Parameters
    ----------
    constraints : PathConstraints
    p, v : ndarray, shape (T, N, 2)
        Positions (L) and velocities (L/T).
    only : str, optional
        One group's name (e.g. ``"keep_out[1]"``): only that group is computed.

    Returns
    -------
    dict
        Group name -> violation (T,): penetration depth into a zone (L), separation deficit (L),
        speed excess (L/T), distance outside the workspace (L).
    """
    out: dict[str, np.ndarray] = {}
    N = p.shape[1]

    def wanted(name: str) -> bool:
        return only is None or only == name

    for k, zone in enumerate(constraints.keep_out):
        if not wanted(f"keep_out[{k}]"):
            continue
        if isinstance(zone, KeepOutDisc):
            depth = zone.radius - np.linalg.norm(p - np.asarray(zone.center), axis=2)
        else:
            Vx = np.asarray(zone.polygon, float)
            edges = _polygon_edges(Vx, len(Vx), zone.orientation)
            depth = -np.max([(p - a) @ n for a, n in edges], axis=0)
        out[f"keep_out[{k}]"] = depth.max(axis=1)
    if constraints.min_separation is not None and N > 1 and wanted("min_separation"):
        out["min_separation"] = constraints.min_separation - _closest_pairs(p)
    if constraints.max_speed is not None and wanted("max_speed"):
        out["max_speed"] = np.linalg.norm(v, axis=2).max(axis=1) - constraints.max_speed
    if constraints.workspace is not None and wanted("workspace"):
        w = constraints.workspace
        outside = np.maximum.reduce([w.x[0] - p[..., 0], p[..., 0] - w.x[1], w.y[0] - p[..., 1], p[..., 1] - w.y[1]])
        out["workspace"] = outside.max(axis=1)
    return out


def constraint_sizes(constraints: PathConstraints) -> dict[str, float]:
    """The size of each group (physical units), which violations are judged relative to.

    A disc's radius, a polygon's √area, d_min, v_max, the workspace's shorter side.
    """
    sizes: dict[str, float] = {}
    for k, zone in enumerate(constraints.keep_out):
        sizes[f"keep_out[{k}]"] = float(zone.radius) if isinstance(zone, KeepOutDisc) else zone.area**0.5
    if constraints.min_separation is not None:
        sizes["min_separation"] = float(constraints.min_separation)
    if constraints.max_speed is not None:
        sizes["max_speed"] = float(constraints.max_speed)
    if constraints.workspace is not None:
        w = constraints.workspace
        sizes["workspace"] = float(min(w.x[1] - w.x[0], w.y[1] - w.y[0]))
    return sizes


def polygon_scale_outside(zone: KeepOutPolygon, p: np.ndarray) -> float:
    """The largest s ≤ 1 for which the polygon, scaled by s about its vertices' mean c, leaves ``p`` (N, 2) outside.

    On its edges counts as outside; 0 when a point is at c. Scaled by s, edge e (vertex a_e, outward unit
    normal n_e) keeps q outside when n_eᵀ(q − c) ≥ s n_eᵀ(a_e − c), and n_eᵀ(a_e − c) > 0 for a convex polygon
    around c: q is outside for s up to max_e n_eᵀ(q − c) / n_eᵀ(a_e − c).
    """
    V = np.asarray(zone.polygon, float)
    c = V.mean(axis=0)
    edges = _polygon_edges(V, len(V), zone.orientation)
    a = np.array([vertex for vertex, _ in edges])
    n = np.array([normal for _, normal in edges])
    reach = np.einsum("ej,ej->e", n, a - c)  # distance of each edge's line from c, > 0
    s = ((np.asarray(p, float) - c) @ n.T / reach).max(axis=1)  # (N,)
    return float(np.clip(s.min(), 0.0, 1.0))


def _closest_pairs(p: np.ndarray) -> np.ndarray:
    """The smallest distance between two of the N points at each time, shape (T,), for ``p`` of shape (T, N, 2).

    Vectorised over the N(N−1)/2 pairs in chunks of times holding at most 2²⁰ pair distances (a loop over the
    pairs took 11 s for 2000 sensors).
    """
    i, j = np.triu_indices(p.shape[1], 1)
    chunk = max(1, 2**20 // len(i))
    return np.concatenate(
        [np.linalg.norm(p[t : t + chunk, i] - p[t : t + chunk, j], axis=2).min(axis=1) for t in range(0, len(p), chunk)]
    )


def check_initial_state(constraints: PathConstraints, p0: list[list[float]], v0: list[list[float]]) -> None:
    """Raise :class:`InvalidValue` (key path of the offending sensor) if the initial state violates a constraint."""
    p = np.asarray(p0, float)[None]
    v = np.asarray(v0, float)[None]
    for name, violation in margins(constraints, p, v).items():
        if violation[0] > 0 and name == "min_separation":  # the closest pair: the later sensor, as for terminals
            i, j = np.triu_indices(p.shape[1], 1)
            k = int(np.argmin(np.linalg.norm(p[0, i] - p[0, j], axis=1)))
            raise InvalidValue(
                f"sensors[{j[k]}].p0",
                f"expected an initial position at least constraints.min_separation {constraints.min_separation:g} "
                f"from sensor {i[k]}'s, got {constraints.min_separation - violation[0]:g}",
            )
        if violation[0] > 0:
            field = "v0" if name == "max_speed" else "p0"
            i = _offending_sensor(constraints, name, p[0], v[0])
            raise InvalidValue(
                f"sensors[{i}].{field}",
                f"expected an initial state satisfying constraints.{name} (violated by {violation[0]:.3g})",
            )


def check_terminal_states(constraints: PathConstraints, terminals: list[tuple[Any, Any]]) -> None:
    """Raise :class:`InvalidValue` (``sensors[i].terminal.p`` or ``.v``) if a fixed end state violates a constraint.

    ``terminals[i]`` is sensor i's ``(p, v)`` target, either None when free. An end state no path can reach
    otherwise fails in Ipopt as an infeasible problem, blamed on a continuity row.
    """
    alone = _without_separation(constraints)
    fixed = []
    for i, (p, v) in enumerate(terminals):
        if p is not None:
            fixed.append((i, np.asarray(p, float)))
            at = margins(alone, np.asarray(p, float)[None, None], np.zeros((1, 1, 2)))
            for name, violation in at.items():
                if name != "max_speed" and violation[0] > 0:
                    raise InvalidValue(f"sensors[{i}].terminal.p", f"expected a terminal position satisfying "
                                       f"constraints.{name} (violated by {violation[0]:.3g})")  # fmt: skip
        speed = None if v is None else float(np.linalg.norm(np.asarray(v, float)))
        if speed is not None and constraints.max_speed is not None and speed > constraints.max_speed:
            raise InvalidValue(f"sensors[{i}].terminal.v", f"expected a terminal speed within constraints.max_speed "
                               f"{constraints.max_speed:g}, got {speed:g}")  # fmt: skip
    if constraints.min_separation is not None:
        for a, (i, p) in enumerate(fixed):
            for j, q in fixed[a + 1 :]:
                if (gap := float(np.linalg.norm(p - q))) < constraints.min_separation:
                    raise InvalidValue(f"sensors[{j}].terminal.p", f"expected a terminal position at least "
                                       f"constraints.min_separation {constraints.min_separation:g} from sensor "
                                       f"{i}'s, got {gap:g}")  # fmt: skip


def _offending_sensor(constraints: PathConstraints, name: str, p: np.ndarray, v: np.ndarray) -> int:
    single = _without_separation(constraints)
    for i in range(p.shape[0]):
        if margins(single, p[None, i : i + 1], v[None, i : i + 1]).get(name, np.zeros(1))[0] > 0:
            return i
    return 0


def _without_separation(constraints: PathConstraints) -> PathConstraints:
    """The constraints of one sensor alone: ``min_separation`` dropped."""
    return constraints.model_copy(update={"min_separation": None})  # validated already: not again
