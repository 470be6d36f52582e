"""Running a sweep into a result folder: resumable, one row per task, results appended as tasks finish.

Order of checks (nothing is run or written before the last): the sweep file and its base problem, the
number of tasks (before expanding them), the memory budget, every task's problem, the output folder
(usable, not locked by another run, empty or made by this same sweep), the results already there.
"""

from __future__ import annotations

import sys
import time
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ...core.files import write_json
from ...core.interrupts import deferred_interrupts
from ..task_files import lost_solutions, remove_unlisted, write_task_files
from .sweep import RESULT_COLUMNS, expand_sweep, load_sweep
from .sweep_report import SweepProgress, sweep_summary

__all__ = ["SweepResult", "run_sweep", "RESULT_COLUMNS", "content_bytes"]


#: task statuses that are final (not re-run on resume)
DONE = ("solved", "failed")
#: finished rows are appended to results.parquet in batches of at most this many rows, …
BATCH_ROWS = 1024
#: … solutions of at most this many bytes held in the client (K = 60, one sensor: ≈ 40 kB a task) …
BATCH_BYTES = 64 * 2**20
#: … or after this many seconds (and whenever the sweep ends, finished or interrupted). Each flush writes at least
#: one part file, ≈ 21 ms of the client's CPU whatever its size (h5py's variables, attributes and dimension scales;
#: + 0.12 ms a task): 64-row batches cost a 200-task sweep of 1.1 s four files, three of them taken from the workers'
#: two cores while they solve
BATCH_SECONDS = 2.0


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
    security: Any = None,
    max_memory: int | None = None,
    max_time: float | None = None,
) -> SweepResult:
    """Validate a sweep file, run the tasks not finished in ``out`` before, and summarise.

    Parameters
    ----------
    path : str or Path
        The sweep YAML file (see the module docstring).
    out : str or Path
        Result folder: ``results.parquet`` (a folder of parquet fragments, one appended per batch of finished
        tasks, so an interrupted sweep resumes), ``sweep.json`` (which sweep made the folder),
        ``tasks/part-NNNNNN.nc`` (the solutions of the tasks finished between two flushes, stacked along a
        ``task`` dimension: :mod:`mobisense.ocp.task_files`; each row's ``solution_file`` names its file)
        and ``summary.json``.
    scheduler : str, optional
        Address of a running dask scheduler (with dask ``security``); default a local cluster of ``workers``
        processes.
    workers : int, optional
        Local worker processes, 1 … 4096 (default one per core, at most one per task).
    warm_start : bool
        Solve the tasks in chains of neighbours, one per worker, each warm-started from its predecessor
        (:mod:`mobisense.ocp.batch.chains`); otherwise every task starts from the coasting solution.
    time_limit : float, optional
        Wall-clock limit (s) of each Ipopt solve (sets ``solver.time_limit``).
    quiet : bool
        No progress display or table.
    security : distributed.security.Security, optional
        TLS settings for ``scheduler``.
    max_memory : int, optional
        Memory budget (bytes, 1 MiB … 1 EiB) checked before anything runs (default half of the RAM).
    max_time : float, optional
        Time budget (s, 1 … 1e8) checked before anything runs (default one hour on the local workers).

    Raises
    ------
    TypeError
        ``workers``, ``max_memory`` or ``max_time`` is not a number.
    ConfigError
        ``workers``, ``max_memory`` or ``max_time`` is out of range; the sweep file, its base problem or one
        of its tasks is invalid, the sweep is too large for the
        memory budget, ``out`` cannot be used or holds another sweep, or a results fragment is corrupt
        (nothing is run or written).
    """
    import os

    import pandas as pd

    from ...core.budget import check_budget, check_limits
    from ...core.errors import ConfigError
    from ...core.output import OutputFolder, input_files
    from .cluster import check_count
    from .engine import open_client, refuse_in_a_worker_import, run_tasks
    from .results_store import ResultStore, check_manifest, value_kind, write_manifest
    from .sweep import sweep_digest, sweep_estimates, task_count

    check_limits(max_memory, max_time, "sweep")
    if workers is not None:
        check_count("workers", workers, "sweep")
    if scheduler is None:
        refuse_in_a_worker_import()  # before the folder's lock, which the parent process holds
    path, source = Path(path), str(path)
    spec, base = load_sweep(path)
    if time_limit is not None:
        if not (isinstance(time_limit, (int, float)) and 0 < time_limit <= 1e9):
            raise ConfigError(f"{source}: --time-limit: expected seconds in (0, 1e9], got {time_limit}")
        base = base.with_solver(time_limit=time_limit)
    count = task_count(spec, source)
    local = 0 if scheduler else min(count, workers or os.cpu_count() or 1)
    check_budget(sweep_estimates(spec, base, local, source), max_memory, source, max_time)
    tasks = expand_sweep(spec, base, source=source)  # ConfigError -> nothing run or written
    check_budget(sweep_estimates(spec, base, local, source, tasks), max_memory, source, max_time)  # their largest
    folder = OutputFolder.check(out, inputs=input_files(path, spec))
    digest = sweep_digest(tasks)
    with folder.lock():
        out = folder.path
        resuming = check_manifest(out, digest, source)
        store = ResultStore(out, {k: value_kind(v) for k, v in spec.vary.items()})
        previous = store.read() if resuming else {}
        rows = {t: r for t, r in previous.items() if r["status"] in DONE}
        lost = lost_solutions(out, rows.values())
        if lost:  # a part file deleted, truncated or replaced since: its tasks are solved again
            first = next(iter(lost.values()))
            print(f"mobisense: {len(lost)} finished task(s) of {out} lost their solutions ({first}): solving them "
                  "again", file=sys.stderr)  # fmt: skip
            rows = {t: r for t, r in rows.items() if t not in lost}
        todo = [t for t in tasks if t.task not in rows]
        batch = _Batch(store, out)
        progress = SweepProgress(len(tasks), len(tasks) - len(todo), quiet=quiet)

        def on_result(i: int, result: dict[str, Any]) -> None:
            task = todo[i]
            row = {"task": task.task, "index": task.index, **task.values}
            row.update({c: None for c in RESULT_COLUMNS})
            row.update(result["row"])
            with deferred_interrupts():  # a task's solution and its row are flushed together: both or neither
                rows[task.task] = row
                batch.add(row, result.get("dataset"), last=len(rows) == len(tasks))
            progress.advance(row)

        connection = open_client(scheduler, min(local, len(todo)) or None, security) if todo else nullcontext()
        with connection as client:  # ConfigError (scheduler unreachable) before anything is written
            if not resuming:
                write_manifest(out, digest, source, len(tasks), spec.mode, list(spec.vary))
            try:
                with progress:
                    if todo:
                        run_tasks(
                            client,
                            [t.payload() for t in todo],
                            on_result,
                            [t.structure for t in todo],
                            [t.coordinates() for t in todo],
                            warm_start=warm_start,
                        )
            finally:
                batch.flush()  # rows of finished tasks are kept however the run ends
        store.compact()
        remove_unlisted(out, rows.values())
        summary = sweep_summary(spec, tasks, list(rows.values()), resumed=len(tasks) - len(todo))
        write_json(out / "summary.json", summary)
        progress.report(summary, out)
    table = pd.DataFrame(sorted(rows.values(), key=lambda r: r["index"]))
    return SweepResult(table, summary, out)


