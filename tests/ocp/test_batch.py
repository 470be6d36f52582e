"""Sweeps and multi-start on a real dask LocalCluster of 2 worker processes."""

from __future__ import annotations

import json
import os
import signal

import numpy as np
import pandas as pd
import pytest
import yaml
from reference_problems import hussein2008

from mobisense import cli
from mobisense.core.errors import ConfigError
from mobisense.core.keypath import get_path, parse_key_path, set_path
from mobisense.formation.replay.reference import load_checked
from mobisense.ocp.batch.engine import open_client, run_tasks
from mobisense.ocp.batch.sweep import SweepSpec, expand_sweep
from mobisense.ocp.direct.solver import solve_direct
from mobisense.ocp.problem import Problem
from mobisense.ocp.solution import Solution

pytestmark = pytest.mark.slow  # every test here runs solvers or subprocesses for seconds

ALPHAS = [0.002, 0.004, 0.008]
STARTS = [[10.0, 10.0], [10.0, -10.0], [8.0, 12.0]]


def small_base():
    return hussein2008(collocation={"intervals": 40})


@pytest.fixture()
def sweep_file(tmp_path):
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(small_base()))
    spec = {"base": "base.yaml", "mode": "grid", "vary": {"cost.alpha": ALPHAS, "sensors[0].p0": STARTS}}
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def test_key_paths():
    assert parse_key_path("sensors[0].p0") == ["sensors", 0, "p0"]
    data = {"sensors": [{"p0": [1, 2]}], "cost": {"alpha": 1.0}}
    assert get_path(data, "sensors[0].p0") == [1, 2]
    assert set_path(data, "cost.alpha", 2.0)["cost"]["alpha"] == 2.0 and data["cost"]["alpha"] == 1.0
    with pytest.raises(KeyError, match="did you mean 'alpha'"):
        get_path(data, "cost.alpah")
    with pytest.raises(KeyError, match=r"no item \[3\]"):
        get_path(data, "sensors[3].p0")
    with pytest.raises(ValueError):
        parse_key_path("cost..alpha")


def test_sweep_files_refuse_a_varied_name_or_result_column_and_a_base_that_is_a_folder(tmp_path, capsys):
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(small_base()))
    (tmp_path / "folder").mkdir()
    cases = {
        "name.yaml": ({"base": "base.yaml", "vary": {"name": ["a", "b"]}},
                      "vary: name: the tasks are named by the sweep (base name and index); vary another key"),
        "folder.yaml": ({"base": "folder", "vary": {"cost.alpha": [0.1]}},
                        f"base: {tmp_path / 'folder'} is a directory, expected the base problem file"),
        # the whole cost section: its column and the optimal cost's would be one (a fuzzer's: internal error
        # ArrowInvalid after the first results were written)
        "cost.yaml": ({"base": "base.yaml", "vary": {"cost": [{"M": [[1.0]], "alpha": 0.1}]}},
                      "vary: cost: also the name of a column of the results; vary the keys inside it (cost.…)"),
    }  # fmt: skip
    for name, (spec, expected) in cases.items():
        (tmp_path / name).write_text(yaml.safe_dump(spec))
        assert cli.main(["validate", str(tmp_path / name)]) == 2
        assert f"{tmp_path / name}: {expected}" in capsys.readouterr().err


def test_iter_tasks_is_expand_sweep_one_task_at_a_time():
    from mobisense.ocp.batch.sweep import iter_tasks

    spec = SweepSpec(base="x", vary={"cost.alpha": ALPHAS, "sensors[0].p0": STARTS})
    base = Problem.from_dict(small_base())
    listed, streamed = expand_sweep(spec, base), list(iter_tasks(spec, base))
    assert [(t.task, t.index, t.values) for t in listed] == [(t.task, t.index, t.values) for t in streamed]


def test_zip_mode_needs_equal_lengths():
    spec = SweepSpec(base="x", mode="zip", vary={"cost.alpha": [0.1, 0.2], "horizon.tf": [5.0]})
    with pytest.raises(ValueError, match="equal length"):
        expand_sweep(spec, Problem.from_dict(small_base()))


