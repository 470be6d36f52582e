"""Running a sweep into a result folder: resumable, one row per task, results written as tasks finish."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .sweep import expand_sweep, load_sweep
from .sweep_report import SweepProgress, sweep_summary

__all__ = ["SweepResult", "run_sweep", "RESULT_COLUMNS"]


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
#: task statuses that are final (not re-run on resume)
DONE = ("solved", "failed")


@dataclass
class SweepResult:
    """A finished sweep: one row per task (``pandas.DataFrame``, as ``results.parquet``) and the summary."""

    table: Any
    summary: dict[str, Any]
    folder: Path

    def __repr__(self) -> str:
        c = self.summary["counts"]
        best = self.summary.get("best")
        best_text = "" if best is None else f"; best task #{best['index']} J = {best['cost']:.8g}"
        return (
            f"SweepResult({c['tasks']} tasks: {c['solved']} solved, {c['failed']} failed, {c['error']} errors"
            f"{best_text}; in {self.folder})"
        )


def run_sweep(
    path: str | Path,
    out: str | Path,
    scheduler: str | None = None,
    workers: int | None = None,
    warm_start: bool = True,
    time_limit: float | None = None,
    quiet: bool = True,
) -> SweepResult:
    """Validate a sweep file, run the tasks not finished in ``out`` before, and summarise.

    Parameters
    ----------
    path : str or Path
        The sweep YAML file (see the module docstring).
    out : str or Path
        Result folder: ``results.parquet`` (rewritten as each task finishes, so an interrupted sweep
        resumes), ``tasks/<index>_<task>/solution.nc`` and ``summary.json``.
    scheduler : str, optional
        Address of a running dask scheduler; default a local cluster of ``workers`` processes.
    workers : int, optional
        Local worker processes (default one per core).
    warm_start : bool
        Warm-start each task from the nearest finished task of the same structure.
    time_limit : float, optional
        Wall-clock limit (s) of each Ipopt solve (sets ``solver.time_limit``).
    quiet : bool
        No progress display or table.

    Raises
    ------
    ConfigError
        The sweep file, its base problem or one of its tasks is invalid (nothing is run or written).
    """
    import pandas as pd

    from ...core.files import write_json, write_netcdf
    from .engine import open_client, run_tasks

    path, out = Path(path), Path(out)
    spec, base = load_sweep(path)
    if time_limit is not None:
        base = base.with_solver(time_limit=time_limit)
    tasks = expand_sweep(spec, base, source=str(path))  # ConfigError -> nothing run or written
    results_path = out / "results.parquet"
    previous = {r["task"]: r for r in _read_existing(results_path)}
    rows = {t: r for t, r in previous.items() if r["status"] in DONE}
    todo = [t for t in tasks if t.task not in rows]
    progress = SweepProgress(len(tasks), len(tasks) - len(todo), quiet=quiet)

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
            with open_client(scheduler, workers) as client:
                run_tasks(
                    client,
                    [{"problem": t.problem} for t in todo],
                    on_result,
                    [t.structure for t in todo],
                    [t.coordinates() for t in todo],
                    warm_start=warm_start,
                )
    summary = sweep_summary(spec, tasks, list(rows.values()), resumed=len(tasks) - len(todo))
    write_json(out / "summary.json", summary)
    progress.report(summary, out)
    table = pd.DataFrame(sorted(rows.values(), key=lambda r: r["index"]))
    return SweepResult(table, summary, out)


def _read_existing(path: Path) -> list[dict[str, Any]]:
    import pandas as pd

    return pd.read_parquet(path).to_dict("records") if path.exists() else []


def _write_rows(path: Path, rows: list[dict[str, Any]]) -> None:
    import pandas as pd

    from ...core.files import atomic_path

    frame = pd.DataFrame(sorted(rows, key=lambda r: r["index"]))
    with atomic_path(path) as tmp:
        frame.to_parquet(tmp, index=False)
