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

from ..core.config import MAX_MAGNITUDE
from ..core.errors import ConfigError, brief
from ..core.files import to_jsonable
from ..core.netcdf_writer import DatasetContent
from ..core.reader import parse_document
from ..core.units import UnitSystem
from ..core.yaml_text import dump_mapping

__all__ = [
    "VARIABLES",
    "COORDINATES",
    "DIMENSIONS",
    "solution_content",
    "solution_dataset",
    "solution_fields",
    "stored_problem",
    "check_layout",
    "check_times",
    "check_values",
    "variable_attrs",
]

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

#: variable -> its dimensions in ``solution.nc`` (as written, and as :func:`check_layout` checks a file read back)
DIMENSIONS: dict[str, tuple[str, ...]] = {
    "time": ("time",), "time_u": ("time_u",), "time_costate": ("time_costate",),
    "Sigma": ("time", "row", "col"), "p": ("time", "sensor", "xy"), "v": ("time", "sensor", "xy"),
    "u": ("time_u", "sensor", "xy"), "sigma_diag": ("time", "state"),
    "Lam": ("time_costate", "row", "col"), "lam_p": ("time_costate", "sensor", "xy"),
    "lam_v": ("time_costate", "sensor", "xy"),
    "path_eps": ("step",), "path_p": ("step", "time", "sensor", "xy"), "path_Sigma": ("step", "time", "row", "col"),
    **{f"nlp_{key}": (dim,) for key, dim in _NLP_DIMS.items()},
}  # fmt: skip
#: coordinates that are not index coordinates: their dimension
_AUXILIARY = {"state_x": ("state",), "state_y": ("state",)}
#: the global ``comment`` of a solution, and of a shooting solution (no costates)
_COMMENT = "Sigma and Lam are full symmetric matrices; costates are those of J (minimisation, H = L + λ'f)"
_SHOOTING_COMMENT = "Sigma (when stored) is the full symmetric covariance; shooting has no costates"
#: the time coordinates of a shooting solution, which has no collocation points
_SHOOTING_TIMES = {
    "time": "time of the states: the shooting intervals' boundaries",
    "time_u": "time of the controls (piecewise linear between them): the shooting intervals' boundaries",
}


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
    arrays: dict[str, Any] = {"Sigma": s.Sigma, "p": s.p, "v": s.v, "u": s.u}
    coords: dict[str, Any] = {"time": s.t, "time_u": s.t_u, "sensor": [x.name for x in s.problem.sensors],
                              "xy": ["x", "y"], "row": np.arange(n), "col": np.arange(n)}  # fmt: skip
    if s.problem.process.field is not None:
        locations = s.problem.process.field.process().locations
        coords.update(state=np.arange(n), state_x=locations[:, 0], state_y=locations[:, 1])
        arrays["sigma_diag"] = s.variances()
        # solver.shooting.full_sigma (default: n <= 25); a solution loaded from such a file has no Σ to write
        if s.Sigma is None or not s.stats.get("full_sigma", True):
            del arrays["Sigma"], coords["row"], coords["col"]
    if s.Lam is not None:
        coords["time_costate"] = s.t_costate
        arrays.update(Lam=s.Lam, lam_p=s.lam_p, lam_v=s.lam_v)
    if s.path_eps is not None:
        coords["step"] = np.arange(len(s.path_eps))
        arrays.update(path_eps=s.path_eps, path_p=s.path_p, path_Sigma=s.path_Sigma)
    if s.nlp is not None:
        arrays.update({f"nlp_{key}": np.asarray(s.nlp[key]) for key in _NLP_DIMS})
    attrs = {
        "title": f"mobisense: solution of problem '{s.problem.name}' by the {s.method} method",
        "comment": _SHOOTING_COMMENT if s.method == "shooting" else _COMMENT,
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
        "cost": s.cost, "terminal_cost": s.terminal_cost, "running_cost": s.running_cost,
        "control_energy": s.control_energy,
    }  # fmt: skip
    content = DatasetContent(attrs=attrs)
    system = s.problem.units.system()
    for name, values in arrays.items():
        content.add_variable(name, DIMENSIONS[name], values, _attrs(system, name))
    for name, values in coords.items():
        attrs = _attrs(system, name)
        if s.method == "shooting" and name in _SHOOTING_TIMES:  # no collocation points (docs/theory/field.md §3)
            attrs["long_name"] = _SHOOTING_TIMES[name]
        if name in ("row", "col") and "Lam" not in arrays:  # no costates in this file
            attrs["long_name"] = attrs["long_name"].replace(" and Λ", "")
        content.add_coord(name, _AUXILIARY.get(name, (name,)), values, attrs)
    return content


