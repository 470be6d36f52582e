"""Warm-started sweeps through the command's path (``run_sweep``): parallel speed-up and per-task overhead.

    .venv/bin/python benchmarks/bench_sweep_overhead.py [--workers 2] [--repeats 2]

The 40 tasks of ``bench_sweep.py`` (8 α × 5 start positions of the default problem, K = 60) as a sweep file,
run by :func:`mobisense.ocp.batch.run_sweep` on a LocalCluster (chains of neighbours, one per worker, each
task warm-started on its worker from its predecessor; solutions written by the client as stacked part files
with the rows), against the same work serially in this process: the same tasks in the same snake order as
one chain through the same worker function (:func:`mobisense.ocp.batch.chains.solve_in_chain`), the same
tolerances, the solutions written as the same part files. Serial and parallel runs alternate (``--repeats``
rounds); medians are compared.

Targets (issue 14): a warm-started sweep ≥ 1.6× serial on 2 workers (cluster start-up excluded, printed
separately) and per-task overhead ≤ 3 ms, where overhead = (workers × wall − Σ Ipopt time) / tasks: every
worker-second not spent in Ipopt (validation, coasting baseline, solution assembly, dask round trip, idle),
per task; its parts are printed.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

import mobisense.ocp.batch.sweep_runner as runner
from mobisense.ocp.batch import open_client, run_sweep
from mobisense.ocp.batch.chains import snake_order, solve_in_chain
from mobisense.ocp.batch.sweep import expand_sweep, load_sweep
from mobisense.ocp.task_files import write_task_files

ALPHAS = [float(a) for a in np.geomspace(0.001, 0.02, 8)]
ROOT = Path(__file__).resolve().parent.parent
STARTS = [[float(14.14 * np.cos(np.deg2rad(45 + a))), float(14.14 * np.sin(np.deg2rad(45 + a)))]
          for a in np.linspace(-60, 60, 5)]  # fmt: skip


def write_sweep(folder: Path) -> Path:
    """The 40-task sweep file (and its base problem) in ``folder``."""
    base = yaml.safe_load((ROOT / "problems" / "hussein2008.yaml").read_text())
    base["solver"]["collocation"].update(intervals=60)
    (folder / "base.yaml").write_text(yaml.safe_dump(base))
    sweep = {"base": "base.yaml", "mode": "grid", "vary": {"cost.alpha": ALPHAS, "sensors[0].p0": STARTS}}
    (folder / "sweep.yaml").write_text(yaml.safe_dump(sweep))
    return folder / "sweep.yaml"


def serial(path: Path, folder: Path) -> tuple[float, list[dict], float]:
    """The same tasks as one chain in this process, solutions written as part files: wall, rows, write time."""
    spec, base = load_sweep(path)
    t0 = time.perf_counter()
    tasks = expand_sweep(spec, base, str(path))
    rows, datasets, previous = [], [], None
    for i in snake_order([t.coordinates() for t in tasks], [t.structure for t in tasks]):
        previous = solve_in_chain({"problem": tasks[i].problem}, previous)
        rows.append({"task": tasks[i].task, "index": tasks[i].index, **previous["row"]})
        datasets.append(previous.get("dataset"))
    t1 = time.perf_counter()
    write_task_files(folder, rows, datasets)
    t2 = time.perf_counter()
    return t2 - t0, rows, t2 - t1


def parallel(path: Path, out: Path, workers: int) -> tuple[float, list[dict], float]:
    """``run_sweep`` on a LocalCluster (start-up subtracted): wall, rows, client time in file writes."""
    spent = [0.0]
    real = runner.write_task_files

    def timed(*args: object) -> None:
        t = time.perf_counter()
        real(*args)  # type: ignore[arg-type]
        spent[0] += time.perf_counter() - t

    t0 = time.perf_counter()
    with open_client(None, workers):
        pass
    startup = time.perf_counter() - t0
    runner.write_task_files = timed  # type: ignore[assignment]
    try:
        t0 = time.perf_counter()
        result = run_sweep(path, out, workers=workers, warm_start=True)
        wall = time.perf_counter() - t0 - startup
    finally:
        runner.write_task_files = real  # type: ignore[assignment]
    return wall, result.table.to_dict("records"), spent[0]


def main() -> None:
    """Alternate serial and parallel runs; print the medians and PASS/MISS."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    print(f"load average before: {os.getloadavg()[0]:.2f} ({os.cpu_count()} cores)")
    runs: dict[str, list[tuple[float, list[dict], float]]] = {"serial": [], "parallel": []}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        path = write_sweep(tmp)
        solve_in_chain({"problem": yaml.safe_load((tmp / "base.yaml").read_text())})  # imports, first build
        for r in range(args.repeats):
            runs["serial"].append(serial(path, tmp / f"serial{r}"))
            runs["parallel"].append(parallel(path, tmp / f"sweep{r}", args.workers))
        rows_p, rows_s = runs["parallel"][-1][1], runs["serial"][-1][1]
        files = {r["solution_file"] for r in rows_p}
        assert all((tmp / f"sweep{args.repeats - 1}" / f).is_file() for f in files)
    n = len(rows_p)
    assert all(r["status"] == "solved" for r in rows_p + rows_s), "a task did not solve"
    by_task = {r["task"]: r["cost"] for r in rows_s}
    spread = max(abs(r["cost"] - by_task[r["task"]]) / abs(by_task[r["task"]]) for r in rows_p)
    t_serial = statistics.median(w for w, _, _ in runs["serial"])
    wall = statistics.median(w for w, _, _ in runs["parallel"])
    ipopt = sum(r["solve_time_s"] for r in rows_p) / n
    outside = sum(r["time_s"] - r["solve_time_s"] for r in rows_p) / n
    writes = statistics.median(s for _, _, s in runs["parallel"]) / n
    overhead = args.workers * wall / n - ipopt
    serial_overhead = t_serial / n - sum(r["solve_time_s"] for r in rows_s) / n
    speedup = t_serial / wall
    warm = sum(r["start"] == "warm start from init" for r in rows_p)
    print(f"{n} tasks, K = 60; per-task costs of the two runs agree to {spread:.1e} relative")
    print(f"  serial, one chain in this process (+ part files)  {t_serial:6.2f} s   "
          f"overhead {1e3 * serial_overhead:6.1f} ms/task")  # fmt: skip
    print(f"  run_sweep, {args.workers} local workers, chains          {wall:6.2f} s   "
          f"({warm}/{n} tasks warm-started; cluster start-up excluded)")  # fmt: skip
    print(f"  per task: Ipopt {1e3 * ipopt:.1f} ms; overhead {1e3 * overhead:.1f} ms = on the worker outside Ipopt "
          f"(validation, baseline, assembly, dataset) {1e3 * outside:.1f} ms + client file writes {1e3 * writes:.1f} ms "
          f"(of the client's time, overlapping) + dask and idle {1e3 * (overhead - outside):.1f} ms")  # fmt: skip
    print(f"{'PASS' if speedup >= 1.6 else 'MISS'}  warm-started sweep vs serial on {args.workers} workers: "
          f"{speedup:.2f}x (target >= 1.6x, cluster start-up excluded)")
    print(f"{'PASS' if overhead <= 3e-3 else 'MISS'}  per-task overhead: {1e3 * overhead:.1f} ms (target <= 3 ms)")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