def test_grid_sweep_equals_single_solves_and_resumes(sweep_file, tmp_path, capsys):
    out = tmp_path / "out"
    assert cli.main(["sweep", str(sweep_file), "--out", str(out), "--workers", "2", "--quiet"]) == 0
    rows = pd.read_parquet(out / "results.parquet")
    assert len(rows) == 9 and set(rows["status"]) == {"solved"}
    assert {
        "cost.alpha",
        "sensors[0].p0",
        "status",
        "cost",
        "terminal_cost",
        "running_cost",
        "iterations",
        "time_s",
        "worker",
    } <= set(rows.columns)
    for _, row in rows.iterrows():
        data = small_base()
        data["cost"]["alpha"] = row["cost.alpha"]
        data["sensors"][0]["p0"] = list(row["sensors[0].p0"])
        single = solve_direct(Problem.from_dict(data))
        # same optimum whether warm-started from a neighbour or continued from coasting (Ipopt tol 1e-9)
        assert row["cost"] == pytest.approx(single.cost, rel=1e-8)
    # every task's solution is in the part file its row names, the same as the row says
    for _, row in rows.iterrows():
        solution = Solution.load(out / row["solution_file"], task=int(row["index"]))
        assert solution.cost == row["cost"] and solution.problem.digest() == row["task"]
    with pytest.raises(ConfigError, match="several tasks of a sweep"):
        Solution.load(out / rows["solution_file"][0])
    with pytest.raises(ConfigError, match=r"task: expected the task's sweep index, an integer .* got '"):
        Solution.load(out / rows["solution_file"][0], task=rows["task"][0])  # the hash column, not the index
    # mobisense replay reads a task of a sweep (solution: OUT/tasks/part-….nc, task: INDEX)
    first = rows.iloc[0]
    replayed, note, solved_here = load_checked(out / first["solution_file"], None, task=int(first["index"]))
    assert not solved_here and replayed.cost == first["cost"] and note.startswith("loaded")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["counts"]["solved"] == 9 and summary["best"]["cost"] == pytest.approx(rows["cost"].min())
    # two workers share one cold head: the second chain starts from the first chain's head (chains.pair_chains)
    assert summary["warm_start"]["warm_tasks"] == 8
    # re-running the same command computes nothing
    stamps = {p: p.stat().st_mtime_ns for p in (out / "tasks").glob("part-*.nc")}
    assert cli.main(["sweep", str(sweep_file), "--out", str(out), "--workers", "2", "--quiet"]) == 0
    assert json.loads((out / "summary.json").read_text())["counts"]["resumed"] == 9
    assert stamps and stamps == {p: p.stat().st_mtime_ns for p in (out / "tasks").glob("part-*.nc")}
    # … and with --no-plot it leaves no cost.png of an earlier run (one may show fewer tasks than the rows)
    assert (out / "cost.png").is_file()
    assert cli.main(["sweep", str(sweep_file), "--out", str(out), "--workers", "2", "--quiet", "--no-plot"]) == 0
    assert not (out / "cost.png").exists()


def test_interrupted_sweep_resumes_without_recomputing(sweep_file, tmp_path, monkeypatch):
    import mobisense.ocp.batch.results_store as store
    import mobisense.ocp.batch.sweep_runner as command

    out = tmp_path / "out"
    monkeypatch.setattr(command, "BATCH_ROWS", 1)  # one fragment per finished task
    real_append = store.ResultStore.append
    appended = []

    def interrupt_after_four(self, rows):
        real_append(self, rows)
        appended.extend(rows)
        if len(appended) == 4:
            raise KeyboardInterrupt

    monkeypatch.setattr(store.ResultStore, "append", interrupt_after_four)
    assert cli.main(["sweep", str(sweep_file), "--out", str(out), "--workers", "2", "--quiet"]) == 130
    assert len(pd.read_parquet(out / "results.parquet")) == 4
    calls = []

    def count(self, rows):
        calls.append(len(rows))
        real_append(self, rows)

    monkeypatch.setattr(store.ResultStore, "append", count)
    # the resumed run flushes by the bytes of the solutions held (each task's arrays, ≈ 30 kB, over 1 byte)
    monkeypatch.setattr(command, "BATCH_ROWS", 1024)
    monkeypatch.setattr(command, "BATCH_BYTES", 1)
    assert cli.main(["sweep", str(sweep_file), "--out", str(out), "--workers", "2", "--quiet"]) == 0
    assert calls == [1, 1, 1, 1, 1, 9]  # only the five unfinished tasks ran; then the fragments are compacted
    summary = json.loads((out / "summary.json").read_text())
    assert summary["counts"]["resumed"] == 4 and summary["counts"]["solved"] == 9
    assert len(list((out / "results.parquet").glob("*.parquet"))) == 1  # compacted into one fragment


