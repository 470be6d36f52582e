"""The constraints of the direct NLP in problem terms, and the worst-violated one of a failed solve.

Ipopt measures a violation in the NLP's scaled rows (docs/theory/direct.md §3): a dynamics row is a state's
defect over one interval divided by that state's scale, a keep-out disc's row is (r² − |p − c|²) / L², and so
on. :func:`worst_violation` picks the row that is worst in those units (the ones Ipopt's tolerance applies
to) and reports it in the natural quantity of its constraint: a state's defect in the state's units, a
disc's penetration depth r − |p − c| and a separation deficit in lengths, a speed excess |v| − v_max, a
control excess |u| − u_max on the Bernstein coefficient, a terminal position or velocity off its target.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from ..problem import Problem
    from .transcription import DirectCollocation

__all__ = ["ConstraintRow", "constraint_rows", "natural_violation", "worst_violation"]


@dataclass(frozen=True)
class ConstraintRow:
    """One row of the direct NLP's constraints, in problem terms.

    Attributes
    ----------
    description : str
        What the row holds, e.g. ``"dynamics of Σ[0,0] (collocation)"``.
    time : float
        When (T): a collocation node, an interval boundary or a Bernstein coefficient's instant.
    kind : str
        ``"state"`` (continuity or collocation), ``"u_max"``, ``"path"``, ``"terminal position"`` or
        ``"terminal velocity"``.
    key : int or str
        The state component (index into the state vector) of a ``"state"`` row, the sensor of a ``"u_max"``
        or terminal row, the group name of a ``"path"`` row (e.g. ``"keep_out[0]"``, ``"max_speed"``).
    """

    description: str
    time: float
    kind: str
    key: int | str


def constraint_rows(tr: DirectCollocation, sensor_names: list[str], t0: float, tf: float) -> list[ConstraintRow]:
    """Every constraint row of the transcription ``tr``, in the NLP's order (see :class:`ConstraintRow`)."""
    s, k, d, K = tr.structure, tr.kernels, tr.colloc.degree, tr.intervals
    state = s.state.labels(sensor_names)
    nx = len(state)
    starts, nodes = tr.times(t0, tf)
    bounded = [i for i in range(s.N) if s.bounded_control[i]]
    hull = len(tr.colloc.bernstein)  # Bernstein coefficient r sits at τ = r / (hull − 1)
    rows: list[ConstraintRow] = []
    for j in range(K):
        rows += [ConstraintRow(f"continuity of {state[c]}", float(starts[j + 1]), "state", c)
                 for c in range(nx - k.nn, nx)]  # fmt: skip
        for r in range(d):
            rows += [ConstraintRow(f"dynamics of {state[c]} (collocation)", float(nodes[j, r]), "state", c)
                     for c in range(k.ns)]  # fmt: skip
        for r in range(hull):
            at = float(starts[j] + (starts[j + 1] - starts[j]) * r / max(hull - 1, 1))
            rows += [ConstraintRow(f"|u| ≤ u_max of sensor {sensor_names[i]} (Bernstein coefficient {r + 1})", at,
                                   "u_max", i) for i in bounded]  # fmt: skip
        for r in range(d):
            rows += [ConstraintRow(what.format(*sensor_names), float(nodes[j, r]), "path", group)
                     for group, what in tr.model.path_labels]  # fmt: skip
    rows += [ConstraintRow(f"{kind} of sensor {sensor_names[i]}", float(starts[-1]), kind.rsplit(" ", 1)[0], i)
             for kind, i in k.terminal_labels]  # fmt: skip
    return rows


def natural_violation(row: ConstraintRow, value: float, problem: Problem) -> tuple[float, str]:
    """The violation of ``row`` in its constraint's natural quantity, and that quantity's unit.

    Parameters
    ----------
    row : ConstraintRow
    value : float
        The row's physical residual beyond its bound (≥ 0): the scaled violation times the row's
        :meth:`~mobisense.ocp.direct.transcription.DirectCollocation.constraint_scales` entry, e.g.
        r² − |p − c|² (L²) for a disc, |u|² − u_max² (L²/T⁴) for a control bound.
    problem : Problem

    Returns
    -------
    violation : float
        A state's defect (its unit), a penetration depth or separation deficit (L), |v| − v_max (L/T),
        |u| − u_max (L/T²), a distance or speed off a terminal target.
    units : str
        UDUNITS string of ``violation`` in the problem's declared units.
    """
    units = problem.units.system()
    length, speed, accel = units.of(length=1), units.of(length=1, time=-1), units.of(length=1, time=-2)

    def deficit(size: float, squared: float) -> float:  # size − √(size² − (size² − d²)) = size − d
        return size - float(np.sqrt(max(size**2 - squared, 0.0)))

    def excess(size: float, squared: float) -> float:  # √(size² + (|x|² − size²)) − size = |x| − size
        return float(np.sqrt(max(size**2 + squared, 0.0))) - size

    if row.kind == "state":
        n_sigma = problem.n * (problem.n + 1) // 2
        c = int(row.key)
        unit = units.of(state=2) if c < n_sigma else (length if c < n_sigma + 2 * problem.N else speed)
        return value, unit
    if row.kind == "u_max":
        return excess(float(problem.sensors[int(row.key)].u_max), value), accel
    if row.kind == "terminal position":
        return value, length
    if row.kind == "terminal velocity":
        return value, speed
    constraints, group = problem.constraints, str(row.key)
    if group.startswith("keep_out"):
        zone = constraints.keep_out[int(group[len("keep_out[") : -1])]
        if hasattr(zone, "radius"):
            return deficit(float(zone.radius), value), length
        return value, length  # a polygon's row is its smoothed depth (L) already (eq. path.2)
    if group == "min_separation":
        return deficit(float(constraints.min_separation), value), length
    if group == "max_speed":
        return excess(float(constraints.max_speed), value), speed
    return value, length  # workspace: the distance outside an edge


def worst_violation(tr: DirectCollocation, g: np.ndarray, P: np.ndarray, problem: Problem) -> dict[str, Any]:
    """The worst-violated constraint of the NLP point with rows ``g`` at parameters ``P``.

    Returns
    -------
    dict
        ``constraint`` and ``time`` (the row in problem terms), ``violation`` and ``units`` (the natural
        quantity, :func:`natural_violation`) and ``scaled_violation`` (what Ipopt compares with its tolerance,
        by which the row was chosen).
    """
    _, _, lbg, ubg = tr.bounds()
    scaled = np.maximum(np.maximum(lbg - g, g - ubg), 0.0)
    index = int(np.argmax(scaled))
    row = constraint_rows(tr, [s.name for s in problem.sensors], problem.horizon.t0, problem.horizon.tf)[index]
    violation, units = natural_violation(row, float(scaled[index] * tr.constraint_scales(P)[index]), problem)
    return {"constraint": row.description, "time": row.time, "violation": violation, "units": units,
            "scaled_violation": float(scaled[index])}  # fmt: skip
