"""Warm-started sweeps through the command's path (``run_sweep``): parallel speed-up and per-task overhead.

    .venv/bin/python benchmarks/bench_sweep_overhead.py [--workers 2] [--repeats 3] [--alphas 8]

The 40 tasks of ``bench_sweep.py`` (8 α × 5 start positions of the default problem, K = 60; ``--alphas 40``:
200 tasks, where the cold head weighs less) as a sweep file, run by :func:`mobisense.ocp.batch.run_sweep` on a
LocalCluster (chains of neighbours, one per worker, two running outwards from each cold head, each task
warm-started on its worker from its predecessor; solutions written by the client as stacked part files
with the rows), against the same work serially in this process: the same tasks in the same snake order as
one chain through the same worker function (:func:`mobisense.ocp.batch.chains.solve_in_chain`), the same
tolerances, the solutions written as the same part files. This process and the workers have imported
everything and built the transcription before any clock starts; serial and parallel runs alternate
(``--repeats`` rounds); medians are compared. The head is a cold solve (≈ 15–25 × a warm task here, 200–270
iterations over its three starts), solved once per pair of chains, its starts shared by the pair's two
workers (the serial run solves them one after another), so the whole sweep's speed-up is bounded by
Amdahl's law (printed, with both heads as measured); the warm-start speed-up compares each worker's tasks after its
first with the same number of warm tasks solved serially.

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
from typing import Any

import numpy as np
import yaml

import mobisense.ocp.batch.sweep_runner as runner
from mobisense.ocp.batch import open_client, run_sweep
from mobisense.ocp.batch.chains import snake_order, solve_in_chain
from mobisense.ocp.batch.sweep import expand_sweep, load_sweep
from mobisense.ocp.task_files import write_task_files


def alphas(count: int) -> list[float]:
    """``count`` values of α, geometrically spaced over [0.001, 0.02] (8: bench_sweep.py's)."""
    return [float(a) for a in np.geomspace(0.001, 0.02, count)]
ROOT = Path(__file__).resolve().parent.parent
STARTS = [[float(14.14 * np.cos(np.deg2rad(45 + a))), float(14.14 * np.sin(np.deg2rad(45 + a)))]
          for a in np.linspace(-60, 60, 5)]  # fmt: skip


def write_sweep(folder: Path, count: int = 8) -> Path:
    """The sweep file of ``count`` α × 5 starts (and its base problem) in ``folder``."""
    base = yaml.safe_load((ROOT / "problems" / "hussein2008.yaml").read_text())
    base["solver"]["collocation"].update(intervals=60)
    (folder / "base.yaml").write_text(yaml.safe_dump(base))
    sweep = {"base": "base.yaml", "mode": "grid", "vary": {"cost.alpha": alphas(count), "sensors[0].p0": STARTS}}
    (folder / "sweep.yaml").write_text(yaml.safe_dump(sweep))
    return folder / "sweep.yaml"


def serial(path: Path, folder: Path) -> dict[str, Any]:
    """The same tasks as one chain in this process, solutions written as part files."""
    spec, base = load_sweep(path)
    cpu0, t0 = time.process_time(), time.perf_counter()
    tasks = expand_sweep(spec, base, str(path))
    rows, datasets, previous, durations = [], [], None, []
    for i in snake_order([t.coordinates() for t in tasks], [t.structure for t in tasks]):
        t = time.perf_counter()
        previous = solve_in_chain(tasks[i].payload(), previous)
        durations.append(time.perf_counter() - t)
        rows.append({"task": tasks[i].task, "index": tasks[i].index, **previous["row"]})
        datasets.append(previous.get("dataset"))
    t1 = time.perf_counter()
    write_task_files(folder, rows, datasets)
    wall = time.perf_counter() - t0
    # a warm task's share: its solve, and its part of the validation and of the file write
    warm = (wall - durations[0]) / (len(rows) - 1) if len(rows) > 1 else float("nan")
    return {"wall": wall, "rows": rows, "writes": time.perf_counter() - t1, "head": durations[0], "warm": warm,
            "cpu": time.process_time() - cpu0}  # fmt: skip


def parallel(path: Path, out: Path, client: Any) -> dict[str, Any]:
    """``run_sweep`` on the running cluster: wall, rows, client time in file writes, each worker's compute spans."""
    from dask.distributed import get_task_stream

    spent = [0.0]
    real_write = runner.write_task_files

    def timed(*args: Any) -> None:
        t = time.perf_counter()
        real_write(*args)
        spent[0] += time.perf_counter() - t

    runner.write_task_files = timed  # type: ignore[assignment]
    try:
        with get_task_stream(client) as stream:
            workers0, cpu0 = client.run(time.process_time), time.process_time()  # CPU time of each process
            t0, epoch = time.perf_counter(), time.time()
            result = run_sweep(path, out, scheduler=client.scheduler.address, warm_start=True)
            wall = time.perf_counter() - t0
            cpu_client = time.process_time() - cpu0
            cpu_workers = sorted(t - workers0[w] for w, t in client.run(time.process_time).items())
    finally:
        runner.write_task_files = real_write  # type: ignore[assignment]
    names = {address: str(info["name"]) for address, info in client.scheduler_info()["workers"].items()}
    computes: dict[str, list[tuple[float, float, str]]] = {}  # worker name (a row's "worker") -> its computes
    for task in stream.data:
        for span in task["startstops"]:
            if span["action"] == "compute":
                start, stop = span["start"] - epoch, span["stop"] - epoch
                computes.setdefault(names[task["worker"]], []).append((start, stop, task["key"]))
    return {"wall": wall, "rows": result.table.to_dict("records"), "writes": spent[0],
            "computes": {w: sorted(c) for w, c in computes.items()}, "cpu_client": cpu_client,
            "cpu_workers": cpu_workers}  # fmt: skip


def measure(client: Any, folder: Path, alphas: int, repeats: int, workers: int) -> None:
    """Alternate serial and parallel runs of the sweep of ``alphas`` × 5 tasks; print medians and PASS/MISS."""
    runs: dict[str, list[dict[str, Any]]] = {"serial": [], "parallel": []}
    path = write_sweep(folder, alphas)
    serial(path, folder / "warm-up-serial")  # one round of each off the clock: the sweep path's imports here,
    parallel(path, folder / "warm-up-sweep", client)  # the workers' first random starts
    for r in range(repeats):
        runs["serial"].append(serial(path, folder / f"serial{r}"))
        runs["parallel"].append(parallel(path, folder / f"sweep{r}", client))
    last = runs["parallel"][-1]
    assert all((folder / f"sweep{repeats - 1}" / r["solution_file"]).is_file() for r in last["rows"])
    rows_p, rows_s = last["rows"], runs["serial"][-1]["rows"]
    n, med = len(rows_p), statistics.median
    assert all(r["status"] == "solved" for r in rows_p + rows_s), "a task did not solve"
    by_task = {r["task"]: r["cost"] for r in rows_s}
    spread = max(abs(r["cost"] - by_task[r["task"]]) / abs(by_task[r["task"]]) for r in rows_p)
    t_serial, wall = med(r["wall"] for r in runs["serial"]), med(r["wall"] for r in runs["parallel"])
    head, warm_serial = med(r["head"] for r in runs["serial"]), med(r["warm"] for r in runs["serial"])
    parts: dict[str, list[float]] = {"warm": [], "gaps": [], "idle": [], "startup": [], "head": []}
    for run in runs["parallel"]:
        warm_tasks, spans, gaps, idle, startup, heads = 0, [], 0.0, 0.0, [], []
        for worker, computes in run["computes"].items():
            # a worker's head work: the shares of the cold head's starts and the head's own link (not warm)
            own = [r for r in run["rows"] if r["worker"] == worker]
            cold = {str(r["index"]) for r in own if r["start"] != "warm start from init"}
            head_end = max((stop for _, stop, key in computes if key.startswith("starts-")
                            or key.split("-")[1] in cold), default=computes[0][0])  # fmt: skip
            warm_tasks += sum(r["start"] == "warm start from init" for r in own)
            spans.append(computes[-1][1] - head_end)
            gaps += sum(max(0.0, b[0] - a[1]) for a, b in zip(computes[:-1], computes[1:], strict=True))
            idle += run["wall"] - sum(stop - start for start, stop, _ in computes)
            startup.append(computes[0][0])
            heads.append(head_end)
        parts["warm"].append(warm_tasks * warm_serial / max(spans))
        parts["gaps"].append(gaps)
        parts["idle"].append(idle - gaps)
        parts["startup"].append(min(startup))
        parts["head"].append(max(heads))
    warm_speedup = med(parts["warm"])
    ipopt = sum(r["solve_time_s"] for r in rows_p) / n
    outside = sum(r["time_s"] - r["solve_time_s"] for r in rows_p) / n
    writes = med(r["writes"] for r in runs["parallel"]) / n
    overhead = workers * wall / n - ipopt
    gaps, idle = med(parts["gaps"]) / n, med(parts["idle"]) / n
    serial_overhead = t_serial / n - sum(r["solve_time_s"] for r in rows_s) / n
    heads = sum(r["start"] != "warm start from init" for r in rows_p)
    print(f"{n} tasks, K = 60, {repeats} interleaved rounds (medians); per-task costs of the two runs agree "
          f"to {spread:.1e} relative")  # fmt: skip
    print(f"  serial, one chain in this process (+ part files)  {t_serial:6.2f} s   (cold head {head:.2f} s, then "
          f"{1e3 * warm_serial:.1f} ms per warm task; overhead {1e3 * serial_overhead:.1f} ms/task)")  # fmt: skip
    print(f"  run_sweep, {workers} workers, one chain each       {wall:6.2f} s   ({n - heads}/{n} tasks "
          f"warm-started; first task on a worker after {med(parts['startup']):.3f} s, both workers past the cold "
          f"head after {med(parts['head']):.2f} s; warm cluster, start-up excluded)")  # fmt: skip
    print("  rounds (s): serial " + " ".join(f"{r['wall']:.2f}" for r in runs["serial"]) + "; run_sweep "
          + " ".join(f"{r['wall']:.2f}" for r in runs["parallel"]))  # fmt: skip
    print(f"  per task: Ipopt {1e3 * ipopt:.1f} ms; overhead {1e3 * overhead:.1f} ms = on the worker outside Ipopt "
          f"(validation, baseline, assembly, dataset) {1e3 * outside:.1f} ms + hand-overs between links "
          f"{1e3 * gaps:.1f} ms + a worker idle (start-up, the other's cold head or longer chain, the end) "
          f"{1e3 * idle:.1f} ms + in the workers' dask tasks outside the rows' own time "
          f"{1e3 * (overhead - outside - gaps - idle):.1f} ms; client file writes {1e3 * writes:.1f} ms "
          "(client)")  # fmt: skip
    cpu_serial, cpu_client = med(r["cpu"] for r in runs["serial"]), med(r["cpu_client"] for r in runs["parallel"])
    cpu_workers = [med(r["cpu_workers"][k] for r in runs["parallel"]) for k in range(workers)]
    floor = (cpu_client + sum(cpu_workers)) / min(workers, os.cpu_count() or 1)
    print(f"  CPU time (core-s): serial run {cpu_serial:.2f}; run_sweep: client process {cpu_client:.2f} (main thread, "
          f"scheduler, nannies), workers " + " + ".join(f"{c:.2f}" for c in cpu_workers) + f" (least to most) = "
          f"{cpu_client + sum(cpu_workers):.2f} in all, {(cpu_client + sum(cpu_workers)) / cpu_serial:.2f}x the "
          f"serial run's; spread over {min(workers, os.cpu_count() or 1)} cores with no idle core it needs {floor:.2f} "
          f"s: at most {t_serial / floor:.2f}x for the work this run did (information, not a target)")  # fmt: skip
    print(f"  the engine's own work per task (all but Ipopt and idle time): {1e3 * (overhead - idle):.1f} ms "
          "(information, not the target)")
    print(f"{'PASS' if warm_speedup >= 1.6 else 'MISS'}  warm-started tasks vs serial on {workers} workers: "
          f"{warm_speedup:.2f}x (target >= 1.6x; each worker's warm tasks after its cold-head work, compute spans)")
    print(f"{'PASS' if t_serial / wall >= 1.6 else 'MISS'}  whole sweep vs serial on {workers} workers: "
          f"{t_serial / wall:.2f}x (target >= 1.6x)")
    print(f"{'PASS' if overhead <= 3e-3 else 'MISS'}  per-task overhead: {1e3 * overhead:.1f} ms (target <= 3 ms; "
          f"workers x wall - Ipopt, per task)")


def main() -> None:
    """Measure each sweep size (default 40 and 200 tasks) on one warm cluster."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--alphas", type=int, nargs="+", default=[8, 40],
        help="values of α (× 5 starts = tasks) of each sweep measured (8: the 40 tasks of bench_sweep.py)",
    )  # fmt: skip
    args = parser.parse_args()
    print(f"load average before: {os.getloadavg()[0]:.2f} ({os.cpu_count()} cores)")
    with tempfile.TemporaryDirectory() as tmp, open_client(None, args.workers) as client:
        first = {"problem": yaml.safe_load((ROOT / "problems" / "hussein2008.yaml").read_text())}
        first["problem"]["solver"]["collocation"]["intervals"] = 60
        solve_in_chain(first)  # imports and the first build, here and on every worker, before any clock
        client.run(solve_in_chain, first)
        for alphas in args.alphas:
            folder = Path(tmp) / f"alphas{alphas}"
            folder.mkdir()
            measure(client, folder, alphas, args.repeats, args.workers)
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