# ------------------------------------------------------------------------------------------ reading back
#: variables read together: a file with the first holds all of them
_GROUPS = (("Lam", "lam_p", "lam_v", "time_costate"), ("path_eps", "path_p", "path_Sigma"),
           ("nlp_w", "nlp_lam_w", "nlp_lam_g", "nlp_P"))  # fmt: skip


def _fail(source: str, key: str, expected: str, got: str) -> ConfigError:
    return ConfigError(f"{source}: {key}: expected {expected}, got {got}")


def _attribute(ds: Any, name: str, source: str) -> Any:
    if name not in ds.attrs:
        raise _fail(source, name, "the attribute mobisense solve writes", "a file without it (not a solution)")
    return ds.attrs[name]


def _text(ds: Any, name: str, source: str) -> str:
    value = _attribute(ds, name, source)
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    if not isinstance(value, str):
        raise _fail(source, name, "text", brief(value))
    return value


def _number(ds: Any, name: str, source: str) -> float:
    value = np.asarray(_attribute(ds, name, source))
    if value.size != 1 or value.dtype.kind not in "fiu" or not np.isfinite(value.astype(float)).all():
        raise _fail(source, name, "a finite number", brief(value))
    return float(value.reshape(()))


def _json(ds: Any, name: str, source: str, kind: type) -> Any:
    text = _text(ds, name, source)
    try:
        value = json.loads(text)
    except (ValueError, RecursionError):
        raise _fail(source, name, "JSON text", brief(text)) from None
    if not isinstance(value, kind):
        raise _fail(source, name, f"a JSON {'object' if kind is dict else 'list'}", brief(value))
    return value


def _collocation(ds: Any, source: str) -> tuple[str, int, int] | None:
    """``(scheme, degree, intervals)`` of a direct solution (``collocation_json``), None for other methods."""
    from .collocation import SCHEMES

    value = ds.attrs.get("collocation_json")
    if value is None or (isinstance(value, str) and value == "null"):
        return None
    value = _json(ds, "collocation_json", source, list)
    if not (
        len(value) == 3
        and isinstance(value[0], str)
        and value[0] in SCHEMES
        and all(type(x) is int for x in value[1:])
        and 1 <= value[1] <= 9
        and 1 <= value[2] <= 100_000
    ):
        raise _fail(source, "collocation_json", "[scheme, degree 1…9, intervals 1…100000]", brief(value))
    return value[0], value[1], value[2]


def stored_problem(ds: Any, source: str = "solution.nc") -> Any:
    """The :class:`~mobisense.ocp.problem.Problem` a solution dataset solves (its ``problem_yaml``), validated."""
    from .problem import Problem

    where = f"{source}:problem_yaml"
    return Problem.from_dict(parse_document(_text(ds, "problem_yaml", source), where), source=where)


