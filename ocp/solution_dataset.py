"""``solution.nc``: a :class:`~mobisense.ocp.solution.Solution` as a CF-1.10 ``xarray.Dataset`` and back.

Units come from the problem's ``units`` block (:class:`~mobisense.ocp.problem.Units`: length and time,
default metre and second, and the units of the process state and of the cost, default dimensionless):
``p`` is in the length unit, ``Sigma`` in state², the costates in cost per unit of their state. The
table :data:`VARIABLES` gives every variable's description and unit; the file reference of the
documentation is generated from the datasets themselves.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from typing import Any

import numpy as np

from ..core.files import to_jsonable
from ..core.netcdf_writer import DatasetContent
from ..core.reader import parse_document
from ..core.units import UnitSystem
from ..core.yaml_text import dump_mapping

__all__ = ["VARIABLES", "COORDINATES", "solution_content", "solution_dataset", "solution_fields", "variable_attrs"]

#: variable -> (long_name, powers of the base units in its unit)
VARIABLES: dict[str, tuple[str, dict[str, int]]] = {
    "Sigma": ("estimation error covariance Σ(t) of the process state", {"state": 2}),
    "p": ("sensor position", {"length": 1}),
    "v": ("sensor velocity", {"length": 1, "time": -1}),
    "u": ("sensor acceleration (the control)", {"length": 1, "time": -2}),
    "Lam": ("costate of Σ, ∂J/∂Σ (symmetric)", {"cost": 1, "state": -2}),
    "lam_p": ("costate of the sensor position, ∂J/∂p", {"cost": 1, "length": -1}),
    "lam_v": ("costate of the sensor velocity, ∂J/∂v", {"cost": 1, "length": -1, "time": 1}),
    "sigma_diag": ("error variance diag Σ(t) of the field at each state (grid cell centre)", {"state": 2}),
    "path_eps": ("ε of each accepted homotopy step (1: the original problem)", {}),
    "path_p": ("sensor position at each accepted homotopy step", {"length": 1}),
    "path_Sigma": ("error covariance at each accepted homotopy step", {"state": 2}),
    "nlp_w": ("scaled NLP decision variables at the optimum (warm starts)", {}),
    "nlp_lam_w": ("multipliers of the bounds of the scaled NLP variables (warm starts)", {}),
    "nlp_lam_g": ("multipliers of the NLP constraints (warm starts)", {}),
    "nlp_P": ("packed problem data of the NLP (mixed units, see mobisense.ocp.model.ParameterLayout)", {}),
}
#: coordinate -> (long_name, powers of the base units)
COORDINATES: dict[str, tuple[str, dict[str, int]]] = {
    "time": ("time of the states (interval boundaries and collocation points)", {"time": 1}),
    "time_u": ("time of the controls (collocation points)", {"time": 1}),
    "time_costate": ("time of the costates (t0 and every collocation point)", {"time": 1}),
    "time_indirect": ("time of the indirect (BVP) solution's nodes", {"time": 1}),
    "row": ("row index of Σ and Λ (process state)", {}),
    "col": ("column index of Σ and Λ (process state)", {}),
    "step": ("index of the accepted homotopy step", {}),
    "state": ("index j = ix + nx·iy of the field state (grid cell)", {}),
    "state_x": ("x of the field state's cell centre", {"length": 1}),
    "state_y": ("y of the field state's cell centre", {"length": 1}),
    "sensor": ("sensor name", {}),
    "xy": ("planar component", {}),
}
#: NLP vector -> its dimension (not an index coordinate: the values are not labels)
_NLP_DIMS = {"w": "nlp_variable", "lam_w": "nlp_variable", "lam_g": "nlp_constraint", "P": "nlp_parameter"}


_DESCRIBED = {**VARIABLES, **COORDINATES}


def variable_attrs(solution: Any, name: str, suffix: str = "") -> dict[str, str]:
    """``long_name`` and ``units`` of variable or coordinate ``name`` in the units of a Solution's problem."""
    return _attrs(solution.problem.units.system(), name, suffix)


def _attrs(system: UnitSystem, name: str, suffix: str = "") -> dict[str, str]:
    long_name, powers = _DESCRIBED[name]
    return {"long_name": long_name + suffix, "units": system.of(**powers)}


def solution_dataset(solution: Any) -> Any:
    """The solution as an ``xarray.Dataset`` (what ``solution.nc`` holds, see the module notes)."""
    return solution_content(solution).to_xarray()


