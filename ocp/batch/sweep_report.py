"""Progress display (counts and ETA) and summary of a sweep."""

from __future__ import annotations

import statistics
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.table import Table

from ..solution import StartKind
from .sweep import SweepSpec, SweepTask

__all__ = ["SweepProgress", "sweep_summary"]


class SweepProgress:
    """A rich progress bar over tasks with solved/failed/error counts; a context manager."""

    def __init__(self, total: int, done: int, quiet: bool = False) -> None:
        self.quiet = quiet
        self.counts = {"solved": 0, "failed": 0, "error": 0}
        self.progress = Progress(
            TextColumn("[bold]sweep"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.fields[info]}"),
            TimeElapsedColumn(),
            TextColumn("ETA"),
            TimeRemainingColumn(),
            console=Console(stderr=True),
            disable=quiet,
        )
        self.task = self.progress.add_task(
            "sweep", total=total, completed=done, info=f"{done} done before" if done else ""
        )

    def __enter__(self) -> SweepProgress:
        self.progress.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        self.progress.__exit__(*exc)

    def advance(self, row: dict[str, Any]) -> None:
        """Count one finished task."""
        self.counts[row["status"] if row["status"] in self.counts else "error"] += 1
        info = "  ".join(f"{k} {v}" for k, v in self.counts.items())
        self.progress.update(self.task, advance=1, info=info)

    def report(self, summary: dict[str, Any], out: Path) -> None:
        """Print the counts, the best task and the warm-start saving."""
        if self.quiet:
            return
        table = Table(title=f"sweep — {out}", show_header=False)
        for key, value in summary["counts"].items():
            table.add_row(key, str(value))
        best = summary.get("best")
        if best:
            table.add_row("best task", f"#{best['index']} J = {best['cost']:.8g}  {best['values']}")
        saving = summary.get("warm_start")
        if saving and saving.get("warm_median_solve_s") is not None and saving.get("cold_median_solve_s"):
            table.add_row(
                "median solve, warm vs cold",
                f"{saving['warm_median_solve_s']:.3f} s vs {saving['cold_median_solve_s']:.3f} s "
                f"({saving['warm_median_iterations']:.0f} vs {saving['cold_median_iterations']:.0f} it)",
            )
        Console().print(table)


def _median(values: list[float]) -> float | None:
    return statistics.median(values) if values else None


def sweep_summary(spec: SweepSpec, tasks: list[SweepTask], rows: list[dict[str, Any]], resumed: int) -> dict[str, Any]:
    """Counts, the best solved task, the first task with warnings and the warm-start saving (medians)."""
    statuses = [r["status"] for r in rows]
    solved = [r for r in rows if r["status"] == "solved"]
    best = min(solved, key=lambda r: r["cost"]) if solved else None
    warm = [r for r in solved if r.get("start") == StartKind.WARM.value]
    cold_starts = (StartKind.CONTINUATION.value, StartKind.WARM_FAILED.value, StartKind.COARSE.value)
    cold = [r for r in solved if r.get("start") in cold_starts]
    warned = sorted((r for r in solved if r.get("warning")), key=lambda r: r["index"])
    return {
        "mode": spec.mode,
        "vary": list(spec.vary),
        "counts": {
            "tasks": len(tasks),
            "solved": statuses.count("solved"),
            "failed": statuses.count("failed"),
            "error": sum(s not in ("solved", "failed") for s in statuses),
            "resumed": resumed,
            "warned": len(warned),
        },
        "first_warning": {"index": int(warned[0]["index"]), "warning": warned[0]["warning"]} if warned else None,
        "best": None
        if best is None
        else {
            "task": best["task"],
            "index": int(best["index"]),
            "cost": float(best["cost"]),
            "values": {k: best[k].tolist() if hasattr(best[k], "tolist") else best[k] for k in spec.vary},
        },
        "warm_start": {
            "warm_tasks": len(warm),
            "cold_tasks": len(cold),
            "warm_median_solve_s": _median([float(r["solve_time_s"]) for r in warm]),
            "cold_median_solve_s": _median([float(r["solve_time_s"]) for r in cold]),
            "warm_median_iterations": _median([float(r["iterations"]) for r in warm]),
            "cold_median_iterations": _median([float(r["iterations"]) for r in cold]),
        },
        "transcription_cache_hits": sum(bool(r.get("transcription_cached")) for r in rows),
    }
