"""Hostile ``solution.nc`` files: one ``ConfigError`` line naming the file and the variable, nothing allocated first.

A real solution (Hussein's problem on 4 intervals, solved in a fraction of a second) is copied and corrupted with
h5py; a "bomb" is a few-kB file whose chunked, never written variables declare arrays of any size. Every bad file
is refused by :meth:`Solution.load` (and the layout ones already by :meth:`Solution.read_problem`, which
``mobisense replay`` calls for its pre-flight budget) with ``FILE: <variable>: expected …, got …``; through the
command: exit 2, one line, no output folder.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
import yaml
from reference_problems import hussein2008

from mobisense import cli
from mobisense.core.errors import ConfigError
from mobisense.ocp.solution import Solution


@pytest.fixture(scope="module")
def saved(tmp_path_factory) -> Path:
    from mobisense.ocp.direct.solver import solve_direct
    from mobisense.ocp.problem import Problem

    solution = solve_direct(Problem.from_dict(hussein2008(collocation={"intervals": 4}, homotopy={"step": 0.5})))
    assert solution.success and len(solution.t) == 13 and len(solution.t_u) == 12
    folder = tmp_path_factory.mktemp("saved")
    solution.save(folder)
    return folder / "solution.nc"


def variant(saved: Path, folder: Path, edit: Callable[[h5py.File], None], name: str = "bad.nc") -> Path:
    """A copy of the saved solution with ``edit`` applied to the open HDF5 file."""
    path = folder / name
    shutil.copyfile(saved, path)
    with h5py.File(path, "r+") as f:
        edit(f)
    return path


def _problem_yaml(f: h5py.File) -> dict[str, Any]:
    text = f.attrs["problem_yaml"]
    return yaml.safe_load(text.decode() if isinstance(text, bytes) else text)


def _edit_problem(change: Callable[[dict[str, Any]], None]) -> Callable[[h5py.File], None]:
    def edit(f: h5py.File) -> None:
        data = _problem_yaml(f)
        change(data)
        f.attrs["problem_yaml"] = yaml.safe_dump(data)

    return edit


def _two_sensors(data: dict[str, Any]) -> None:
    data["sensors"].append({**data["sensors"][0], "name": "s2", "p0": [-10.0, 10.0]})


def _two_states(data: dict[str, Any]) -> None:
    eye = [[1.0, 0.0], [0.0, 1.0]]
    data["process"].update(A=[[-0.5, 0.0], [0.0, -0.5]], B=eye, Q=eye, Sigma0=[[200.0, 0.0], [0.0, 200.0]],
                           locations=[[0.0, 0.0], [1.0, 1.0]])  # fmt: skip
    data["cost"].update(M=[[20.0, 0.0], [0.0, 20.0]], K=[[0.0, 0.0], [0.0, 0.0]])


def _set(name: str, index: Any, value: float) -> Callable[[h5py.File], None]:
    def edit(f: h5py.File) -> None:
        values = f[name][...]
        values[index] = value
        f[name][...] = values

    return edit


def _reverse_time(f: h5py.File) -> None:
    f["time"][...] = f["time"][...][::-1]


def _attribute(name: str, value: Any) -> Callable[[h5py.File], None]:
    def edit(f: h5py.File) -> None:
        if value is None:
            del f.attrs[name]
        else:
            f.attrs[name] = value

    return edit


def _tf(data: dict[str, Any]) -> None:
    data["horizon"]["tf"] = 1000.0


#: corruption -> (edit, variable named, what the message says); the layout cases are refused before any value is read
LAYOUT = {
    "problem_yaml with 2 sensors, arrays with 1": (_edit_problem(_two_sensors), "p",
                                                   "expected 2 entries along 'sensor' (the sensors of problem_yaml)"),
    "problem_yaml with 2 states, arrays with 1": (_edit_problem(_two_states), "Sigma",
                                                  "expected 2 entries along 'row' (the process states"),
    "no problem_yaml": (_attribute("problem_yaml", None), "problem_yaml", "expected the attribute"),
    "collocation_json of another grid": (_attribute("collocation_json", json.dumps(["radau", 3, 5])), "time_u",
                                         "expected 15 control times (5 intervals × degree 3"),
    "collocation_json not a grid": (_attribute("collocation_json", json.dumps(["radau", "3", 4])),
                                    "collocation_json", "expected [scheme, degree 1…9, intervals 1…100000]"),
}  # fmt: skip
VALUES = {
    "NaN in p": (_set("p", (5, 0, 0), np.nan), "p", "expected finite numbers"),
    "p = 1e300": (_set("p", (5, 0, 1), 1e300), "p", "of magnitude at most 1e+100, got 1e+300 at [5, 0, 1]"),
    "NaN in time": (_set("time", 5, np.nan), "time", "expected finite numbers, got nan at [5]"),
    "reversed time": (_reverse_time, "time", "expected strictly increasing times"),
    "time_u beyond tf": (_set("time_u", -1, 20.0), "time_u", "expected times in the horizon [0, 10] of problem_yaml"),
    "problem_yaml tf = 1000": (_edit_problem(_tf), "time", "expected times from t0 = 0 to tf = 1000"),
    "unknown status": (_attribute("status", "maybe"), "status", "expected 'solved' or 'failed', got 'maybe'"),
    "NaN eps": (_attribute("eps", np.nan), "eps", "expected a finite number"),
    "homotopy_json nested too deep": (_attribute("homotopy_json", "[" * 100_000), "homotopy_json",
                                      "expected JSON text"),
    "homotopy_json of other records": (_attribute("homotopy_json", '[{"x": 1}]'), "homotopy_json",
                                       "expected a list of steps"),
}  # fmt: skip


def assert_names(err: pytest.ExceptionInfo[ConfigError], path: Path, variable: str, expected: str) -> None:
    text = str(err.value)
    assert text.startswith(f"{path}: {variable}: ") or text.startswith(f"{path}:{variable}: "), text
    assert expected in text and "\n" not in text, text


def test_the_saved_solution_loads(saved):
    solution = Solution.load(saved)
    assert solution.success and solution.p.shape == (13, 1, 2) and Solution.read_problem(saved).N == 1
    again = Solution.from_dataset(solution.to_dataset())  # the multistart path: an in-memory dataset
    assert again.cost == solution.cost and np.array_equal(again.t, solution.t)


@pytest.mark.parametrize("case", LAYOUT)
def test_a_file_not_shaped_like_its_problem_is_refused_before_reading_values(case, saved, tmp_path):
    edit, variable, expected = LAYOUT[case]
    path = variant(saved, tmp_path, edit)
    for read in (Solution.load, Solution.read_problem):
        with pytest.raises(ConfigError) as err:
            read(path)
        assert_names(err, path, variable, expected)


@pytest.mark.parametrize("case", VALUES)
def test_a_file_with_impossible_values_is_refused(case, saved, tmp_path):
    edit, variable, expected = VALUES[case]
    path = variant(saved, tmp_path, edit)
    with pytest.raises(ConfigError) as err:
        Solution.load(path)
    assert_names(err, path, variable, expected)


def test_a_failed_solve_keeps_what_it_reached(saved, tmp_path):
    # NaN in a failed solve's arrays is what the solver reached (Solution.reject_non_finite), not a corrupt file
    path = variant(saved, tmp_path, lambda f: (_set("p", (5, 0, 0), np.nan)(f), _attribute("status", "failed")(f)))
    solution = Solution.load(path)
    assert not solution.success and np.isnan(solution.p[5, 0, 0])


def bomb(saved: Path, path: Path, times: int) -> Path:
    """The saved solution's attributes with chunked, never written variables of ``times`` state times."""
    import h5netcdf

    sizes = {"time": times, "row": 1, "col": 1, "sensor": 1, "xy": 2, "time_u": 12}
    sensor = ("sensor", "xy")
    variables = {"time": ("time",), "time_u": ("time_u",), "Sigma": ("time", "row", "col"), "p": ("time", *sensor),
                 "v": ("time", *sensor), "u": ("time_u", *sensor)}  # fmt: skip
    with h5py.File(saved, "r") as src:
        attrs = {k: v for k, v in src.attrs.items() if not k.startswith("_")}  # not the netCDF-internal ones
    with h5netcdf.File(path, "w") as f:
        f.dimensions = sizes
        for name, dims in variables.items():
            f.create_variable(name, dims, float, chunks=tuple(min(sizes[d], 1024) for d in dims))
        f.attrs.update(attrs)
    assert path.stat().st_size < 100_000
    return path