def test_killed_worker_does_not_lose_tasks():
    problems = []
    for alpha in np.linspace(0.002, 0.01, 8):
        data = small_base()
        data["cost"]["alpha"] = float(alpha)
        problems.append({"problem": data})
    results = {}
    with open_client(None, 2) as client:
        pids = list(client.run(os.getpid).values())

        def on_result(i, result):
            results[i] = result["row"]
            if len(results) == 2:
                os.kill(pids[0], signal.SIGKILL)  # the nanny restarts it; dask reschedules its tasks

        run_tasks(client, problems, on_result, warm_start=False)
    assert sorted(results) == list(range(8))
    assert all(r["status"] == "solved" for r in results.values())


def test_a_shared_cold_head_is_solved_on_both_workers_as_one_solve_would_be():
    from dask.distributed import get_task_stream

    payloads = []
    for alpha in (0.002, 0.003, 0.004, 0.005):
        data = small_base()
        data["cost"]["alpha"] = alpha
        payloads.append({"problem": data})
    rows = {}
    with open_client(None, 2) as client, get_task_stream(client) as stream:
        coordinates = [np.array([float(i)]) for i in range(4)]
        run_tasks(client, payloads, lambda i, r: rows.update({i: r["row"]}), coordinates=coordinates)
    # the head's certain starts (cold + random start 1, random start 2) ran as two dask tasks on the two workers
    shares = [t for t in stream.data if str(t["key"]).startswith("starts-")]
    assert len(shares) == 2 and len({t["worker"] for t in shares}) == 2
    head = next(i for i, r in rows.items() if r["start"] != "warm start from init")
    single = solve_direct(Problem.from_dict(payloads[head]["problem"]))
    # the same optimum as one process solving every start (Ipopt tol 1e-9; the workers may run compiled kernels)
    assert rows[head]["cost"] == pytest.approx(single.cost, rel=1e-9)
    # its three starts' iterations, summed over both workers (a kernel rounding apart may cost an iteration)
    assert rows[head]["iterations"] == pytest.approx(sum(s.iterations for s in single.homotopy), abs=3)
    assert sum(r["start"] == "warm start from init" for r in rows.values()) == 3


def test_invalid_parameter_path_fails_before_running(tmp_path, capsys):
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(small_base()))
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump({"base": "base.yaml", "vary": {"cost.alhpa": [0.1, 0.2]}}))
    out = tmp_path / "out"
    assert cli.main(["sweep", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "cost.alhpa" in err and "did you mean 'alpha'" in err and str(path) in err
    assert not out.exists()


def test_invalid_parameter_value_fails_before_running(tmp_path, capsys):
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(small_base()))
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump({"base": "base.yaml", "vary": {"cost.alpha": [0.1, -1.0]}}))
    assert cli.main(["sweep", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "task 1" in err and "cost.alpha" in err and "> 0" in err
    assert not (tmp_path / "out").exists()


def test_multistart_reports_optima(tmp_path, capsys):
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump(small_base()))
    out = tmp_path / "out"
    assert (
        cli.main(["solve", str(path), "--multistart", "3", "--workers", "2", "--out", str(out), "--no-plot", "--quiet"])
        == 0
    )
    summary = json.loads((out / "summary.json").read_text())
    multistart = summary["multistart"]
    assert multistart["starts"] == 3 and multistart["converged"] >= 1
    assert sum(len(g["starts"]) for g in multistart["optima"]) == multistart["converged"]
    single = solve_direct(Problem.from_dict(small_base()))
    assert summary["cost"] <= single.cost * (1 + 1e-8)  # the best of several starts is never worse
    # the plan returned is checked as a single solve's is: its J re-integrated (ocp/direct/plan_check.py)
    assert abs(summary["plan_check"]["cost"] - summary["cost"]) <= 1e-5 * summary["cost"]


def test_timed_out_task_is_a_row_with_its_error():
    slow = small_base()
    # seconds per Ipopt solve: every start stops at once (1e-3 s let a fast machine finish a step now and then)
    slow["solver"]["time_limit"] = 1e-9
    rows = {}
    with open_client(None, 1) as client:
        run_tasks(client, [{"problem": slow}, {"problem": small_base()}], lambda i, r: rows.update({i: r["row"]}),
                  warm_start=False)
    assert rows[0]["status"] == "failed" and "Maximum_WallTime_Exceeded" in rows[0]["error"]
    # no start converged: the cold solve's failure is reported (tests/ocp/test_strategy.py), not "converged"
    assert rows[0]["error"].startswith("Ipopt returned Maximum_WallTime_Exceeded at ε = 1; last ε solved = 0")
    assert rows[1]["status"] == "solved"


def test_sweep_of_a_field_problem_uses_the_shooting_method(tmp_path):
    from short_runs import field_problem

    from mobisense.ocp.field_solve import solve_shooting

    base = field_problem(shooting={"intervals": 20, "coarse_intervals": 10})
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(base))
    spec = {"base": "base.yaml", "mode": "grid", "vary": {"cost.alpha": [0.02, 0.05]}}
    (tmp_path / "sweep.yaml").write_text(yaml.safe_dump(spec))
    out = tmp_path / "out"
    assert cli.main(["sweep", str(tmp_path / "sweep.yaml"), "--out", str(out), "--workers", "1", "--quiet"]) == 0
    rows = pd.read_parquet(out / "results.parquet")
    assert set(rows["status"]) == {"solved"}
    for _, row in rows.iterrows():
        base["cost"]["alpha"] = row["cost.alpha"]
        assert row["cost"] == pytest.approx(solve_shooting(Problem.from_dict(base)).cost, rel=1e-12)  # same solve


