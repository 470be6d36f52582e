"""Path constraints of a field's shooting NLP: its rows, and their activity and violation at the solution.

:func:`shooting_control_report` gives the ``u_max`` group of the same report: the controls are piecewise linear
between the nodes, so |u(t)| is convex on each interval and its largest value is at a node.

:func:`path_row_function` gives the rows of eq. path.1–5 of one instant as a CasADi function of the sensors'
positions and velocities (the shooting has no collocation model to hold them). The NLP holds them at its K
nodes; the sensors between them fly the piecewise-linear controls exactly (eq. field.7,
:func:`~mobisense.ocp.field.flown_states`), so :func:`shooting_constraint_report` samples the flown path 20
times per interval and refines the largest violation of each group between the samples
(:func:`~mobisense.ocp.direct.path_report.refine_maximum`), as for a direct solution.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .direct.path_report import refine_maximum, rows_active
from .field import flown_states
from .path_constraints import (
    PathConstraints,
    group_names,
    margins,
    path_parameter_blocks,
    path_parameter_values,
    path_rows,
    path_structure,
)
from .problem import Problem

__all__ = ["path_row_function", "shooting_constraint_report", "shooting_control_report"]

#: samples of the flown path per interval before the maxima are refined
SAMPLES_PER_INTERVAL = 20


def path_row_function(constraints: PathConstraints, n_sensors: int) -> tuple[Any, np.ndarray, list[tuple[str, str]]]:
    """The scaled rows of one instant as a CasADi function of the sensors' state, for methods without a model.

    Parameters
    ----------
    constraints : PathConstraints
    n_sensors : int

    Returns
    -------
    rows : casadi.Function
        ``(p (2N), v (2N), params) -> (g, scale)``: the rows of :func:`path_rows` and the physical size of a unit
        of each, with ``params`` the constraints' numbers followed by the length and velocity scales.
    params : ndarray
        The constraints' numbers in that order (append the two scales).
    labels : list of (group, description)
    """
    import casadi as ca

    structure = path_structure(constraints, n_sensors)
    values = path_parameter_values(constraints, n_sensors)
    b: dict[str, Any] = {}
    numbers = []
    for name, shape in path_parameter_blocks(structure):
        b[name] = ca.SX.sym(name, *shape) if len(shape) == 2 else ca.SX.sym(name, shape[0])
        numbers.append(np.asarray(values[name], float).ravel(order="F"))  # as ca.vec: column-major
    b["length_scale"], b["velocity_scale"] = ca.SX.sym("L"), ca.SX.sym("V")
    p, v = ca.SX.sym("p", 2 * n_sensors), ca.SX.sym("v", 2 * n_sensors)
    rows, scales, labels = path_rows([p[2 * i : 2 * i + 2] for i in range(n_sensors)],
                                     [v[2 * i : 2 * i + 2] for i in range(n_sensors)], b, structure)  # fmt: skip
    params = ca.vertcat(*[ca.vec(b[name]) for name, _ in path_parameter_blocks(structure)], b["length_scale"],
                        b["velocity_scale"])  # fmt: skip
    function = ca.Function("path_rows", [p, v, params], [ca.vertcat(*rows), ca.vertcat(*scales)])
    return function, np.concatenate(numbers) if numbers else np.zeros(0), labels


def shooting_constraint_report(problem: Problem, trajectory: Any, rows: np.ndarray, multipliers: np.ndarray,
                               units: np.ndarray, groups: np.ndarray, cost_scale: float) -> dict[str, Any]:  # fmt: skip
    """``{group: {active, max_violation, max_violation_time, max_violation_at_nodes, max_multiplier, units}}``.

    Parameters
    ----------
    problem : Problem
        With ``constraints``.
    trajectory : ShootingTrajectory
        Node times ``t`` (K + 1,), ``p``, ``v``, ``u`` (K + 1, N, 2) of the solution.
    rows, multipliers : ndarray, shape (K, R)
        The NLP's scaled path rows at nodes 1 … K and their multipliers.
    units : ndarray, shape (R,)
        The physical size of one unit of each row.
    groups : ndarray of str, shape (R,)
        Each row's constraint group (``keep_out[0]``, ``max_speed``, …).
    cost_scale : float
        The NLP's objective is J / cost_scale.

    Returns
    -------
    dict
        As :func:`mobisense.ocp.direct.path_report.constraint_report`'s path groups: ``max_violation`` is the
        largest physical violation on the flown path (≤ 0: held with that margin), in the problem's length (or
        speed) unit.
    """
    constraints = problem.constraints
    system = problem.units.system()
    length, speed = system.of(length=1), system.of(length=1, time=-1)
    t_nodes, p_nodes, v_nodes, u_nodes = (np.asarray(getattr(trajectory, k)) for k in ("t", "p", "v", "u"))
    K = len(t_nodes) - 1
    t = np.linspace(t_nodes[0], t_nodes[-1], K * SAMPLES_PER_INTERVAL + 1)

    def flown(times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p, v, _ = flown_states(t_nodes, p_nodes, v_nodes, u_nodes, np.asarray(times, float))
        return p, v

    violation = margins(constraints, *flown(t))
    at_nodes = margins(constraints, p_nodes[1:], v_nodes[1:])
    names = group_names(path_structure(constraints, problem.N))
    per_unit = np.abs(multipliers) * cost_scale / units[None, :]
    out: dict[str, Any] = {}
    for name in names:
        mask = groups == name
        largest, when = refine_maximum(lambda times, name=name: margins(constraints, *flown(times), only=name)[name],
                                       t, violation[name])  # fmt: skip
        out[name] = {
            "active": rows_active(rows[:, mask], multipliers[:, mask]),
            "max_violation": largest,
            "max_violation_time": when,
            "max_violation_at_nodes": float(at_nodes[name].max()),
            "max_multiplier": float(per_unit[:, mask].max()),
            "units": speed if name == "max_speed" else length,
        }
    return out


def shooting_control_report(problem: Problem, trajectory: Any, rows: np.ndarray, multipliers: np.ndarray,
                            cost_scale: float) -> dict[str, Any]:  # fmt: skip
    """The ``u_max`` group of a shooting solution: |u| − u_max of the bounded sensors, activity, multipliers.

    Parameters
    ----------
    problem : Problem
        With at least one sensor's ``u_max``.
    trajectory : ShootingTrajectory
        Node times ``t`` (K + 1,) and controls ``u`` (K + 1, N, 2) (L/T²).
    rows, multipliers : ndarray, shape (B·(K + 1),)
        The NLP's rows |u|²/u_max² − 1 of the bounded sensors, sensor by sensor and node by node, and their
        multipliers.
    cost_scale : float
        The NLP's objective is J / cost_scale.

    Returns
    -------
    dict
        As the ``u_max`` entry of :func:`mobisense.ocp.direct.path_report.constraint_report`: ``max_violation``
        the largest |u(t)| − u_max (L/T²) on the whole path — at a node, since |u| is convex between nodes —
        and ``max_multiplier`` the price of one L/T² of it, λ·c_s·2/u_max (the row's slope in |u| at the bound).
    """
    t, u = np.asarray(trajectory.t, float), np.asarray(trajectory.u, float)
    bounded = [i for i, sensor in enumerate(problem.sensors) if sensor.u_max is not None]
    u_max = np.array([problem.sensors[i].u_max for i in bounded])
    excess = np.linalg.norm(u[:, bounded], axis=-1) - u_max  # (K + 1, B)
    node = int(np.argmax(excess.max(axis=1)))
    slope = np.repeat(2.0 / u_max, len(t))  # rows are sensor-major, as the NLP holds them
    return {
        "active": rows_active(rows, multipliers),
        "max_violation": float(excess.max()),
        "max_violation_time": float(t[node]),
        "max_violation_at_nodes": float(excess.max()),
        "max_multiplier": float((np.abs(multipliers) * cost_scale * slope).max()),
        "units": problem.units.system().of(length=1, time=-2),
    }
