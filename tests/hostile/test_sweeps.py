"""Hostile sweeps: huge grids, foreign or corrupt result folders, bad cluster options, any YAML value varied."""

from __future__ import annotations

import json
import socket
import threading

import pandas as pd
import pytest
import yaml
from hostile.harness import GOOD, attack
from hostile.inputs import small_problem

from mobisense.core.errors import ConfigError

pytestmark = pytest.mark.slow  # each case starts a Python process (~1 s); some solve for seconds


def _write(tmp_path, vary, mode="grid", base=None):
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(base or small_problem()))
    path = tmp_path / "input.yaml"
    path.write_text(yaml.safe_dump({"base": "base.yaml", "mode": mode, "vary": vary}))
    return path


def _args(path, out, *extra):
    return ["sweep", str(path), "--out", str(out), "--quiet", *map(str, extra)]


REFUSED = {
    "a 10^6-task grid": ({"cost.alpha": [0.001 * (i + 1) for i in range(1000)],
                          "horizon.tf": [5.0 + i for i in range(1000)]}, "grid", (), ("1e+06 tasks", "100000")),
    "zip of unequal lengths": ({"cost.alpha": [0.1, 0.2], "horizon.tf": [5.0]}, "zip", (), ("equal length",)),
    "a key that is not in the problem": ({"cost.alhpa": [0.1]}, "grid", (), ("cost.alhpa", "did you mean 'alpha'")),
    "a malformed key path": ({"cost..alpha": [0.1]}, "grid", (), ("cost..alpha",)),
    "an empty list of values": ({"cost.alpha": []}, "grid", (), ("at least one value",)),
    "an invalid value in one task": ({"cost.alpha": [0.1, -1.0]}, "grid", (), ("task 1", "cost.alpha")),
    "a string for a number": ({"cost.alpha": ["0.1"]}, "grid", (), ("cost.alpha", "remove the quotes")),
    "an unknown scheme": ({"solver.collocation.scheme": ["radau", "gauss"]}, "grid", (),
                          ("task 1", "solver.collocation.scheme")),
    "--workers 0": ({"cost.alpha": [0.1]}, "grid", ("--workers", "0"), ("--workers",)),
    "--workers -1": ({"cost.alpha": [0.1]}, "grid", ("--workers", "-1"), ("--workers",)),
    "--time-limit -1": ({"cost.alpha": [0.1]}, "grid", ("--time-limit", "-1"), ("--time-limit",)),
    "--scheduler refused": ({"cost.alpha": [0.1]}, "grid", ("--scheduler", "tcp://127.0.0.1:1"), ("cannot connect",)),
    "--scheduler of an unknown protocol": ({"cost.alpha": [0.1]}, "grid", ("--scheduler", "gopher://x:1"),
                                           ("unknown protocol",)),
    "--tls-cert without --scheduler": ({"cost.alpha": [0.1]}, "grid", ("--tls-cert", "input.yaml"),
                                       ("only used with --scheduler",)),
    "--workers with --scheduler": ({"cost.alpha": [0.1]}, "grid", ("--workers", "2", "--scheduler",
                                                                    "tcp://127.0.0.1:1"), ("--workers",)),
    "--max-memory 1M": ({"cost.alpha": [0.1]}, "grid", ("--max-memory", "1M"), ("too large",)),
    # a varied value that makes one task's problem huge: its structure is budgeted, not only the base's (a fuzzer's:
    # ran past 3 GiB of memory until killed)
    "one task of K = 100000": ({"solver.collocation.intervals": [20, 100000]}, "grid", ("--max-memory", "8G"),
                               ("too large", "K = 100000 intervals")),  # 52 GiB: refused whatever the RAM
    # the whole cost section: its column would be the optimal cost's (a fuzzer's: internal error from pyarrow)
    "the whole cost section": ({"cost": [{"M": [[1.0]], "alpha": 0.1}]}, "grid", (), ("vary: cost:", "cost.…")),
}  # fmt: skip


@pytest.mark.parametrize("name", list(REFUSED))
def test_refused_sweep(tmp_path, name):
    vary, mode, extra, words = REFUSED[name]
    path = _write(tmp_path, vary, mode)
    out = tmp_path / "out"
    outcome = attack("sweep", _args(path, out, *extra), tmp_path, 2, words, out, limit=60)
    assert outcome.verdict in GOOD, outcome.problems