def check_layout(ds: Any, problem: Any, source: str = "solution.nc") -> None:
    """Check, before reading any value, that a dataset holds a Solution of ``problem``; else ``ConfigError``.

    Every variable a Solution reads has its dimensions (:data:`DIMENSIONS`) and numbers; ``sensor``, ``xy``,
    ``row``/``col``/``state`` have the problem's N, 2 and n entries; there are at least two state times; a
    direct solution's grids are those of its ``collocation_json`` (K intervals of degree d: K d control times).
    """
    N, n = problem.N, problem.n
    required = ["time", "time_u", "p", "v", "u"] + (["Sigma"] if problem.process.field is None else [])
    for group in _GROUPS:
        if group[0] in ds.variables:
            required += group[1:]
    for name in required:
        if name not in ds.variables:
            raise _fail(source, name, f"a variable of dimensions {DIMENSIONS[name]}", "a file without it")
    for name, dims in DIMENSIONS.items():
        if name not in ds.variables:
            continue
        var = ds.variables[name]
        if tuple(var.dims) != dims:
            raise _fail(source, name, f"dimensions {dims}", str(tuple(var.dims)))
        if var.dtype.kind not in "fiu":
            raise _fail(source, name, "numbers", f"values of type {var.dtype}")
    sizes = {str(k): int(v) for k, v in ds.sizes.items()}
    states = "the process states of problem_yaml"
    what = {"sensor": (N, "the sensors of problem_yaml"), "xy": (2, "x and y"), "row": (n, states),
            "col": (n, states), "state": (n, states)}  # fmt: skip
    for dim, (size, which) in what.items():
        if dim in sizes and sizes[dim] != size:
            raise _fail(source, _variable_of(ds, dim), f"{size} entries along {dim!r} ({which})", f"{sizes[dim]}")
    for dim, least in (("time", 2), ("time_u", 1), ("time_costate", 1), ("step", 1)):
        if dim in sizes and sizes[dim] < least:
            raise _fail(source, dim, f"at least {least} value(s)", f"{sizes[dim]}")
    collocation = _collocation(ds, source)
    if collocation is not None:
        _, d, K = collocation
        if sizes["time_u"] != K * d:
            raise _fail(source, "time_u", f"{K * d} control times ({K} intervals × degree {d}, collocation_json)",
                        f"{sizes['time_u']}")  # fmt: skip
        if not K * d + 1 <= sizes["time"] <= K * (d + 1) + 1:
            raise _fail(source, "time", f"{K * d + 1} to {K * (d + 1) + 1} state times ({K} intervals × degree {d}, "
                        "collocation_json)", f"{sizes['time']}")  # fmt: skip
        if "time_costate" in sizes and sizes["time_costate"] != K * d + 1:
            raise _fail(source, "time_costate", f"{K * d + 1} costate times (t0 and the {K * d} collocation points)",
                        f"{sizes['time_costate']}")  # fmt: skip


def _variable_of(ds: Any, dim: str) -> str:
    """The first variable read that has dimension ``dim`` (the key path of a wrong size)."""
    return next((name for name, dims in DIMENSIONS.items() if dim in dims and name in ds.variables), dim)


def check_times(ds: Any, problem: Any, source: str = "solution.nc") -> None:
    """Read the times only and check them, before the other arrays are read.

    Finite, strictly increasing, within the horizon of ``problem``; the state times run from t0 to tf.
    """
    t0, tf = problem.horizon.t0, problem.horizon.tf
    tol = 1e-8 * (tf - t0) + 64 * np.finfo(float).eps * max(abs(t0), abs(tf))
    for name in ("time", "time_u", "time_costate"):
        if name not in ds.variables:
            continue
        t = _values(ds, name)
        _finite(t, name, source)
        steps = np.diff(t)
        if np.any(steps <= 0):
            i = int(np.argmax(steps <= 0))
            raise _fail(source, name, "strictly increasing times", f"{name}[{i + 1}] = {t[i + 1]:g} after {t[i]:g}")
        if t[0] < t0 - tol or t[-1] > tf + tol:
            raise _fail(source, name, f"times in the horizon [{t0:g}, {tf:g}] of problem_yaml",
                        f"[{t[0]:g}, {t[-1]:g}]")  # fmt: skip
        if name == "time" and (abs(t[0] - t0) > tol or abs(t[-1] - tf) > tol):
            raise _fail(source, name, f"times from t0 = {t0:g} to tf = {tf:g} (the horizon of problem_yaml)",
                        f"[{t[0]:g}, {t[-1]:g}]")  # fmt: skip