def solution_content(solution: Any) -> DatasetContent:
    """What ``solution.nc`` holds, as numpy arrays (written without xarray, see the module notes)."""
    s, n = solution, solution.problem.n
    sensor, cov = ("time", "sensor", "xy"), ("time", "row", "col")
    arrays: dict[str, tuple[tuple[str, ...], Any]] = {
        "Sigma": (cov, s.Sigma), "p": (sensor, s.p), "v": (sensor, s.v), "u": (("time_u", "sensor", "xy"), s.u),
    }  # fmt: skip
    coords: dict[str, tuple[tuple[str, ...], Any]] = {
        "time": (("time",), s.t), "time_u": (("time_u",), s.t_u),
        "sensor": (("sensor",), [x.name for x in s.problem.sensors]), "xy": (("xy",), ["x", "y"]),
        "row": (("row",), np.arange(n)), "col": (("col",), np.arange(n)),
    }  # fmt: skip
    if s.problem.process.field is not None:
        locations = s.problem.process.field.process().locations
        coords.update(state=(("state",), np.arange(n)), state_x=(("state",), locations[:, 0]),
                      state_y=(("state",), locations[:, 1]))  # fmt: skip
        arrays["sigma_diag"] = (("time", "state"), np.diagonal(s.Sigma, axis1=1, axis2=2))
        if not s.stats.get("full_sigma", True):  # solver.shooting.full_sigma (default: n <= 25)
            del arrays["Sigma"], coords["row"], coords["col"]
    if s.Lam is not None:
        coords["time_costate"] = (("time_costate",), s.t_costate)
        arrays["Lam"] = (("time_costate", "row", "col"), s.Lam)
        arrays["lam_p"] = (("time_costate", "sensor", "xy"), s.lam_p)
        arrays["lam_v"] = (("time_costate", "sensor", "xy"), s.lam_v)
    if s.path_eps is not None:
        coords["step"] = (("step",), np.arange(len(s.path_eps)))
        arrays["path_eps"] = (("step",), s.path_eps)
        arrays["path_p"] = (("step", "time", "sensor", "xy"), s.path_p)
        arrays["path_Sigma"] = (("step", "time", "row", "col"), s.path_Sigma)
    if s.nlp is not None:
        for key, dim in _NLP_DIMS.items():
            arrays[f"nlp_{key}"] = ((dim,), np.asarray(s.nlp[key]))
    attrs = {
        "title": f"mobisense: solution of problem '{s.problem.name}' by the {s.method} method",
        "comment": "Sigma and Lam are full symmetric matrices; costates are those of J (minimisation, H = L + λ'f)",
        "nlp_signature": "" if s.nlp is None else s.nlp["signature"],
        # a sweep pays this per task: the text of the entries its tasks share is emitted once
        "problem_yaml": dump_mapping(s.problem.normalised()),
        "solver_options_json": s.problem.solver.model_dump_json(),
        "summary_json": json.dumps(s.summary()),
        "homotopy_json": json.dumps(to_jsonable([asdict(step) for step in s.homotopy])),
        "baseline_json": json.dumps(to_jsonable(s.baseline)),
        "stats_json": json.dumps(to_jsonable(s.stats)),
        "method": s.method, "status": s.status.value, "message": s.message, "eps": s.eps,
        "collocation_json": json.dumps(s.collocation),
        "terminal_cost": s.terminal_cost, "running_cost": s.running_cost, "control_energy": s.control_energy,
    }  # fmt: skip
    content = DatasetContent(attrs=attrs)
    system = s.problem.units.system()
    for name, (dims, values) in arrays.items():
        content.add_variable(name, dims, values, _attrs(system, name))
    for name, (dims, values) in coords.items():
        content.add_coord(name, dims, values, _attrs(system, name))
    return content


def solution_fields(ds: Any) -> dict[str, Any]:
    """The constructor arguments of a :class:`Solution` read from its dataset (``problem`` as YAML data)."""
    a = ds.attrs
    has_costates, has_path = "Lam" in ds, "path_eps" in ds
    optional = {
        "t_costate": ds["time_costate"].values if has_costates else None,
        **{k: ds[k].values if has_costates else None for k in ("Lam", "lam_p", "lam_v")},
        **{k: ds[k].values if has_path else None for k in ("path_eps", "path_p", "path_Sigma")},
    }
    collocation = a.get("collocation_json")
    return {
        "problem": parse_document(str(a["problem_yaml"]), "solution.nc:problem_yaml"),
        "method": str(a["method"]),
        "status": str(a["status"]),
        "message": str(a["message"]),
        "eps": float(a["eps"]),
        "t": ds["time"].values,
        "Sigma": ds["Sigma"].values if "Sigma" in ds else None,
        "p": ds["p"].values,
        "v": ds["v"].values,
        "t_u": ds["time_u"].values,
        "u": ds["u"].values,
        "terminal_cost": float(a["terminal_cost"]),
        "running_cost": float(a["running_cost"]),
        "control_energy": float(a["control_energy"]),
        "homotopy": json.loads(a["homotopy_json"]),
        "baseline": json.loads(a["baseline_json"]),
        "stats": json.loads(a["stats_json"]),
        "collocation": None if collocation in (None, "null") else tuple(json.loads(collocation)),
        "nlp": None
        if "nlp_w" not in ds
        else {
            "w": ds["nlp_w"].values,
            "lam_w": ds["nlp_lam_w"].values,
            "lam_g": ds["nlp_lam_g"].values,
            "P": ds["nlp_P"].values,
            "signature": str(a["nlp_signature"]),
        },
        **optional,
    }
