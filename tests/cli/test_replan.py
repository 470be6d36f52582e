"""``mobisense replay`` on a ``kind: replan`` file: outputs, and bad input (exit 2 with the key path)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from reference_problems import PROBLEMS

from mobisense import cli


def _files(tmp_path, **replan):
    data = yaml.safe_load((PROBLEMS / "hussein2008.yaml").read_text())
    data["solver"]["collocation"]["intervals"] = 20
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(data))
    scenario = {
        "kind": "replan",
        "problem": "p.yaml",
        "replan": {"every": 2.5, "horizon": "shrinking", **replan},
        "disturbance": {"drift": [0.3, -0.2], "force_noise_std": 0.05, "seed": 1},
        "monte_carlo": {"runs": 2, "time_step": 0.02},
    }
    path = tmp_path / "replan.yaml"
    path.write_text(yaml.safe_dump(scenario))
    return path


@pytest.mark.slow
def test_replan_file_writes_summary_result_and_figure(tmp_path, capsys) -> None:
    out = tmp_path / "out"
    assert cli.main(["replay", str(_files(tmp_path)), "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    for name in ("closed_loop", "open_loop", "no_control"):
        assert set(s[name]) == {"cost_mean", "cost_std", "cost_stderr"}
    assert s["replan_every_s"] == 2.5 and s["replan_solve_time_s"]["max"] > 0
    assert {"result.nc", "replan.png"} <= set(s["files"])
    printed = capsys.readouterr().out  # the terminal gives the three policies' costs as summary.json has them
    closed, open_ = s["closed_loop"], s["open_loop"]
    assert f"closed loop {closed['cost_mean']:.6g} ± {closed['cost_stderr']:.2g}" in printed
    assert f"open loop {open_['cost_mean']:.6g} ± {open_['cost_stderr']:.2g}" in printed
    assert f"results in {out}/" in printed


@pytest.mark.slow
def test_receding_replan_file_stores_every_runs_plans_with_cf_attributes(tmp_path) -> None:
    import cf_units
    import xarray as xr

    from mobisense.core.netcdf import cf_problems

    out = tmp_path / "out"
    path = _files(tmp_path, horizon="receding", length=5.0)
    assert cli.main(["replay", str(path), "--out", str(out), "--no-plot"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["horizon"] == {"kind": "receding", "length": 5.0} and s["warm_start"] == "shifted"
    with xr.open_dataset(out / "result.nc", engine="h5netcdf") as ds:
        assert cf_problems(ds, cf_units.Unit) == []
        assert ds["plan_p"].dims == ("run", "plan", "plan_node", "sensor", "xy") and ds.sizes["run"] == 2
        # every run made its first plan and its re-plans at t = 2.5, 5, 7.5 (every = 2.5 over tf = 10)
        assert ds["plan_instant"].values.tolist() == [[0.0, 2.5, 5.0, 7.5]] * 2
        # a receding plan made at t covers [t, min(t + 5, 10)]
        assert ds["plan_time"].values[0, :, -1].tolist() == pytest.approx([5.0, 7.5, 10.0, 10.0])


@pytest.mark.slow
@pytest.mark.parametrize("grid, variance", [((2, 2), "Sigma"), ((6, 5), "sigma_diag")])
def test_a_field_replan_file_is_solved_by_shooting_and_stores_its_covariance_as_a_field_solution_does(
    tmp_path, grid, variance
) -> None:
    # re-planning a field was refused ("re-planning solves by direct collocation"); now its windows are shot
    import xarray as xr
    from short_runs import field_problem

    problem = field_problem(grid=grid, sensors=2, shooting={"intervals": 20, "coarse_intervals": 10})
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(problem))
    scenario = {"kind": "replan", "problem": "p.yaml", "replan": {"every": 1.25},
                "disturbance": {"drift": [0.3, -0.2], "force_noise_std": 0.05, "seed": 1},
                "monte_carlo": {"runs": 2, "time_step": 0.05}}  # fmt: skip
    path = tmp_path / "replan.yaml"
    path.write_text(yaml.safe_dump(scenario))
    out = tmp_path / "out"
    assert cli.main(["replay", str(path), "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["replan_failures"] == 0 and s["replan_iterations"]["max"] > 0
    assert s["closed_loop"]["cost_mean"] < s["no_control"]["cost_mean"]
    n = grid[0] * grid[1]
    with xr.open_dataset(out / "result.nc", engine="h5netcdf") as ds:
        assert variance in ds and ds["plan_instant"].values[0].tolist() == [0.0, 1.25, 2.5, 3.75]
        values = ds[variance].values
        diag = values if variance == "sigma_diag" else values.diagonal(axis1=2, axis2=3)
        assert diag.shape == (2, 101, n) and np.all(diag > 0)
        assert np.asarray(ds.attrs["process_locations"]).size == 2 * n and ds.attrs["process_field"] == 1
    assert (out / "replan.png").stat().st_size > 0


@pytest.mark.parametrize(
    ("replan", "monte_carlo", "key"),
    [
        ({"horizon": "receding"}, {}, "replan.length: a receding horizon needs"),
        ({"horizon": "receding", "length": 0.0}, {}, "replan.length: expected a number > 0"),
        ({"horizon": "receding", "length": 20.0}, {}, "replan.length: expected a window within the horizon"),
        ({"horizon": "receding", "length": 2.0}, {}, "replan.every: expected every ≤ length"),
        ({"length": 5.0}, {}, "replan.length: only a receding horizon"),
        ({"warm_start": "hot"}, {}, "replan.warm_start"),
        ({"every": 0.001}, {}, "replan.every: expected at least monte_carlo.time_step"),
        ({}, {"runs": 100_000, "time_step": 1e-5}, "too large: 100000 runs × 1e+06 steps"),
    ],
)
def test_bad_replan_files_exit_2_with_the_key_path_and_write_nothing(tmp_path, capsys, replan, monte_carlo, key):
    path = _files(tmp_path, **replan)
    if monte_carlo:
        data = yaml.safe_load(path.read_text())
        data["monte_carlo"].update(monte_carlo)
        path.write_text(yaml.safe_dump(data))
    out = tmp_path / "out"
    assert cli.main(["replay", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert key in err and len(err.strip().splitlines()) == 1 and not out.exists()


def test_a_negative_disturbance_seed_exits_2_naming_it(tmp_path, capsys) -> None:
    # red team: validate passed it and replay exited 1 with numpy's "expected non-negative integer"
    path = _files(tmp_path)
    data = yaml.safe_load(path.read_text())
    data["disturbance"]["seed"] = -1
    path.write_text(yaml.safe_dump(data))
    assert cli.main(["validate", str(path)]) == 2
    out = tmp_path / "out"
    assert cli.main(["replay", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "disturbance.seed" in err and len(err.strip().splitlines()) == 2 and not out.exists()  # one per command


def test_a_replan_whose_first_plan_fails_keeps_that_solve_and_exits_1(tmp_path, capsys) -> None:
    # red team: with solver.max_iterations: 1 the full-horizon plan failed and replay exited 1 writing nothing;
    # `mobisense solve` of the same problem keeps its solve (solution.nc, summary.json with Ipopt's status)
    path = _files(tmp_path)
    problem_file = tmp_path / yaml.safe_load(path.read_text())["problem"]
    data = yaml.safe_load(problem_file.read_text())
    data["solver"]["max_iterations"] = 1
    data["solver"]["strategy"] = "cold"
    problem_file.write_text(yaml.safe_dump(data))
    out = tmp_path / "out"
    assert cli.main(["replay", str(path), "--out", str(out), "--no-plot"]) == 1
    err = capsys.readouterr().err
    assert "the full-horizon plan failed, nothing was flown" in err and "Maximum_Iterations_Exceeded" in err
    assert sorted(p.name for p in out.iterdir()) == ["solution.nc", "summary.json"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed" and "Maximum_Iterations_Exceeded" in summary["message"]
    from mobisense.ocp.solution import Solution

    assert Solution.load(out).problem.solver.max_iterations == 1  # the failed solve, readable as any solution


def test_a_replan_file_allowed_more_time_than_the_default_is_not_refused_by_the_apis_own_check(
    tmp_path, monkeypatch
) -> None:
    # the API's replan_monte_carlo checks its budget against the command's defaults (1 h, half the memory); the
    # command checks the file against --max-time and --max-memory first, so a run allowed more must not be refused
    # inside: the file's run hands the API the widest limits
    import mobisense.ocp.replan as replan_module
    from mobisense.core.budget import MEMORY_LIMITS, TIME_LIMITS
    from mobisense.formation.replay.replan import ReplanScenario, run_replan

    path = _files(tmp_path)
    seen = {}

    def record(problem, samples, limits, **arguments):  # stop at the API's check: no flight needed
        seen["limits"] = limits
        raise KeyboardInterrupt

    monkeypatch.setattr(replan_module, "check_replan_arguments", record)
    with pytest.raises(KeyboardInterrupt):
        run_replan(ReplanScenario.model_validate(yaml.safe_load(path.read_text())), path)
    assert seen["limits"] == (MEMORY_LIMITS[1], TIME_LIMITS[1])
