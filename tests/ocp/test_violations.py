"""The direct NLP's constraint rows in problem terms, and the worst violation of a failed solve in its natural units.

Every row's size is checked against the quantity computed here from the states and controls the NLP point
holds (:meth:`DirectCollocation.unpack`), by the constraint's own formula: a disc's depth r − |p − c|, the
separation deficit, |v| − v_max, the distance outside the workspace, |u| − u_max on the Bernstein coefficients,
a terminal position off its target. Those are exact identities of the row formulas, so the tolerance is
rounding: 1e-9 of the sizes involved (≈ 10).
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import yaml
from reference_problems import PROBLEMS

import mobisense as ms
from mobisense.ocp.direct.guesses import coasting_start
from mobisense.ocp.direct.transcription import transcription_for
from mobisense.ocp.direct.violations import ConstraintRow, constraint_rows, natural_violation, worst_violation
from mobisense.ocp.problem import Problem


def _problem(units: dict | None = None) -> Problem:
    """Two sensors crossing a disc and each other's path, a workspace, a speed limit, |u| and terminal bounds."""
    data = yaml.safe_load((PROBLEMS / "hussein2008.yaml").read_text())
    sensor = data["sensors"][0]
    data["sensors"] = [
        {**sensor, "name": "a", "p0": [10.0, 10.0], "v0": [-0.7, -1.1], "u_max": 0.5},
        {**sensor, "name": "b", "p0": [2.0, 10.0], "v0": [0.075, -1.05], "terminal": {"p": [3.0, 2.0]}},
    ]
    data["constraints"] = {"keep_out": [{"center": [6.5, 4.5], "radius": 2.0}], "min_separation": 3.5,
                           "max_speed": 1.4, "workspace": {"x": [-2.0, 12.0], "y": [0.0, 12.0]}}  # fmt: skip
    data["solver"]["collocation"]["intervals"] = 12
    if units:
        data["units"] = units
    return Problem.from_dict(data)


def _point(problem: Problem) -> tuple:
    """The transcription, P, and a point that breaks every kind of row: the coasting guess, jittered."""
    tr = transcription_for(problem)
    P, w0 = coasting_start(problem, tr)
    w = w0 + np.random.default_rng(5).normal(scale=0.3, size=w0.shape)
    g = np.asarray(ca.Function("g", [tr.nlp["x"], tr.nlp["p"]], [tr.nlp["g"]])(w, P)).ravel()
    return tr, P, w, g


def test_every_row_is_sized_in_its_constraints_natural_quantity() -> None:
    problem = _problem()
    tr, P, w, g = _point(problem)
    rows = constraint_rows(tr, ["a", "b"], 0.0, 10.0)
    assert len(rows) == tr.ng
    _, _, lbg, ubg = tr.bounds()
    scaled = np.maximum(np.maximum(lbg - g, g - ubg), 0.0)
    physical = scaled * tr.constraint_scales(P)
    sizes = np.array([natural_violation(row, value, problem)[0] for row, value in zip(rows, physical, strict=True)])

    x = tr.unpack(w, P)
    n_sigma, K, d = 1, tr.intervals, tr.colloc.degree
    p = x["xc"][:, :, n_sigma : n_sigma + 4].reshape(K, d, 2, 2)  # (K, d, sensor, xy) at the collocation nodes
    v = x["xc"][:, :, n_sigma + 4 :].reshape(K, d, 2, 2)
    u = x["u"].reshape(K, d, 2, 2)

    def largest(kind: str, key: int | str) -> float:
        chosen = [i for i, row in enumerate(rows) if row.kind == kind and row.key == key]
        assert chosen, (kind, key)
        return float(sizes[chosen].max())

    depth = 2.0 - np.linalg.norm(p - [6.5, 4.5], axis=-1)
    assert np.isclose(largest("path", "keep_out[0]"), max(depth.max(), 0.0), rtol=1e-9, atol=1e-9)
    deficit = 3.5 - np.linalg.norm(p[:, :, 0] - p[:, :, 1], axis=-1)
    assert np.isclose(largest("path", "min_separation"), max(deficit.max(), 0.0), rtol=1e-9, atol=1e-9)
    speeding = np.linalg.norm(v, axis=-1) - 1.4
    assert np.isclose(largest("path", "max_speed"), max(speeding.max(), 0.0), rtol=1e-9, atol=1e-9)
    outside = np.maximum.reduce([-2.0 - p[..., 0], p[..., 0] - 12.0, 0.0 - p[..., 1], p[..., 1] - 12.0])
    assert np.isclose(largest("path", "workspace"), max(outside.max(), 0.0), rtol=1e-9, atol=1e-9)
    coefficients = np.einsum("rj,kjc->krc", np.asarray(tr.colloc.bernstein), u[:, :, 0])  # sensor a's hull
    assert np.isclose(largest("u_max", 0), max((np.linalg.norm(coefficients, axis=-1) - 0.5).max(), 0.0), rtol=1e-9)
    off = np.abs(x["xs"][-1, n_sigma + 2 : n_sigma + 4] - [3.0, 2.0])  # sensor b's terminal position
    assert np.isclose(largest("terminal position", 1), off.max(), rtol=1e-9)
    # each kind was broken at this point, so none of the comparisons above is 0 = 0
    assert min(depth.max(), deficit.max(), speeding.max(), outside.max()) > 0.0
    assert {r.kind for r in rows} == {"state", "u_max", "path", "terminal position"}