def test_declared_arrays_beyond_the_memory_budget_are_refused_before_xarray_opens_them(saved, tmp_path, monkeypatch):
    import xarray

    path = bomb(saved, tmp_path / "bomb.nc", 2**40)  # 8 TiB per variable, in a few kB

    def refuse(*args: Any, **kwargs: Any) -> None:
        raise AssertionError("xarray opened a file whose arrays do not fit the memory budget")

    monkeypatch.setattr(xarray, "open_dataset", refuse)
    for read in (Solution.load, Solution.read_problem):
        with pytest.raises(ConfigError) as err:
            read(path)
        assert_names(err, path, "p", "expected arrays that fit the memory budget")
        assert f"got shape ({2**40}, 1, 2)" in str(err.value)


def test_declared_sizes_are_checked_against_the_stored_grid_before_loading(saved, tmp_path):
    path = bomb(saved, tmp_path / "bomb.nc", 10**6)  # within the budget, not the 4-interval grid of degree 3
    with pytest.raises(ConfigError) as err:
        Solution.load(path)
    assert_names(err, path, "time", "expected 13 to 17 state times (4 intervals × degree 3, collocation_json), got")


def replay(tmp_path: Path, solution: Path, capsys, task: int | None = None) -> tuple[int, str, Path]:
    scenario = tmp_path / "replay.yaml"
    data = {"name": "r", "solution": str(solution), "monte_carlo": {"runs": 5, "time_step": 0.1}}
    if task is not None:
        data["task"] = task
    scenario.write_text(yaml.safe_dump(data))
    out = tmp_path / "out"
    status = cli.main(["replay", str(scenario), "--out", str(out), "--no-plot"])
    return status, capsys.readouterr().err, out


