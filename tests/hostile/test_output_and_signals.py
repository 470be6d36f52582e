"""Hostile output folders, concurrent writers, full disks and signals: nothing lost, nothing half-written.

- ``--out`` that cannot be used (a file, under a file, a dangling symbolic link, ``/proc``, read-only) → exit 2
  before any work, nothing created;
- a second writer into a locked folder → exit 2 naming the holder's pid;
- temporary files and locks of a run killed with SIGKILL → removed by the next run;
- a full disk (a small tmpfs, where this machine allows ``mount``) → exit 1, the previous files intact;
- SIGINT / SIGTERM → exit 130 and one line; SIGKILL then re-run → a complete result, no temporary file.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from hostile.harness import GOOD, RECORD, Outcome, attack, classify, finish, start, temporaries
from hostile.inputs import KINDS, small_problem
from reference_problems import PROBLEMS

pytestmark = pytest.mark.slow  # each case starts a Python process (~1 s); some solve or sweep for seconds

WRITERS = [k for k, kind in KINDS.items() if kind.writes]


def _bad_outs(tmp_path: Path) -> dict[str, tuple[Path, str]]:
    (tmp_path / "a_file").write_text("x")
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    return {
        "an existing file": (tmp_path / "a_file", "not a folder"),
        "a path under a file": (tmp_path / "a_file" / "out", "which is a file"),
        "a dangling symbolic link": (tmp_path / "dangling", "symbolic link"),
        "/proc": (Path("/proc/self/mobisense_out"), "virtual file system"),
    }


@pytest.mark.parametrize("where", ["an existing file", "a path under a file", "a dangling symbolic link", "/proc"])
@pytest.mark.parametrize("kind_name", WRITERS)
def test_unusable_out_is_refused_before_any_work(tmp_path, kind_name, where):
    kind = KINDS[kind_name]
    path = kind.write(tmp_path)
    out, words = _bad_outs(tmp_path)[where]
    before = sorted(p.name for p in tmp_path.iterdir())
    outcome = attack(kind.name, kind.command(path, out), tmp_path, 2, ("--out", words), None, limit=30)
    assert outcome.verdict in GOOD, outcome.problems
    assert outcome.seconds < 10  # checked before any work (the interpreter and the imports take ~1 s)
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def _mount_tmpfs(path: Path, size: str, read_only: bool = False) -> None:
    path.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)], capture_output=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({done.stderr.decode(errors='replace').strip()[:80]})")
    if read_only:
        subprocess.run(["mount", "-o", "remount,ro", str(path)], check=True)


@pytest.fixture()
def tmpfs(tmp_path):
    mounted: list[Path] = []

    def make(name: str, size: str, read_only: bool = False) -> Path:
        path = tmp_path / name
        _mount_tmpfs(path, size, read_only)
        mounted.append(path)
        return path

    yield make
    for path in mounted:
        subprocess.run(["umount", "-l", str(path)], capture_output=True)


@pytest.mark.parametrize("kind_name", ["solve", "sweep", "simulate distributed"])
def test_read_only_out_is_refused(tmp_path, tmpfs, kind_name):
    kind = KINDS[kind_name]
    path = kind.write(tmp_path)
    disk = tmpfs("ro", "1m", read_only=True)
    outcome = attack(kind.name, kind.command(path, disk / "out"), tmp_path, 2, ("--out", "not writable"), None)
    assert outcome.verdict in GOOD, outcome.problems


def test_full_disk_keeps_the_previous_result(tmp_path, tmpfs):
    kind = KINDS["solve"]
    path = kind.write(tmp_path)
    disk = tmpfs("disk", "3m")
    out = disk / "out"
    first = attack("solve", kind.command(path, out), tmp_path, 0, (), out)
    assert first.verdict in GOOD, first.problems
    digest = hashlib.sha256((out / "solution.nc").read_bytes()).hexdigest()
    filler = os.open(disk / "filler", os.O_WRONLY | os.O_CREAT)
    for chunk in (65536, 4096, 1):  # fill the disk to the last byte
        try:
            while True:
                os.write(filler, b"\0" * chunk)
        except OSError:
            pass
    os.close(filler)
    second = attack("solve", kind.command(path, out), tmp_path, 1, ("No space left on device", "unchanged"), out)
    assert second.verdict in GOOD, second.problems
    assert hashlib.sha256((out / "solution.nc").read_bytes()).hexdigest() == digest
    assert temporaries(disk) == []


def test_second_writer_is_refused_naming_the_holder(tmp_path):
    kind = KINDS["solve"]
    path = kind.write(tmp_path)
    out = tmp_path / "out_locked"
    out.mkdir()
    holder = subprocess.Popen(["sleep", "60"])
    lock = os.open(out / ".mobisense.lock", os.O_RDWR | os.O_CREAT)
    try:
        fcntl.flock(lock, fcntl.LOCK_EX)
        os.write(lock, f"{holder.pid}\n".encode())
        outcome = attack("solve", kind.command(path, out), tmp_path, 2, ("in use by another mobisense run",
                                                                           f"pid {holder.pid}"), None,
                         others=(out / ".mobisense.lock",))  # fmt: skip
        assert outcome.verdict in GOOD, outcome.problems
        assert not (out / "solution.nc").exists()
    finally:
        os.close(lock)
        holder.kill()
        holder.wait()


def test_two_concurrent_solves_into_one_folder(tmp_path):
    kind = KINDS["solve"]
    data = small_problem()
    data["solver"]["collocation"]["intervals"] = 200
    path = kind.write(tmp_path, data)
    out = tmp_path / "shared"
    first = start(kind.command(path, out), tmp_path)
    deadline = time.monotonic() + 30
    while not (out / ".mobisense.lock").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    second = attack("solve", kind.command(path, out), tmp_path, 2, ("in use by another mobisense run",), None,
                    others=(out / ".mobisense.lock",))
    code, _, err, _ = finish(first, 120)
    assert second.verdict in GOOD, second.problems
    assert code == 0, err
    assert temporaries(tmp_path) == []


def test_stale_temporaries_of_a_killed_run_are_removed(tmp_path):
    kind = KINDS["solve"]
    path = kind.write(tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    (out / ".solution.nc.k2j4h5g6.tmp").write_bytes(b"half a file")
    (out / ".mobisense.lock").write_text("99999999\n")  # its holder is gone: the lock is free
    outcome = attack("solve", kind.command(path, out), tmp_path, 0, (), out)
    assert outcome.verdict in GOOD, outcome.problems
    assert (out / "solution.nc").exists() and temporaries(tmp_path) == []


def test_default_out_is_the_sanitised_file_stem(tmp_path):
    kind = KINDS["solve"]
    path = kind.write(tmp_path)
    odd = path.rename(tmp_path / "..yaml")
    outcome = attack("solve", kind.args + [str(odd)], tmp_path, 0, (), None)
    assert outcome.verdict in GOOD, outcome.problems
    assert (tmp_path / "out" / "output" / "solution.nc").exists()
    assert not (tmp_path / "solution.nc").exists()


# --------------------------------------------------------------------------------------------- signals
def _slow_problem(tmp_path: Path) -> Path:
    data = small_problem()
    data["solver"]["collocation"]["intervals"] = 400
    return KINDS["solve"].write(tmp_path, data)


def _slow_sweep(tmp_path: Path) -> Path:
    base = small_problem()
    base["solver"]["collocation"]["intervals"] = 150
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(base))
    spec = {"base": "base.yaml", "vary": {"cost.alpha": [0.001 * (i + 1) for i in range(12)]}}
    path = tmp_path / "input.yaml"
    path.write_text(yaml.safe_dump(spec))
    return path


def _interrupt(command: str, args: list[str], tmp_path: Path, sig: int, after: Path | float) -> Outcome:
    """Start, wait until ``after`` exists (or seconds), send ``sig`` (SIGINT to the group, like Ctrl-C)."""
    process = start(args, tmp_path)
    deadline = time.monotonic() + (120 if isinstance(after, Path) else after)
    while time.monotonic() < deadline and not (isinstance(after, Path) and after.exists()):
        time.sleep(0.05)
    if sig == signal.SIGINT:
        os.killpg(process.pid, sig)
    else:
        os.kill(process.pid, sig)
    code, out, err, seconds = finish(process, 60)
    return Outcome(command, code, out, err, seconds)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_solve_interrupted(tmp_path, sig):
    path = _slow_problem(tmp_path)
    out = tmp_path / "out"
    outcome = _interrupt("solve", KINDS["solve"].command(path, out), tmp_path, sig, out / ".mobisense.lock")
    outcome = classify(outcome, 130, ("interrupted",), tmp_path, None)
    RECORD["solve"][outcome.verdict] += 1
    assert outcome.verdict in GOOD, outcome.problems
    assert len(outcome.lines) == 1, outcome.stderr


@pytest.mark.parametrize(
    ("command", "example", "after"),
    [("solve", "field_mapping_10x10", 4.0), ("replay", "replay_isotherm13", 1.0)],
    ids=["field-solve", "field-replay"],
)
def test_long_runs_stop_soon_after_ctrl_c(tmp_path, command, example, after):
    """One Ipopt solve of a field takes most of its 30 s, a replay's steps call CasADi: Ctrl-C inside either
    was only recorded and both ran to the end (then exit 130 over a complete result)."""
    out = tmp_path / "out"
    outcome = _interrupt(command, [command, example, "--out", str(out)], tmp_path, signal.SIGINT, after)
    outcome = classify(outcome, 130, ("interrupted",), tmp_path, None)
    assert outcome.verdict in GOOD, outcome.problems
    # one L-BFGS iteration or one replay step, then the clean-up (the whole runs take 32 s and 8 s here)
    assert outcome.seconds < 10, outcome.seconds
    assert not out.exists()  # the folder the run created is removed: nothing half-done is left


def test_multistart_stops_soon_after_ctrl_c(tmp_path):
    """First-hour audit: Ctrl-C during --multistart took 4.3–4.5 s to exit: the cluster waited on workers inside
    their Ipopt calls. They are killed now (their results are not needed): 0.2–0.4 s measured."""
    out = tmp_path / "out"
    args = ["solve", "coupled_two_sensor", "--intervals", "200", "--out", str(out), "--multistart", "4", "--workers",
            "2", "--no-plot", "--quiet"]  # fmt: skip
    process = start(args, tmp_path)
    time.sleep(6.0)  # the workers started (≈ 2 s) and inside their starts' Ipopt calls (each several seconds)
    os.killpg(process.pid, signal.SIGINT)
    code, stdout, stderr, seconds = finish(process, 60)
    outcome = classify(Outcome("solve", code, stdout, stderr, seconds), 130, ("interrupted",), tmp_path, None)
    assert outcome.verdict in GOOD, outcome.problems
    assert len(outcome.lines) == 1, outcome.stderr  # no worker or connection tracebacks
    assert seconds < 2.5, seconds  # below the 3 s hard stop: the clean-up no longer waits on the solves


def _one_long_ipopt_call(tmp_path: Path) -> Path:
    """A direct problem solved by one Ipopt call of ≈ 14 s (n = N = 4, K = 150, strategy cold, no compiling)."""
    rng = np.random.default_rng(1)
    n = 4
    data = {
        "name": "one_long_ipopt_call",
        "horizon": {"t0": 0.0, "tf": 10.0},
        "process": {"A": (-0.3 * np.eye(n) + 0.1 * rng.standard_normal((n, n))).tolist(), "B": np.eye(n).tolist(),
                    "Q": np.eye(n).tolist(), "Sigma0": (20 * np.eye(n)).tolist(),
                    "locations": rng.uniform(-5, 5, (n, 2)).tolist()},
        "sensors": [{"name": f"s{i}", "p0": rng.uniform(-8, 8, 2).tolist(), "v0": [0.0, 0.0],
                     "noise": {"model": "quadratic_range", "beta": 1.0, "gamma": 1.0}} for i in range(4)],
        "cost": {"M": np.eye(n).tolist(), "K": np.eye(n).tolist(), "alpha": 0.1},
        "solver": {"method": "direct", "collocation": {"scheme": "radau", "degree": 3, "intervals": 150},
                   "strategy": "cold", "codegen": "off"},
    }  # fmt: skip
    return KINDS["solve"].write(tmp_path, data)


def test_ctrl_c_stops_a_long_direct_solve_within_an_iteration(tmp_path):
    """Ctrl-C during one long Ipopt call of the direct method: held until Ipopt returned (11 s more here), now
    the iteration callback stops Ipopt at its next iteration (≈ 0.14 s) and the command exits 130."""
    out = tmp_path / "out"
    path = _one_long_ipopt_call(tmp_path)
    outcome = _interrupt("solve", KINDS["solve"].command(path, out), tmp_path, signal.SIGINT, 4.0)
    outcome = classify(outcome, 130, ("interrupted",), tmp_path, None)
    assert outcome.verdict in GOOD, outcome.problems
    assert outcome.seconds < 4, outcome.seconds  # an iteration and the clean-up; the rest of the solve is ≥ 8 s
    assert not out.exists()


def _one_long_casadi_call(tmp_path: Path) -> Path:
    """A field solve whose every gradient is one CasADi call of ≈ 25 s (5 × 5 field, 150 point sensors, K = 20)."""
    data = yaml.safe_load((PROBLEMS / "field_mapping_5x5.yaml").read_text())
    grid = np.linspace(0.5, 9.5, 13)
    sensor = data["sensors"][0]
    points = [(x, y) for x in grid for y in grid][:150]
    data["sensors"] = [{**sensor, "name": f"s{i}", "p0": [float(x), float(y)]} for i, (x, y) in enumerate(points)]
    data["solver"]["shooting"] = {"intervals": 20}
    return KINDS["solve"].write(tmp_path, data)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_inside_one_long_casadi_call_ends_the_command_within_the_hard_stop_time(tmp_path, sig):
    """A Python handler runs only between bytecodes: a signal during one long CasADi gradient was held until it
    returned (here 26 s after Ctrl-C, two lines). Now the command ends HARD_STOP_SECONDS (3 s) after it, exit
    130, one line, and leaves no folder, lock or temporary file."""
    out = tmp_path / "out"
    path = _one_long_casadi_call(tmp_path)
    outcome = _interrupt("solve", KINDS["solve"].command(path, out), tmp_path, sig, 6.0)  # inside a gradient
    outcome = classify(outcome, 130, ("interrupted",), tmp_path, None)
    assert outcome.verdict in GOOD, outcome.problems
    assert len(outcome.lines) == 1, outcome.stderr
    assert outcome.seconds < 6, outcome.seconds  # 3 s and the exit; the rest of the gradient took 26 s
    assert not out.exists() and temporaries(tmp_path) == []


def test_solve_killed_then_rerun(tmp_path):
    path = _slow_problem(tmp_path)
    out = tmp_path / "out"
    killed = _interrupt("solve", KINDS["solve"].command(path, out), tmp_path, signal.SIGKILL, out / ".mobisense.lock")
    assert killed.code == -signal.SIGKILL
    outcome = attack("solve", KINDS["solve"].command(path, out), tmp_path, 0, (), out, limit=180)
    assert outcome.verdict in GOOD, outcome.problems
    assert (out / "solution.nc").exists() and temporaries(tmp_path) == []


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_sweep_interrupted_keeps_finished_rows(tmp_path, sig):
    import pandas as pd

    path = _slow_sweep(tmp_path)
    out = tmp_path / "out"
    args = ["sweep", str(path), "--out", str(out), "--workers", "2", "--quiet"]
    first_task = out / "tasks"
    outcome = _interrupt("sweep", args, tmp_path, sig, first_task)
    outcome = classify(outcome, 130, ("interrupted",), tmp_path, None)
    RECORD["sweep"][outcome.verdict] += 1
    assert outcome.verdict in GOOD, outcome.problems
    assert len(outcome.lines) == 1, outcome.stderr  # no worker tracebacks
    rows = pd.read_parquet(out / "results.parquet") if (out / "results.parquet").exists() else pd.DataFrame()
    assert len(rows) >= 1 and list(first_task.glob("part-*.nc"))  # the first flush: files and rows
    assert all((out / f).is_file() for f in rows["solution_file"])  # every row's solution was written with it
    resumed = attack("sweep", args, tmp_path, 0, (), out, limit=300)
    assert resumed.verdict in GOOD, resumed.problems
    table = pd.read_parquet(out / "results.parquet")
    assert len(table) == 12 and set(table["status"]) == {"solved"}


@pytest.mark.parametrize("after", [0.7, 0.85, 1.0, 1.2])
def test_ctrl_c_while_the_local_workers_start_prints_one_line(tmp_path, after):
    """Ctrl-C reaches the whole process group; a worker still importing dask (its first second) printed its
    KeyboardInterrupt traceback, 40–90 lines. Workers now start with SIGINT blocked. Wherever the signal lands
    (before, during or after the cluster's start on a slower machine), one line and exit status 130."""
    out = tmp_path / "out"
    args = ["sweep", str(_slow_sweep(tmp_path)), "--out", str(out), "--workers", "2", "--quiet"]
    outcome = _interrupt("sweep", args, tmp_path, signal.SIGINT, after)
    outcome = classify(outcome, 130, ("interrupted",), tmp_path, None)
    assert outcome.verdict in GOOD, outcome.problems
    assert len(outcome.lines) == 1, outcome.stderr


def test_sweep_killed_then_rerun(tmp_path):
    import pandas as pd

    path = _slow_sweep(tmp_path)
    out = tmp_path / "out"
    args = ["sweep", str(path), "--out", str(out), "--workers", "2", "--quiet"]
    killed = _interrupt("sweep", args, tmp_path, signal.SIGKILL, out / "tasks")
    assert killed.code == -signal.SIGKILL
    time.sleep(2)  # the orphaned workers notice their nanny is gone
    outcome = attack("sweep", args, tmp_path, 0, (), out, limit=300)
    assert outcome.verdict in GOOD, outcome.problems
    table = pd.read_parquet(out / "results.parquet")
    assert len(table) == 12 and table["task"].is_unique and temporaries(tmp_path) == []


@pytest.mark.parametrize("command", [["examples"], ["schema", "problem"], ["validate", "hussein2008"]],
                         ids=" ".join)  # fmt: skip
def test_closed_or_full_standard_output(tmp_path, command):
    import shlex
    import sys

    environment = {k: v for k, v in os.environ.items() if k != "MOBISENSE_TRACEBACK"}
    line = " ".join(shlex.quote(a) for a in [sys.executable, "-m", "mobisense.cli", *command])
    # closed (>&-): what it prints is discarded, no traceback, success
    closed = subprocess.run(["sh", "-c", f"exec {line} >&-"], cwd=tmp_path, capture_output=True, text=True,
                            env=environment, timeout=60)  # fmt: skip
    assert closed.returncode == 0 and closed.stderr == "", closed.stderr
    # a full disk (/dev/full): one line, exit 1 (an output that could not be written), no internal error
    with open("/dev/full", "w") as full:
        done = subprocess.run([sys.executable, "-m", "mobisense.cli", *command], cwd=tmp_path, stdout=full,
                              stderr=subprocess.PIPE, text=True, env=environment, timeout=60)  # fmt: skip
    assert done.returncode == 1, done.stderr
    assert done.stderr.count("\n") == 1 and "No space left on device" in done.stderr and "Traceback" not in done.stderr


@pytest.mark.parametrize("redirect", ["2>&-", "2>/dev/full"], ids=["closed", "full"])
def test_unwritable_standard_error_loses_no_result(tmp_path, redirect):
    import sys

    environment = {k: v for k, v in os.environ.items() if k != "MOBISENSE_TRACEBACK"}
    out = tmp_path / "out"
    # progress and messages go to standard error: closed or on a full disk, they are lost, the solution is not
    line = f"exec {sys.executable} -m mobisense.cli solve hussein2008 --no-plot --out {out} {redirect}"
    done = subprocess.run(["sh", "-c", line], cwd=tmp_path, capture_output=True, text=True, env=environment,
                          timeout=120)  # fmt: skip
    assert done.returncode == 0 and (out / "solution.nc").is_file() and (out / "summary.json").is_file()
    assert "J (ε = 1)" in done.stdout  # the table, on standard output, is still printed
    assert "error" not in done.stdout  # messages are discarded, never printed on standard output instead