def test_the_worst_row_is_chosen_in_ipopts_scaling_and_reported_in_declared_units() -> None:
    problem = _problem(units={"length": "km", "time": "h"})
    tr, P, _, g = _point(problem)
    worst = worst_violation(tr, g, P, problem)
    _, _, lbg, ubg = tr.bounds()
    scaled = np.maximum(np.maximum(lbg - g, g - ubg), 0.0)
    assert worst["scaled_violation"] == scaled.max()
    row = constraint_rows(tr, ["a", "b"], 0.0, 10.0)[int(np.argmax(scaled))]
    assert (worst["constraint"], worst["time"]) == (row.description, row.time)
    expected = {"state": None, "u_max": "km h-2", "path": None, "terminal position": "km"}[row.kind]
    if expected:
        assert worst["units"] == expected


def test_natural_violations_of_each_kind_against_their_closed_forms() -> None:
    problem = _problem(units={"length": "km", "time": "h"})
    # a disc of radius 2 with a sensor 1.5 from its centre: the row's r² − d² = 1.75, the depth 0.5
    assert np.isclose(natural_violation(ConstraintRow("", 0.0, "path", "keep_out[0]"), 4.0 - 1.5**2, problem)[0], 0.5)
    # sensors 2.75 apart under d_min = 3.5: deficit 0.75
    size, unit = natural_violation(ConstraintRow("", 0.0, "path", "min_separation"), 3.5**2 - 2.75**2, problem)
    assert np.isclose(size, 0.75) and unit == "km"
    # |v| = 1.9 under v_max = 1.4: |v|² − v_max² = 1.65, excess 0.5 km/h
    size, unit = natural_violation(ConstraintRow("", 0.0, "path", "max_speed"), 1.9**2 - 1.4**2, problem)
    assert np.isclose(size, 0.5) and unit == "km h-1"
    # |u| = 0.8 against u_max = 0.5 of sensor a
    size, unit = natural_violation(ConstraintRow("", 0.0, "u_max", 0), 0.64 - 0.25, problem)
    assert np.isclose(size, 0.3) and unit == "km h-2"
    assert natural_violation(ConstraintRow("", 0.0, "state", 0), 0.1, problem) == (0.1, "1")  # Σ entry: state²
    assert natural_violation(ConstraintRow("", 0.0, "state", 1), 0.1, problem) == (0.1, "km")  # a position
    assert natural_violation(ConstraintRow("", 0.0, "state", 5), 0.1, problem) == (0.1, "km h-1")  # a velocity


def test_a_failed_constrained_solve_names_its_worst_row_in_problem_units(tmp_path) -> None:
    # keep_out.yaml stopped after 3 iterations: its worst row used to be quoted in scaled NLP units only
    data = yaml.safe_load((PROBLEMS / "keep_out.yaml").read_text())
    data["solver"].update(max_iterations=3, strategy="cold")
    data["solver"]["collocation"]["intervals"] = 30
    solution = ms.solve(ms.Problem.from_dict(data))
    assert solution.status == "failed"
    worst = solution.stats["worst_violation"]
    assert set(worst) == {"constraint", "time", "violation", "units", "scaled_violation"}
    assert worst["violation"] > 0.0 and worst["scaled_violation"] > 1e-6
    assert f"(violation {worst['violation']:.3g}" in solution.message