@pytest.mark.parametrize(
    ("case", "variable", "expected"),
    [
        ("bomb", "p", "expected arrays that fit the memory budget"),
        ("problem_yaml with 2 sensors, arrays with 1", "p", "expected 2 entries along 'sensor'"),
        ("NaN in p", "p", "expected finite numbers"),
        ("problem_yaml tf = 1000", "time", "expected times from t0 = 0 to tf = 1000"),
    ],
)
def test_the_replay_command_refuses_a_bad_solution_in_one_line(case, variable, expected, saved, tmp_path, capsys):
    if case == "bomb":
        path = bomb(saved, tmp_path / "bad.nc", 2**40)
    else:
        path = variant(saved, tmp_path, {**LAYOUT, **VALUES}[case][0])
    status, err, out = replay(tmp_path, path, capsys)
    assert status == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert str(path) in err and f"{variable}: {expected}" in err, err
    assert not out.exists()


@pytest.fixture
def part_file(saved, tmp_path) -> Path:
    """A sweep's file of two tasks (sweep indices 3 and 7), both the saved solution."""
    from mobisense.core.files import write_netcdf
    from mobisense.ocp.task_files import stack_tasks

    solution = Solution.load(saved)
    one, digest = solution.to_content(), solution.problem.digest()
    path = tmp_path / "tasks" / "part-000001.nc"
    path.parent.mkdir()
    write_netcdf(path, stack_tasks([one, one], [3, 7], [digest, digest]))
    return path


def test_the_problem_of_a_sweep_task_is_read_with_its_index(part_file):
    assert Solution.read_problem(part_file, task=7).N == 1
    assert Solution.load(part_file, task=7).success
    with pytest.raises(ConfigError, match="holds several tasks of a sweep"):
        Solution.read_problem(part_file)
    with pytest.raises(ConfigError, match=r"task: task 5 is not in this file \(it holds tasks 3, 7\)"):
        Solution.read_problem(part_file, task=5)


def test_the_replay_command_flies_a_sweep_task(part_file, tmp_path, capsys):
    status, err, out = replay(tmp_path, part_file, capsys, task=7)
    assert status == 0, err
    assert (out / "summary.json").exists()