def test_scheduler_that_accepts_and_never_answers(tmp_path):
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(8)
    accepted = []
    stop = threading.Event()

    def accept():
        listener.settimeout(0.5)
        while not stop.is_set():
            try:
                accepted.append(listener.accept()[0])
            except OSError:
                pass

    thread = threading.Thread(target=accept, daemon=True)
    thread.start()
    try:
        path = _write(tmp_path, {"cost.alpha": [0.1]})
        address = f"tcp://127.0.0.1:{listener.getsockname()[1]}"
        out = tmp_path / "out"
        outcome = attack("sweep", _args(path, out, "--scheduler", address), tmp_path, 2,
                         ("cannot connect within 10 s", "no dask handshake"), out, limit=60)  # fmt: skip
        assert outcome.verdict in GOOD, outcome.problems
        assert outcome.seconds < 30
    finally:
        stop.set()
        thread.join()
        listener.close()


def test_non_local_scheduler_that_does_not_answer_is_one_line(tmp_path):
    path = _write(tmp_path, {"cost.alpha": [0.1]})
    out = tmp_path / "out"
    # a documentation address (RFC 5737) that does not answer: exit 2 with the error alone (the warning about
    # plain tcp:// came first, a second line for a refusal; it is said once the scheduler has answered)
    outcome = attack("sweep", _args(path, out, "--scheduler", "tcp://192.0.2.1:8786"), tmp_path, 2,
                     ("cannot connect",), out, limit=60)  # fmt: skip
    assert outcome.verdict in GOOD, outcome.problems
    assert len(outcome.lines) == 1 and "not encrypted" not in outcome.stderr
    empty = attack("sweep", _args(path, out, "--scheduler", ""), tmp_path, 2, ("expected the address",), out)
    assert empty.verdict in GOOD and len(empty.lines) == 1, empty.problems


@pytest.fixture()
def finished_sweep(tmp_path):
    path = _write(tmp_path, {"cost.alpha": [0.002, 0.004]})
    out = tmp_path / "result"
    outcome = attack("sweep", _args(path, out, "--workers", "1"), tmp_path, 0, (), out, limit=300)
    assert outcome.verdict in GOOD, outcome.problems
    return path, out


def test_another_sweep_into_the_same_folder(tmp_path, finished_sweep):
    _, out = finished_sweep
    other = tmp_path / "other"
    other.mkdir()
    path = _write(other, {"cost.alpha": [0.003]})
    before = sorted(p.name for p in out.rglob("*"))
    outcome = attack("sweep", _args(path, out), other, 2, ("another sweep",), None)
    assert outcome.verdict in GOOD, outcome.problems
    assert sorted(p.name for p in out.rglob("*")) == before


def test_corrupt_results_on_resume(tmp_path, finished_sweep):
    path, out = finished_sweep
    fragment = next((out / "results.parquet").glob("part-*.parquet"))
    fragment.write_bytes(b"PAR1 this is not parquet")
    outcome = attack("sweep", _args(path, out), tmp_path, 2, (fragment.name, "not a readable results fragment"), None)
    assert outcome.verdict in GOOD, outcome.problems


def test_corrupt_manifest_on_resume(tmp_path, finished_sweep):
    path, out = finished_sweep
    (out / "sweep.json").write_text("{not json")
    outcome = attack("sweep", _args(path, out), tmp_path, 2, ("sweep.json", "manifest"), None)
    assert outcome.verdict in GOOD, outcome.problems


def test_sweep_into_a_folder_of_another_command(tmp_path):
    out = tmp_path / "result"
    out.mkdir()
    (out / "summary.json").write_text("{}")
    path = _write(tmp_path, {"cost.alpha": [0.1]})
    outcome = attack("sweep", _args(path, out), tmp_path, 2, ("not empty", "summary.json"), None)
    assert outcome.verdict in GOOD, outcome.problems


