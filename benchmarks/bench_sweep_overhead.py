"""Warm-started sweeps through the command's path (``run_sweep``): parallel speed-up and per-task overhead.

    .venv/bin/python benchmarks/bench_sweep_overhead.py [--workers 2]

The 40 tasks of ``bench_sweep.py`` (8 α × 5 start positions of the default problem, K = 60) as a sweep file,
run by :func:`mobisense.ocp.batch.run_sweep` on a LocalCluster (warm starts from the nearest finished task,
solution files written by the client, rows appended in batches), against the same work serially in this
process: each task warm-started from the nearest finished one, solved and its solution file written.

Targets (issue 14): a warm-started sweep ≥ 1.6× serial on 2 workers (cluster start-up excluded, printed
separately) and per-task overhead ≤ 3 ms, where overhead = (workers × wall − Σ Ipopt time) / tasks: every
worker-second not spent in Ipopt (validation, baseline, solution assembly, file write, dask round trip,
idle), per task.
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

from mobisense.core.files import write_netcdf
from mobisense.ocp.batch import nearest_seed, open_client, run_sweep, solve_task

ALPHAS = [float(a) for a in np.geomspace(0.001, 0.02, 8)]
ROOT = Path(__file__).resolve().parent.parent


def hussein2008(collocation: dict) -> dict:
    """The shipped default problem (problems/hussein2008.yaml) with collocation options replaced."""
    data = yaml.safe_load((ROOT / "problems" / "hussein2008.yaml").read_text())
    data["solver"]["collocation"].update(collocation)
    return data


STARTS = [[float(14.14 * np.cos(np.deg2rad(45 + a))), float(14.14 * np.sin(np.deg2rad(45 + a)))]
          for a in np.linspace(-60, 60, 5)]  # fmt: skip


def write_sweep(folder: Path) -> Path:
    (folder / "base.yaml").write_text(yaml.safe_dump(hussein2008(collocation={"intervals": 60})))
    sweep = {"base": "base.yaml", "mode": "grid", "vary": {"cost.alpha": ALPHAS, "sensors[0].p0": STARTS}}
    (folder / "sweep.yaml").write_text(yaml.safe_dump(sweep))
    return folder / "sweep.yaml"


def serial(folder: Path) -> tuple[float, list[dict]]:
    """The same tasks in this process: warm start from the nearest finished, solve, write the file."""
    items = []
    for alpha in ALPHAS:
        for j, p0 in enumerate(STARTS):
            data = hussein2008(collocation={"intervals": 60})
            data["cost"]["alpha"], data["sensors"][0]["p0"] = alpha, p0
            items.append((data, np.array([np.log(alpha) / np.ptp(np.log(ALPHAS)), j / 4])))
    seeds, rows = [], []
    t0 = time.perf_counter()
    for i, (data, coords) in enumerate(items):
        seed = nearest_seed(seeds, None, coords)
        result = solve_task({"problem": data, "seed": seed})
        write_netcdf(folder / f"{i:04d}" / "solution.nc", result["dataset"])
        if result["nlp"] is not None:
            seeds.append((None, coords, result["nlp"]))
        rows.append(result["row"])
    return time.perf_counter() - t0, rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    print(f"load average before: {os.getloadavg()[0]:.2f} (2 cores)")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        path = write_sweep(tmp)
        solve_task({"problem": hussein2008(collocation={"intervals": 60})})  # imports and the first build
        t_serial, rows_serial = serial(tmp / "serial")
        t0 = time.perf_counter()
        with open_client(None, args.workers):
            pass
        startup = time.perf_counter() - t0
        t0 = time.perf_counter()
        result = run_sweep(path, tmp / "sweep", workers=args.workers, warm_start=True)
        wall = time.perf_counter() - t0 - startup
        rows = result.table.to_dict("records")
        n = len(rows)
        assert all(r["status"] == "solved" for r in rows + rows_serial), "a task did not solve"
        assert len(list((tmp / "sweep" / "tasks").glob("*/solution.nc"))) == n
        costs = dict(zip(sorted(r["cost"] for r in rows), sorted(r["cost"] for r in rows_serial), strict=True))
        spread = max(abs(a - b) / abs(b) for a, b in costs.items())
    ipopt = sum(r["solve_time_s"] for r in rows)
    warm = sum(r["start"] == "warm start from init" for r in rows)
    overhead = (args.workers * wall - ipopt) / n
    serial_overhead = (t_serial - sum(r["solve_time_s"] for r in rows_serial)) / n
    speedup = t_serial / wall
    print(f"{n} tasks, K = 60; sorted costs of the two runs agree to {spread:.1e} relative (different warm starts)")
    print(f"  serial, one process (solve + file per task)   {t_serial:6.2f} s   "
          f"overhead {1e3 * serial_overhead:6.1f} ms/task")  # fmt: skip
    print(f"  run_sweep, {args.workers} local workers, warm starts     {wall:6.2f} s   "
          f"(+ {startup:.2f} s cluster start-up; {warm}/{n} tasks warm-started)")  # fmt: skip
    outside = statistics.median(r["time_s"] - r["solve_time_s"] for r in rows)
    print(f"  per task: Ipopt {1e3 * ipopt / n:.1f} ms; on the worker outside Ipopt (validation, baseline, "
          f"assembly; file write not included) {1e3 * outside:.1f} ms (median)")  # fmt: skip
    print(f"{'PASS' if speedup >= 1.6 else 'MISS'}  warm-started sweep vs serial on {args.workers} workers: "
          f"{speedup:.2f}x (target >= 1.6x, cluster start-up excluded)")
    print(f"{'PASS' if overhead <= 3e-3 else 'MISS'}  per-task overhead: {1e3 * overhead:.1f} ms (target <= 3 ms)")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
