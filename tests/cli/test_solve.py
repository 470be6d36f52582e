"""The ``mobisense solve|validate`` command line: outputs contract, bad input (exit 2), solver failure (exit 1)."""

from __future__ import annotations

import json
import math
import re

import pytest
import yaml
from reference_problems import PROBLEMS, hussein2008

from mobisense import cli


def write(tmp_path, data, name="problem.yaml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data) if not isinstance(data, str) else data)
    return path


def run_cli(args, capsys):
    code = cli.main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.mark.slow
def test_solve_writes_the_contract(tmp_path, capsys):
    out = tmp_path / "out"
    code, stdout, _ = run_cli(["solve", PROBLEMS / "hussein2008.yaml", "--out", out, "--intervals", "40"], capsys)
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    for key in (
        "name",
        "method",
        "status",
        "cost",
        "terminal_cost",
        "running_cost",
        "control_energy",
        "solve_time_s",
        "homotopy",
        "baseline",
        "improvement_percent",
        "problem_hash",
    ):
        assert key in summary
    assert summary["status"] == "solved"
    assert summary["cost"] == pytest.approx(summary["terminal_cost"] + summary["running_cost"], rel=1e-14)
    # the default strategy (auto, docs/theory/direct.md §5.6) records the steps of every start it solved,
    # each labelled with its start; the kept start reached ε = 1 with the reported cost
    kept = summary["strategy"]["kept"]
    assert kept in {s["start"] for s in summary["strategy"]["starts"]}
    kept_steps = [h for h in summary["homotopy"] if h["start"] == kept]
    assert kept_steps[-1]["eps"] == 1.0 and kept_steps[-1]["cost"] == pytest.approx(summary["cost"], rel=1e-12)
    assert set(summary["homotopy"][0]) == {"eps", "cost", "iterations", "status", "time_s", "start"}
    assert summary["solver"]["collocation"]["intervals"] == 40
    assert summary["improvement_percent"] == pytest.approx(
        100 * (summary["baseline"]["cost"] - summary["cost"]) / summary["baseline"]["cost"]
    )
    for figure in ("paths.png", "covariance.png", "controls.png", "homotopy.png", "solution.nc"):
        assert (out / figure).stat().st_size > 0
    assert "improvement" in stdout
    # the table counts the starts and names the kept one (the ε steps are those of all the starts)
    starts = len(summary["strategy"]["starts"])
    reached = sum(start["eps_reached"] == 1.0 for start in summary["strategy"]["starts"])
    assert re.search(rf"starts tried\s*│\s*{starts}, {reached} reached ε = 1 \({kept} kept\)", stdout)
    assert re.search(rf"Ipopt solves of all starts\s*│\s*{len(summary['homotopy'])} \(ε steps; ε reached 1\)", stdout)
    assert not list(out.glob(".*.tmp"))


def test_every_shipped_problem_validates(capsys):
    files = sorted(PROBLEMS.glob("*.yaml"))
    problems = [f for f in files if {"process", "sensors", "cost"} <= set(yaml.safe_load(f.read_text()))]
    assert len(problems) >= 3
    code, stdout, _ = run_cli(["validate", *problems], capsys)
    assert code == 0
    assert stdout.count("valid") == len(problems)


def _mutate(path, value):
    def apply(data):
        target = data
        for key in path[:-1]:
            target = target[key]
        if value is KeyError:
            del target[path[-1]]
        else:
            target[path[-1]] = value
        return data

    return apply


BAD_INPUTS = [
    ("cost.alhpa", _mutate(["cost", "alhpa"], 0.1), "did you mean 'alpha'"),
    ("cost.alpha", _mutate(["cost", "alpha"], -1.0), "> 0"),
    ("cost.alpha", _mutate(["cost", "alpha"], math.nan), "finite"),
    ("cost", _mutate(["cost"], KeyError), "required"),
    ("cost.M", _mutate(["cost", "M"], [[-1.0]]), "positive definite"),
    ("cost.M", _mutate(["cost", "M"], [[1.0, 0.0], [0.0, 1.0]]), "shape 1x1"),
    ("cost.K", _mutate(["cost", "K"], [[-2.0]]), "semidefinite"),
    ("process.A", _mutate(["process", "A"], [[1.0, 2.0]]), "square"),
    ("process.B", _mutate(["process", "B"], [[1.0], [2.0]]), "shape 1x1"),
    ("process.Sigma0", _mutate(["process", "Sigma0"], [[0.0]]), "positive definite"),
    ("process.locations", _mutate(["process", "locations"], [[0.0, 0.0], [1.0, 1.0]]), "one per state"),
    ("sensors[0].p0", lambda d: (d["sensors"][0].update(p0=[1.0, 2.0, 3.0]), d)[1], "length 2"),
    ("sensors[0].noise.beta", lambda d: (d["sensors"][0]["noise"].update(beta=0.0), d)[1], "> 0"),
    ("sensors[0].noise.model", lambda d: (d["sensors"][0]["noise"].update(model="cubic"), d)[1], "unknown noise model"),
    ("sensors[0].measures", lambda d: (d["sensors"][0].update(measures=[[1.0, 0.0]]), d)[1], "length n = 1"),
    ("sensors[1].name", lambda d: (d["sensors"].append(dict(d["sensors"][0])), d)[1], "duplicate"),
    ("horizon.tf", _mutate(["horizon", "tf"], -1.0), "tf > t0"),
    (
        "solver.collocation.intervals",
        _mutate(["solver", "collocation", "intervals"], 0),
        "expected greater than or equal to 1",
    ),
    (
        "solver.collocation.scheme",
        _mutate(["solver", "collocation", "scheme"], "gauss"),
        "unknown collocation scheme 'gauss'; expected one of 'legendre', 'radau'",
    ),
    ("solver.homotopy.step", _mutate(["solver", "homotopy", "step"], 2.0), "expected less than or equal to 1"),
    # a section that is not a mapping was "a valid dictionary or instance of PathConstraints" (an internal class)
    ("constraints", _mutate(["constraints"], [1, 2]), "expected a mapping of keys to values (got [1, 2], a list)"),
    ("solver.homotopy", _mutate(["solver", "homotopy"], None), "expected a mapping of keys to values (got null)"),
]


@pytest.mark.parametrize("key,mutate,expected", BAD_INPUTS, ids=[f"{k}:{e}" for k, _, e in BAD_INPUTS])
@pytest.mark.parametrize("command", ["solve", "validate"])
def test_bad_input_exit_2_with_key_path(tmp_path, capsys, command, key, mutate, expected):
    path = write(tmp_path, mutate(hussein2008()))
    out = tmp_path / "out"
    args = [command, path] + (["--out", out] if command == "solve" else [])
    code, stdout, stderr = run_cli(args, capsys)
    assert code == 2
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert str(path) in lines[0] and f" {key}:" in lines[0] and expected in lines[0], lines[0]
    assert "Traceback" not in stderr
    assert not out.exists()


@pytest.mark.parametrize(
    "text,expected",
    [
        ("name: x\nhorizon: {t0: 0, tf: [1\n", "invalid YAML"),
        ("- just\n- a list\n", "expected a mapping"),
    ],
)
def test_malformed_yaml(tmp_path, capsys, text, expected):
    path = write(tmp_path, text)
    code, _, stderr = run_cli(["solve", path, "--out", tmp_path / "out"], capsys)
    assert code == 2 and expected in stderr and str(path) in stderr
    assert not (tmp_path / "out").exists()


def test_missing_file(tmp_path, capsys):
    code, _, stderr = run_cli(["validate", tmp_path / "nope.yaml"], capsys)
    assert code == 2 and "file not found" in stderr


def test_command_line_override_is_validated(tmp_path, capsys):
    code, _, stderr = run_cli(
        ["solve", PROBLEMS / "hussein2008.yaml", "--intervals", "0", "--out", tmp_path / "o"], capsys
    )
    assert code == 2 and "solver.collocation.intervals" in stderr


def test_intervals_set_the_grid_of_the_method_that_solves():
    import argparse

    from mobisense.ocp.commands import apply_overrides

    args = argparse.Namespace(method=None, strategy=None, intervals=30, degree=None, scheme=None, homotopy=None,
                              step=None)  # fmt: skip
    field = yaml.safe_load((PROBLEMS / "field_mapping_5x5.yaml").read_text(encoding="utf-8"))
    # a field problem is solved by shooting (its default method): --intervals is the shooting grid's K
    assert apply_overrides(field, args)["solver"]["shooting"]["intervals"] == 30
    # fewer intervals than the homotopy's coarse grid (25 by default): that grid is no finer than the final one
    args.intervals = 7
    shooting = apply_overrides(yaml.safe_load((PROBLEMS / "field_mapping_5x5.yaml").read_text()), args)["solver"]
    assert shooting["shooting"] == {"intervals": 7, "coarse_intervals": 7}
    args.intervals = 30
    assert "intervals" not in field["solver"].get("collocation", {})
    collocated = apply_overrides({**field, "solver": {"method": "direct"}}, args)["solver"]
    assert collocated["collocation"]["intervals"] == 30 and "shooting" not in collocated
    assert apply_overrides(hussein2008(), args)["solver"]["collocation"]["intervals"] == 30


def test_a_failure_with_every_constraint_satisfied_does_not_blame_one() -> None:
    # 5 iterations leave the cold step feasible to 3.5e-7 (scaled) but not optimal: naming the "worst-violated
    # constraint" sent the reader after a constraint that holds
    import mobisense as ms

    solution = ms.solve(ms.Problem.from_dict(hussein2008(max_iterations=5, collocation={"intervals": 30})))
    assert solution.status == "failed" and "Maximum_Iterations_Exceeded" in solution.message
    assert "every constraint holds to" in solution.message and "worst-violated" not in solution.message
    assert solution.stats["worst_violation"]["scaled_violation"] <= 1e-6


def test_solver_failure_keeps_results_and_names_the_constraint(tmp_path, capsys):
    # 3 Ipopt iterations cannot solve the first, cold step (it needs 19): the run fails, exits 1, and keeps
    # what it has (the coasting ε → 0 solution) with the failure described in problem terms.
    data = hussein2008(max_iterations=3, collocation={"intervals": 30})
    path = write(tmp_path, data)
    out = tmp_path / "out"
    code, stdout, stderr = run_cli(["solve", path, "--out", out, "--no-plot"], capsys)
    assert code == 1
    assert "Maximum_Iterations_Exceeded" in stderr and "worst-violated constraint" in stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed"
    # the table names the plan it holds (of the last ε solved), not "J (ε = 1)", and quotes no improvement
    assert f"J of the plan held (ε = {summary['eps_reached']:g})" in stdout and "J (ε = 1)" not in stdout
    assert "none quoted: the solve did not reach ε = 1" in stdout
    assert summary["homotopy"][-1]["status"] == "Maximum_Iterations_Exceeded"
    worst = summary["worst_violation"]
    assert worst["constraint"].startswith(("dynamics of", "continuity of", "initial value of", "terminal"))
    assert 0.0 <= worst["time"] <= 10.0
    assert (out / "solution.nc").exists()


@pytest.mark.slow
def test_plot_writes_only_the_figures_asked_for(tmp_path, capsys):
    out = tmp_path / "out"
    args = ["solve", PROBLEMS / "hussein2008.yaml", "--out", out, "--intervals", "20", "--quiet"]
    code, _, _ = run_cli([*args, "--plot", "homotopy, paths.png"], capsys)
    assert code == 0
    assert sorted(p.name for p in out.glob("*.png")) == ["homotopy.png", "paths.png"]
    assert (out / "solution.nc").is_file() and (out / "summary.json").is_file()


@pytest.mark.parametrize(
    ("option", "expected"),
    [
        (["--plot", "paths,maps"], "--plot: no figure 'maps' for the problem of "),
        (["--plot", "path"], "expected some of paths, covariance, controls"),
        (["--plot", "variance_maps"], "--plot: no figure 'variance_maps'"),  # a field problem's figure
        (["--plot", "continuation"], "--plot continuation: only the indirect method draws it"),  # wrote nothing
        (["--plot", ","], "expected a comma list of figure names"),
        (["--plot", "paths", "--no-plot"], "not allowed with argument"),
    ],
)
def test_plot_names_are_checked_before_solving(tmp_path, capsys, option, expected):
    out = tmp_path / "out"
    code, _, stderr = run_cli(["solve", PROBLEMS / "hussein2008.yaml", "--out", out, *option], capsys)
    assert code == 2 and expected in stderr and stderr.count("\n") == 1
    assert not out.exists()


@pytest.mark.slow
def test_a_rerun_into_the_same_folder_leaves_no_earlier_figure(tmp_path, capsys):
    # the figures of an earlier run describe another solution: a re-run with --no-plot (or one interrupted while
    # drawing) must not leave them beside the new solution.nc
    out = tmp_path / "out"
    args = ["solve", PROBLEMS / "hussein2008.yaml", "--out", out, "--intervals", "20", "--quiet"]
    assert run_cli([*args, "--plot", "homotopy"], capsys)[0] == 0
    assert (out / "homotopy.png").is_file()
    (out / "notes.txt").write_text("the user's own file")
    assert run_cli([*args, "--no-plot"], capsys)[0] == 0
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt", "solution.nc", "summary.json"]


def test_homotopy_budget_option_lets_the_continuation_reach_one(tmp_path, capsys):
    """--strategy homotopy is budgeted (1.5 × the cold solve's iterations): on the default example at K = 30
    the continuation stops short of ε = 1 and the cold plan is kept. --homotopy-budget none lifts the budget:
    the continuation alone runs, to ε = 1, at the cold solve's optimum (the same local optimum here; the cold
    solve's J is the independent value, 1e-8 relative being the solves' tolerance, well above round-off)."""
    base = ["solve", "hussein2008", "--intervals", "30", "--strategy", "homotopy", "--no-plot", "--quiet"]
    code, _, stderr = run_cli([*base, "--out", str(tmp_path / "budgeted")], capsys)
    budgeted = json.loads((tmp_path / "budgeted" / "summary.json").read_text())
    assert code == 0 and "spent its budget" in stderr and budgeted["strategy"]["kept"] == "cold"
    code, _, _ = run_cli([*base, "--homotopy-budget", "none", "--out", str(tmp_path / "free")], capsys)
    free = json.loads((tmp_path / "free" / "summary.json").read_text())
    assert code == 0 and {h["start"] for h in free["homotopy"]} == {"homotopy"}  # no cold solve
    assert free["homotopy"][-1]["eps"] == 1.0 and free["eps_reached"] == 1.0
    assert free["cost"] == pytest.approx(budgeted["cost"], rel=1e-8)
    for bad in ("0", "-1", "1e9", "nan", "lots"):
        code, _, stderr = run_cli([*base, "--homotopy-budget", bad, "--out", str(tmp_path / "bad")], capsys)
        assert code == 2 and "--homotopy-budget" in stderr and not (tmp_path / "bad").exists()


def test_a_mistyped_option_is_named_with_the_closest_ones_and_the_commands_help(capsys):
    """argparse reports an unknown option from the top-level parser ("mobisense: error: unrecognized arguments:
    --stratgy cold (see mobisense --help)"), with no hint; the command's own closest options are named now."""
    code, _, stderr = run_cli(["solve", "hussein2008", "--stratgy", "cold"], capsys)
    assert code == 2 and len(stderr.strip().splitlines()) == 1
    assert stderr.startswith("mobisense solve: error: unrecognized arguments: --stratgy cold")
    assert "did you mean --strategy?" in stderr and "(see mobisense solve --help)" in stderr
    code, _, stderr = run_cli(["validate", "hussein2008", "--zzz"], capsys)  # nothing close: no guess
    assert code == 2 and "did you mean" not in stderr and "(see mobisense validate --help)" in stderr


@pytest.mark.parametrize(("flags", "named"), [
    (["--intervals", "0"], "--intervals 0: expected greater than or equal to 1 (got 0) (it sets "
                           "solver.collocation.intervals)"),
    (["--step", "0"], "--step 0: expected greater than or equal to 0.0001"),
    (["--degree", "99"], "--degree 99: expected less than or equal to 9"),
    (["--time-limit", "-1"], "--time-limit -1: expected greater than 0 (got -1.0) (it sets solver.time_limit)"),
])  # fmt: skip
def test_a_bad_override_names_its_flag_not_the_files_key(tmp_path, capsys, flags, named) -> None:
    # first-hour audit: "--intervals 0" was reported as "hussein2008.yaml: solver.collocation.intervals: …",
    # a key the file sets to 100
    out = tmp_path / "out"
    assert cli.main(["solve", "hussein2008", "--out", str(out), *flags]) == 2
    err = capsys.readouterr().err
    assert f"hussein2008.yaml: {named}" in err and err.count("\n") == 1 and not out.exists()


def test_time_limit_stops_each_ipopt_solve_and_keeps_what_was_solved(tmp_path, capsys) -> None:
    # first-hour audit: solve had no --time-limit (only sweep); it sets solver.time_limit like the file's key
    out = tmp_path / "out"
    assert cli.main(["solve", "field_mapping_5x5", "--time-limit", "0.3", "--out", str(out), "--no-plot",
                     "--quiet"]) == 1  # fmt: skip
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed" and "Maximum_WallTime_Exceeded" in summary["message"]
    assert summary["solver"]["time_limit"] == 0.3 and (out / "solution.nc").exists()

