"""Sweep engine performance, measured in one run.

Prints: the speedup of a 40-task sweep (8 α × 5 start positions of the default problem, K = 60) on a dask
LocalCluster of 2 worker processes vs the same tasks serially in one process (warm: the engine's chains,
one per worker, against one chain serially; target ≥ 1.7× on 2 cores); the engine's per-task overhead; the
transcription cache's saving per task; and the warm-start saving (median solve time of warm vs cold tasks).

Usage: ``python benchmarks/bench_sweep.py``
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from mobisense import Problem
from mobisense.ocp.batch import open_client, run_tasks, solve_task
from mobisense.ocp.batch.chains import snake_order, solve_in_chain
from mobisense.ocp.direct import clear_transcription_cache, solve_direct

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the repository's tests/ package
from tests.reference_problems import hussein2008  # noqa: E402

console = Console()


def tasks() -> list[dict]:
    """40 problems: α × initial position."""
    out = []
    for alpha in np.geomspace(0.001, 0.02, 8):
        for angle in np.linspace(-60, 60, 5):
            data = hussein2008(collocation={"intervals": 60})
            data["cost"]["alpha"] = float(alpha)
            a = np.deg2rad(45 + angle)
            data["sensors"][0]["p0"] = [float(14.14 * np.cos(a)), float(14.14 * np.sin(a))]
            out.append({"problem": data, "coords": np.array([np.log(alpha), angle / 60])})
    return out


def serial(items: list[dict], warm_start: bool) -> tuple[float, list[dict]]:
    """The same tasks in this process, one after the other: warm, as one chain in the engine's snake order."""
    rows = []
    t0 = time.perf_counter()
    if warm_start:
        previous = None
        for i in snake_order([item["coords"] for item in items]):
            previous = solve_in_chain({"problem": items[i]["problem"]}, previous)
            rows.append(previous["row"])
    else:
        rows = [solve_task({"problem": item["problem"]})["row"] for item in items]
    return time.perf_counter() - t0, rows


def parallel(items: list[dict], workers: int, warm_start: bool) -> tuple[float, float, list[dict]]:
    """Cluster start-up time, sweep wall time (excluding start-up), rows."""
    rows: list[dict] = []
    t0 = time.perf_counter()
    with open_client(None, workers) as client:
        client.run(lambda: __import__("mobisense.ocp.direct.solver"))  # workers import CasADi before the clock starts
        startup = time.perf_counter() - t0
        t1 = time.perf_counter()
        run_tasks(
            client,
            [{"problem": i["problem"]} for i in items],
            lambda i, r: rows.append(r["row"]),
            coordinates=[i["coords"] for i in items],
            warm_start=warm_start,
        )
        wall = time.perf_counter() - t1
    return startup, wall, rows


def main() -> None:
    """Run and print the measurements."""
    items = tasks()
    clear_transcription_cache()
    problem = Problem.from_dict(items[0]["problem"])
    t0 = time.perf_counter()
    solve_direct(problem)
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    solve_direct(problem)
    cached = time.perf_counter() - t0
    clear_transcription_cache()

    table = Table(title="40-task sweep (default problem, K = 60), measured in this run")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    for warm in (True, False):
        clear_transcription_cache()
        serial_time, serial_rows = serial(items, warm)
        startup, wall, rows = parallel(items, 2, warm)
        busy = sum(r["time_s"] for r in rows)
        label = "warm starts from neighbours" if warm else "every task from coasting"
        table.add_row(f"[bold]{label}", "")
        table.add_row("  serial, one process", f"{serial_time:.2f} s")
        table.add_row("  LocalCluster, 2 worker processes", f"{wall:.2f} s (+ {startup:.2f} s cluster start-up)")
        table.add_row("  speedup (target ≥ 1.7)", f"{serial_time / wall:.2f}×")
        table.add_row("  engine overhead per task", f"{1000 * max(0.0, 2 * wall - busy) / len(rows):.1f} ms")
        if warm:
            for name, group in (("serial", serial_rows), ("parallel", rows)):
                w = [r["solve_time_s"] for r in group if r["start"] == "warm start from init"]
                c = [r["solve_time_s"] for r in group if r["start"] != "warm start from init"]
                if w and c:
                    table.add_row(f"  {name}: median solve warm / cold",
                                  f"{statistics.median(w):.3f} s / {statistics.median(c):.3f} s "
                                  f"({len(w)} warm, {len(c)} cold)")
        table.add_row("  all solved", str(all(r["status"] == "solved" for r in rows + serial_rows)))
    table.add_row("transcription cache saving per task", f"{first - cached:.3f} s ({first:.3f} s → {cached:.3f} s)")
    console.print(table)


if __name__ == "__main__":
    main()