def content_bytes(dataset: Any) -> int:
    """The bytes of a solution's arrays (a :class:`~mobisense.core.netcdf_writer.DatasetContent`; 0 for None)."""
    if dataset is None:
        return 0
    tables = (dataset.data_vars, dataset.coords) if hasattr(dataset, "data_vars") else ()
    return sum(int(getattr(values, "nbytes", 0)) for table in tables for _, values, _ in table.values())


class _Batch:
    """Rows and solutions waiting to be written: :data:`BATCH_ROWS`, :data:`BATCH_BYTES` or :data:`BATCH_SECONDS`.

    A flush writes the solutions as ``tasks/part-NNNNNN.nc`` (one file per shape of dataset, see
    :mod:`mobisense.ocp.task_files`), then the rows naming them as one results fragment.
    """

    def __init__(self, store: Any, folder: Path) -> None:
        self.store = store
        self.folder = folder
        self.rows: list[dict[str, Any]] = []
        self.datasets: list[Any] = []
        self.bytes = 0
        self.since = time.monotonic()

    def add(self, row: dict[str, Any], dataset: Any = None, last: bool = False) -> None:
        self.rows.append(row)
        self.datasets.append(dataset)
        self.bytes += content_bytes(dataset)
        if (
            last
            or len(self.rows) >= BATCH_ROWS
            or self.bytes >= BATCH_BYTES
            or time.monotonic() - self.since >= BATCH_SECONDS
        ):
            self.flush()

    def flush(self) -> None:
        if not self.rows:
            return
        rows, datasets = self.rows, self.datasets
        self.rows, self.datasets, self.bytes = [], [], 0
        self.since = time.monotonic()
        with deferred_interrupts():  # the files and the rows naming them: both, or rows left to re-run
            write_task_files(self.folder, rows, datasets)
            self.store.append(rows)