def test_a_sweep_with_a_task_not_solved_exits_1_and_keeps_every_row(tmp_path, capsys):
    # like solve: exit 1 when a solve did not converge (here: a wall-time limit no solve can meet), the rows kept
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(small_base()))
    spec = {"base": "base.yaml", "mode": "grid", "vary": {"solver.time_limit": [1e-9, 1000.0]}}
    (tmp_path / "sweep.yaml").write_text(yaml.safe_dump(spec))
    out = tmp_path / "out"
    assert cli.main(["sweep", str(tmp_path / "sweep.yaml"), "--out", str(out), "--workers", "1", "--quiet",
                     "--no-plot"]) == 1  # fmt: skip
    assert f"1 of 2 tasks not solved (1 failed, 0 errors; their rows give the reason) in {out}" in (
        capsys.readouterr().err
    )
    rows = pd.read_parquet(out / "results.parquet").sort_values("index")
    assert list(rows["status"]) == ["failed", "solved"]


def test_results_store_keeps_integers_beyond_two_to_the_53_among_floats(tmp_path):
    """A varied value 9007199254740993 (2^53 + 1) among floats: pyarrow refused to store it in the float64 column
    (ArrowInvalid, an internal error after the first part file was written). It is stored as the double the
    problem itself was given, 2^53 exactly, and an integer beyond the largest double is no number column."""
    from mobisense.ocp.batch.results_store import ResultStore, value_kind

    big = 2**53 + 1
    kinds = {"cost.alpha": value_kind([big, 0.004]), "sensors[0].p0": value_kind([[big, 10.0], [1.5, 2.0]])}
    assert kinds == {"cost.alpha": "float64", "sensors[0].p0": "list"}
    assert value_kind([10**400, 0.5]) == "json"  # not a double: kept exactly, as JSON text
    store = ResultStore(tmp_path, kinds)
    base = {"task": "t0", "index": 0, "status": "solved", "cost": 1.0}
    store.append([{**base, "cost.alpha": big, "sensors[0].p0": [big, 10.0]}])
    row = store.read()["t0"]
    assert row["cost.alpha"] == float(big) == 2.0**53 and row["sensors[0].p0"] == [2.0**53, 10.0]