def test_any_yaml_value_can_be_varied(tmp_path):
    base = small_problem()
    base["solver"]["collocation"]["intervals"] = 15
    vary = {
        "solver.collocation.scheme": ["radau", "legendre"],
        "sensors[0].noise": [{"model": "quadratic_range", "beta": 5.0, "gamma": 3.0},
                             {"model": "quadratic_range", "beta": 2.0, "gamma": 1.0}],
        "sensors[0].name": ["left", "right"],
    }  # fmt: skip
    path = _write(tmp_path, vary, base=base)
    out = tmp_path / "out"
    outcome = attack("sweep", _args(path, out, "--workers", "2"), tmp_path, 0, (), out, limit=300)
    assert outcome.verdict in GOOD, outcome.problems
    table = pd.read_parquet(out / "results.parquet")
    assert len(table) == 8 and set(table["status"]) == {"solved"}
    assert set(table["solver.collocation.scheme"]) == {"radau", "legendre"}
    assert {json.loads(v)["beta"] for v in table["sensors[0].noise"]} == {5.0, 2.0}  # mappings stored as JSON
    assert json.loads((out / "sweep.json").read_text())["tasks"] == 8


def test_a_bad_base_problem_is_reported_under_the_sweep_files_base_key(tmp_path):
    # the base's own error came without the sweep file or its key ("/dev/zero: larger than …"), and a sweep whose
    # base is itself was told to "run it with 'mobisense sweep'", which the user had just done (red team)
    from mobisense.ocp.batch.sweep import load_sweep

    path = _write(tmp_path, {"cost.alpha": [0.1]}, base={**small_problem(), "horizon": {"t0": 0.0, "tf": -1.0}})
    with pytest.raises(ConfigError, match=rf"^{path}: base: {tmp_path / 'base.yaml'}: horizon"):
        load_sweep(path)
    path.write_text(yaml.safe_dump({"base": "input.yaml", "mode": "grid", "vary": {"cost.alpha": [0.1]}}))
    with pytest.raises(ConfigError, match=r"base: expected the base problem file, got this sweep file itself"):
        load_sweep(path)


def test_a_sweep_over_large_field_grids_is_budgeted_without_building_the_fields(tmp_path):
    # each task's structure built its field's kernel matrix and factorised it (O(n³): 3 s and 50 MB a 50 × 50
    # grid); 30 grids took 35 s and 1.4 GB before the budget refused the sweep (red team). A point sensor's one
    # row is counted without the field now.
    import time
    import tracemalloc

    from short_runs import field_problem

    from mobisense.ocp.batch.sweep import expand_sweep, load_sweep, sweep_estimates

    (tmp_path / "base.yaml").write_text(yaml.safe_dump(field_problem()))
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump({"base": "base.yaml", "mode": "grid",
                                    "vary": {"process.field.grid": [[50, 50 - k] for k in range(4)]}}))  # fmt: skip
    spec, base = load_sweep(path)
    tracemalloc.start()
    start = time.perf_counter()
    tasks = expand_sweep(spec, base, str(path))
    estimates = sweep_estimates(spec, base, 1, str(path), tasks)
    seconds, peak = time.perf_counter() - start, tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert len(tasks) == 4 and max(e.bytes for e in estimates) > 100 * 2**30  # refused by any machine's budget
    assert seconds < 2.0 and peak < 20e6  # one 2500 × 2500 kernel matrix alone is 50 MB


def test_a_task_of_its_own_structure_counts_a_whole_cold_solve_in_the_sweeps_time(tmp_path) -> None:
    # red team: vary solver.method over a 3 × 3 field: every task counted at a fifth of a cold solve, so the sweep
    # passed --max-time 10s and ran 4 min 52 s; its direct task, alone ≥ 50 s, has no neighbour to start warm from
    from short_runs import field_problem

    from mobisense.ocp.batch.sweep import WARM_SHARE, expand_sweep, load_sweep, sweep_estimates
    from mobisense.ocp.sizes import problem_estimates

    (tmp_path / "base.yaml").write_text(yaml.safe_dump(field_problem(grid=(3, 3), shooting={"intervals": 10})))
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump({"base": "base.yaml", "vary": {"solver.method": ["shooting", "direct"],
                                                                  "cost.alpha": [0.05, 0.06, 0.07]}}))  # fmt: skip
    spec, base = load_sweep(path)
    tasks = expand_sweep(spec, base, str(path))
    seconds = sweep_estimates(spec, base, 1, str(path), tasks)[-1].seconds
    alone = {method: sum(e.seconds for e in problem_estimates(base.with_solver(method=method)))
             for method in ("shooting", "direct")}  # fmt: skip
    # each method's first task cold, its two others warm: the sum, on one worker
    assert seconds == pytest.approx(sum(alone.values()) * (1 + 2 * WARM_SHARE), rel=1e-9)
    assert seconds > alone["direct"] > 10.0