def check_values(fields: dict[str, Any], source: str = "solution.nc") -> None:
    """Check the values :func:`solution_fields` read (their times are :func:`check_times`'s).

    ``path_eps`` must be finite; a solved solution's Σ, p, v, u and costs must also be finite and at most
    :data:`~mobisense.core.config.MAX_MAGNITUDE` in magnitude (a failed solve keeps what it reached, NaN
    included).
    """
    if fields["path_eps"] is not None:
        _finite(fields["path_eps"], "path_eps", source)
    if fields["status"] != "solved":
        return
    for name in ("terminal_cost", "running_cost", "control_energy"):
        if not abs(fields[name]) <= MAX_MAGNITUDE:
            raise _fail(source, name, f"a magnitude at most {MAX_MAGNITUDE:g} (status: solved)", f"{fields[name]:g}")
    for name in ("Sigma", "sigma_diag", "p", "v", "u"):
        if fields[name] is not None:
            _finite(fields[name], name, source, bound=True)


def _finite(values: np.ndarray, name: str, source: str, bound: bool = False) -> None:
    values = np.asarray(values, dtype=float)
    finite = np.isfinite(values)
    bad = ~finite | (np.abs(np.where(finite, values, 0.0)) > MAX_MAGNITUDE) if bound else ~finite
    if np.any(bad):
        where = np.unravel_index(int(np.argmax(bad)), values.shape)
        index = ", ".join(str(int(i)) for i in where)
        expected = f"finite numbers of magnitude at most {MAX_MAGNITUDE:g}" if bound else "finite numbers"
        raise _fail(source, name, expected, f"{values[where]:g} at [{index}] ({int(bad.sum())} such value(s) in all)")


def solution_fields(ds: Any, source: str = "solution.nc", problem: Any = None) -> dict[str, Any]:
    """The constructor arguments of a :class:`Solution` read from its dataset (``problem`` as YAML data).

    ``problem`` (already read, e.g. by :func:`stored_problem`) is used as is instead. Attributes that are
    missing or not of their type raise ``ConfigError`` naming ``source`` and the attribute.
    """
    has_costates, has_path = "Lam" in ds, "path_eps" in ds
    optional = {
        "t_costate": _values(ds, "time_costate") if has_costates else None,
        **{k: _values(ds, k) if has_costates else None for k in ("Lam", "lam_p", "lam_v")},
        **{k: _values(ds, k) if has_path else None for k in ("path_eps", "path_p", "path_Sigma")},
    }
    if problem is None:
        problem = parse_document(_text(ds, "problem_yaml", source), f"{source}:problem_yaml")
    status = _text(ds, "status", source)
    if status not in ("solved", "failed"):
        raise _fail(source, "status", "'solved' or 'failed'", brief(status))
    return {
        "problem": problem,
        "method": _text(ds, "method", source),
        "status": status,
        "message": _text(ds, "message", source),
        "eps": _number(ds, "eps", source),
        "t": _values(ds, "time"),
        "Sigma": _values(ds, "Sigma") if "Sigma" in ds else None,
        "p": _values(ds, "p"),
        "v": _values(ds, "v"),
        "t_u": _values(ds, "time_u"),
        "u": _values(ds, "u"),
        "terminal_cost": _number(ds, "terminal_cost", source),
        "running_cost": _number(ds, "running_cost", source),
        "control_energy": _number(ds, "control_energy", source),
        "homotopy": _json(ds, "homotopy_json", source, list),
        "baseline": _json(ds, "baseline_json", source, dict),
        "stats": _json(ds, "stats_json", source, dict),
        "collocation": _collocation(ds, source),
        "sigma_diag": _values(ds, "sigma_diag") if "Sigma" not in ds and "sigma_diag" in ds else None,
        "nlp": None
        if "nlp_w" not in ds
        else {
            "w": _values(ds, "nlp_w"),
            "lam_w": _values(ds, "nlp_lam_w"),
            "lam_g": _values(ds, "nlp_lam_g"),
            "P": _values(ds, "nlp_P"),
            "signature": str(ds.attrs.get("nlp_signature", "")),
        },
        **optional,
    }


def _values(ds: Any, name: str) -> np.ndarray:
    """A variable's values as floats (the file may store them as integers)."""
    return np.asarray(ds.variables[name].values, dtype=float)
