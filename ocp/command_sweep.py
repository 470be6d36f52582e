"""Run a parameter sweep on dask (local processes or a cluster); resumable, results in results.parquet."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

__all__ = ["add_arguments", "run", "RESULT_COLUMNS"]

#: columns of results.parquet after the task id, index and one column per varied key path
RESULT_COLUMNS = [
    "status",
    "cost",
    "terminal_cost",
    "running_cost",
    "iterations",
    "time_s",
    "solve_time_s",
    "worker",
    "error",
    "start",
    "transcription_cached",
]
DONE = ("solved", "failed")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``sweep`` arguments."""
    parser.add_argument("sweep", type=Path, help="sweep YAML file (base problem, mode, vary)")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default out/<sweep name>)")
    parser.add_argument("--scheduler", default=None, help="address of a running dask scheduler (tcp://…)")
    parser.add_argument("--workers", type=int, default=None, help="local worker processes (default: one per core)")
    parser.add_argument("--no-warm-start", action="store_true", help="solve every task from the coasting guess")
    parser.add_argument(
        "--time-limit",
        type=float,
        default=None,
        metavar="S",
        help="wall-clock limit of each Ipopt solve of a task (sets solver.time_limit)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress display")


def _read_existing(path: Path) -> list[dict[str, Any]]:
    import pandas as pd

    return pd.read_parquet(path).to_dict("records") if path.exists() else []


def _write_rows(path: Path, rows: list[dict[str, Any]]) -> None:
    import pandas as pd

    from ocp.files import atomic_path

    frame = pd.DataFrame(sorted(rows, key=lambda r: r["index"]))
    with atomic_path(path) as tmp:
        frame.to_parquet(tmp, index=False)


def run(args: argparse.Namespace) -> int:
    """Validate the whole sweep, then run the tasks not finished before; write rows as they complete."""
    from ocp.engine import open_client, run_tasks
    from ocp.files import write_json, write_netcdf
    from ocp.sweep import expand_sweep, load_sweep
    from ocp.sweep_report import SweepProgress, sweep_summary

    spec, base = load_sweep(args.sweep)
    if args.time_limit is not None:
        base = base.with_solver(time_limit=args.time_limit)
    tasks = expand_sweep(spec, base, source=str(args.sweep))  # ConfigError -> exit 2, nothing run or written
    out = args.out if args.out is not None else Path("out") / args.sweep.stem
    results_path = out / "results.parquet"
    previous = {r["task"]: r for r in _read_existing(results_path)}
    rows = {t: r for t, r in previous.items() if r["status"] in DONE}
    todo = [t for t in tasks if t.task not in rows]
    progress = SweepProgress(len(tasks), len(tasks) - len(todo), quiet=args.quiet)

    def on_result(i: int, result: dict[str, Any]) -> None:
        task = todo[i]
        row = {"task": task.task, "index": task.index, **task.values}
        row.update({c: None for c in RESULT_COLUMNS})
        row.update(result["row"])
        if "dataset" in result:
            write_netcdf(out / "tasks" / f"{task.index:04d}_{task.task}" / "solution.nc", result["dataset"])
        rows[task.task] = row
        _write_rows(results_path, list(rows.values()))
        progress.advance(row)

    with progress:
        if todo:
            with open_client(args.scheduler, args.workers) as client:
                run_tasks(
                    client,
                    [{"problem": t.problem} for t in todo],
                    on_result,
                    [t.structure for t in todo],
                    [t.coordinates() for t in todo],
                    warm_start=not args.no_warm_start,
                )
    summary = sweep_summary(spec, tasks, list(rows.values()), resumed=len(tasks) - len(todo))
    write_json(out / "summary.json", summary)
    progress.report(summary, out)
    return 0 if summary["counts"]["error"] == 0 else 1