def test_results_written_before_the_later_columns_existed_read_with_them_empty(tmp_path):
    """A sweep folder of an earlier version (no ``solution_file``, no ``warning`` column) resumes: its rows read
    with those columns None, and new rows are appended beside them."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    from mobisense.ocp.batch.results_store import ResultStore

    store = ResultStore(tmp_path, {"cost.alpha": "float64"})
    old = [f for f in store.schema if f.name not in ("solution_file", "warning")]
    store.path.mkdir(parents=True)
    row = {f.name: None for f in old} | {"task": "t0", "index": 0, "cost.alpha": 0.004, "status": "solved"}
    pq.write_table(pa.Table.from_pylist([row], schema=pa.schema(old)), store.path / "part-000001.parquet")
    store.append([{"task": "t1", "index": 1, "cost.alpha": 0.008, "status": "solved", "warning": "w"}])
    rows = store.read()
    assert rows["t0"]["warning"] is None and rows["t0"]["solution_file"] is None and rows["t0"]["cost.alpha"] == 0.004
    assert rows["t1"]["warning"] == "w"


def test_an_unencrypted_remote_scheduler_is_warned_about_once_it_answers(monkeypatch, caplog):
    """The warning about plain tcp:// to another host used to be printed while the options were checked, so an
    address that then failed to connect gave two lines; now open_client logs it after the scheduler answered."""
    import logging

    from dask.distributed import LocalCluster

    from mobisense.ocp.batch import engine
    from mobisense.ocp.batch.cluster import insecure_warning

    assert insecure_warning("tcp://10.1.2.3:8786").startswith("--scheduler tcp://10.1.2.3:8786 is not encrypted")
    for quiet in ("tls://10.1.2.3:8786", "tcp://127.0.0.1:8786", "tcp://localhost:8786", "inproc://x"):
        assert insecure_warning(quiet) is None
    assert insecure_warning("tcp://10.1.2.3:8786", security=object()) is None
    with LocalCluster(n_workers=0, processes=False, dashboard_address=None) as cluster:
        monkeypatch.setattr(engine, "insecure_warning", lambda address, security=None: f"{address} is plain")
        with caplog.at_level(logging.WARNING, logger="mobisense"), engine.open_client(cluster.scheduler_address, None):
            pass
    said = [r.getMessage() for r in caplog.records if r.name == "mobisense"]  # (dask logs its own)
    assert said == [f"{cluster.scheduler_address} is plain"]


def test_a_sweep_reports_the_warnings_solve_would_print_for_each_task(tmp_path, capsys):
    # a task whose plan breaks a path constraint between the nodes was a silent "solved" row; keep_out.yaml on
    # K = 12 flies through the reef's corner (solve warns: 2.9 % of its size). The check here is independent:
    # the task's controls flown by scipy and the depth into the convex polygon from its edges, maximised by scipy.
    from reference_problems import PROBLEMS
    from scipy.integrate import solve_ivp
    from scipy.optimize import minimize_scalar

    base = yaml.safe_load((PROBLEMS / "keep_out.yaml").read_text())
    base["solver"]["collocation"]["intervals"] = 12
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(base))
    spec = {"base": "base.yaml", "mode": "grid", "vary": {"cost.alpha": [0.004, 0.0041]}}
    (tmp_path / "sweep.yaml").write_text(yaml.safe_dump(spec))
    out = tmp_path / "out"
    assert cli.main(["sweep", str(tmp_path / "sweep.yaml"), "--out", str(out), "--workers", "1", "--quiet",
                     "--no-plot"]) == 0  # fmt: skip
    expected = "mobisense: warning: 2 of 2 solved tasks have warnings (column 'warning' of results.parquet); task #0: "
    assert expected in capsys.readouterr().err
    rows = pd.read_parquet(out / "results.parquet").sort_values("index")
    assert json.loads((out / "summary.json").read_text())["counts"]["warned"] == 2
    polygon = np.array(base["constraints"]["keep_out"][1]["polygon"], float)  # counter-clockwise
    edges = [(a, np.array([b[1] - a[1], a[0] - b[0]]) / np.linalg.norm(b - a))  # (a vertex, outward normal)
             for a, b in zip(polygon, np.roll(polygon, -1, axis=0), strict=True)]  # fmt: skip
    x, y = polygon.T
    size = np.sqrt(0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))  # √area (shoelace)
    for _, row in rows.iterrows():
        assert row["warning"].startswith("the plan's controls, flown, break ") and "keep_out[1] by " in row["warning"]
        solution = Solution.load(out / row["solution_file"], task=int(row["index"]))
        control = solution.sample  # the collocation's own control polynomials

        flown = solve_ivp(lambda t, y, control=control: np.concatenate([y[2:], control(t).u[0, 0]]), (0.0, 10.0),
                          np.r_[10.0, 10.0, 0.0, -2.0], rtol=1e-11, atol=1e-11, max_step=10.0 / 12 / 6,
                          dense_output=True).sol  # fmt: skip

        def depth(t, flown=flown):
            return float(np.min([(a - flown(t)[:2]) @ n for a, n in edges]))  # > 0: inside every edge

        times = np.linspace(0.0, 10.0, 2001)
        peak = times[np.argmax([depth(t) for t in times])]
        best = minimize_scalar(lambda t, depth=depth: -depth(t), bounds=(peak - 0.01, peak + 0.01),
                               method="bounded", options={"xatol": 1e-10})  # fmt: skip
        reported = solution.stats["constraints"]["keep_out[1]"]
        assert -best.fun > 0.01 * size  # beyond the solve's PATH_TOLERANCE: 1 % of √area
        # the report's refined maximum against scipy's (integration tolerance 1e-11, Brent to 1e-10 in t)
        assert reported["max_violation"] == pytest.approx(-best.fun, rel=1e-6)
        assert reported["max_violation_time"] == pytest.approx(best.x, abs=1e-6)


def test_a_resumed_sweep_solves_again_the_tasks_whose_solution_files_were_lost(tmp_path, capsys):
    # a part file deleted, truncated or replaced by a link since the sweep ran: the resume reported every task
    # done (exit 0, "resumed: 2") while results.parquet named files a replay could not read (red team)
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(hussein2008(collocation={"intervals": 20})))
    spec = {"base": "base.yaml", "mode": "grid", "vary": {"cost.alpha": [0.004, 0.008]}}
    (tmp_path / "sweep.yaml").write_text(yaml.safe_dump(spec))
    out = tmp_path / "out"
    args = ["sweep", str(tmp_path / "sweep.yaml"), "--out", str(out), "--workers", "1", "--quiet", "--no-plot"]
    assert cli.main(args) == 0
    first = pd.read_parquet(out / "results.parquet").sort_values("index")
    for damage in ("truncate", "link", "delete"):
        part = out / first["solution_file"].iloc[0]
        if damage == "truncate":
            part.write_bytes(part.read_bytes()[:100])
        elif damage == "link":
            part.unlink()
            part.symlink_to("/etc/hostname")
        else:
            part.unlink()
        capsys.readouterr()
        assert cli.main(args) == 0
        err = capsys.readouterr().err
        assert "2 finished task(s) of" in err and "lost their solutions" in err and "solving them again" in err
        rows = pd.read_parquet(out / "results.parquet").sort_values("index")
        assert json.loads((out / "summary.json").read_text())["counts"]["resumed"] == 0
        for _, row in rows.iterrows():  # every row's solution readable again, and the same optimum
            solution = Solution.load(out / row["solution_file"], task=int(row["index"]))
            assert solution.cost == pytest.approx(first["cost"].iloc[int(row["index"])], rel=1e-9)
        first = rows
    capsys.readouterr()
    assert cli.main(args) == 0 and "lost" not in capsys.readouterr().err  # nothing lost: nothing solved again


def test_a_damaged_results_fragment_is_named_with_its_reason_cut_at_a_word(tmp_path):
    # pyarrow's reason was cut at 100 characters mid-sentence ("… Parquet magic bytes not)") (red team)
    from mobisense.ocp.batch.results_store import ResultStore

    store = ResultStore(tmp_path, {"cost.alpha": "float64"})
    store.path.mkdir(parents=True)
    (store.path / "part-000001.parquet").write_bytes(b"\0" * 4096)
    with pytest.raises(ConfigError) as err:
        store.read()
    reason = str(err.value).split("not a readable results fragment (", 1)[1].split("); delete it", 1)[0]
    assert len(reason) <= 100 and (reason.endswith(" …") or "magic bytes not found" in reason)


def test_a_sweep_reached_again_by_a_worker_importing_the_script_says_to_guard_it(tmp_path) -> None:
    # first-hour audit: a script calling ms.sweep at its top level made every spawned worker call it again; the user
    # saw "--out …: is in use by another mobisense run" and "Nanny failed to start". The worker's import runs the
    # script as module "__mp_main__": simulated here by running the call with that module name
    import mobisense as ms

    script = "ms.sweep(path, out, workers=2)"
    namespace = {"__name__": "__mp_main__", "ms": ms, "path": "sweep_hussein2008", "out": str(tmp_path / "out")}
    with pytest.raises(RuntimeError, match=r'put the call under `if __name__ == "__main__":`'):
        exec(compile(script, "user_script.py", "exec"), namespace)
    assert not (tmp_path / "out").exists()  # refused before the output folder's lock
    namespace["__name__"] = "__main__"  # the guarded parent process gets past the check (to the folder's checks)
    from mobisense.ocp.batch.engine import refuse_in_a_worker_import

    exec(compile("refuse_in_a_worker_import()", "user_script.py", "exec"),
         {**namespace, "refuse_in_a_worker_import": refuse_in_a_worker_import})  # fmt: skip
