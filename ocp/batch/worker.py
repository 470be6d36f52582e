"""The worker side of a batch: solve one task given as plain data, return plain data.

A task is ``{problem: dict or validated Problem, seed: NLP point or None, guess_seed: int or None,
solved_elsewhere: list or None}``; the worker builds (or reuses, per process) the transcription of the
problem's structure and returns the result row, the solution's arrays and the converged NLP point (to
warm-start neighbours). A cold task's certain starts can be solved on several workers first
(:func:`solve_start_share`) and handed to the task that decides (``solved_elsewhere``).
"""

from __future__ import annotations

import time
from typing import Any

__all__ = [
    "solve_task",
    "task_warnings",
    "solve_start_share",
    "shareable_starts",
    "task_problem",
    "worker_name",
    "dask_setup",
]


def solve_task(payload: dict[str, Any]) -> dict[str, Any]:
    """Worker side: solve one task. ``payload`` = {problem, seed (NLP point or None), guess_seed (int|None)}."""
    from ..direct.solver import solve_direct
    from ..direct.transcription import transcription_cache_hits
    from ..solution import StartKind

    t0 = time.perf_counter()
    hits = transcription_cache_hits()
    problem = task_problem(payload)
    guess = None
    if payload.get("guess_seed") is not None:
        from ..direct.guesses import random_guess

        guess = random_guess(problem, payload["guess_seed"])
    if problem.solver.method == "shooting":  # a field problem: no NLP point to warm-start from (cold solve)
        from ..field_solve import solve_shooting

        solution = solve_shooting(problem)
    else:
        solution = solve_direct(
            problem, init=payload.get("seed"), guess=guess, solved_elsewhere=payload.get("solved_elsewhere")
        )
    solution.reject_non_finite()
    cached = transcription_cache_hits() > hits
    row = {
        "status": solution.status,
        "cost": solution.cost,
        "terminal_cost": solution.terminal_cost,
        "running_cost": solution.running_cost,
        "iterations": int(sum(s.iterations for s in solution.homotopy)),
        # worker-seconds spent on the task: here, and on the workers that solved some of its starts
        "time_s": time.perf_counter() - t0 + sum(r.get("seconds", 0.0) for r in payload.get("solved_elsewhere") or ()),
        "solve_time_s": float(sum(s.time_s for s in solution.homotopy)),
        "worker": worker_name(),
        "error": "" if solution.success else solution.message,
        "start": StartKind(solution.stats.get("start", StartKind.CONTINUATION)).value,
        "transcription_cached": cached,
        "warning": task_warnings(solution),
    }
    # the solution.nc content as numpy arrays (no xarray on the worker; cheaper to pickle than a Dataset)
    return {"row": row, "dataset": solution.to_content(), "nlp": solution.nlp if solution.success else None}


def task_warnings(solution: Any) -> str:
    """The warnings ``solve`` would print for this task's solution, joined by ``" | "`` (``""``: none, or failed).

    :func:`~mobisense.ocp.solution_warnings.solution_warnings`; a failed task's ``error`` says why it failed.

    A sweep task runs no plan check (a re-integration per task), so the grid warning of ``solve`` is not among
    them, nor is the warning about an unused ``init`` (a sweep warm-starts from neighbours itself); a plan that
    breaks a path constraint between the nodes, costs more than the no-control baseline or whose Σ(t) is not
    positive definite is.
    """
    if not solution.success:
        return ""
    from ..solution_warnings import solution_warnings

    return " | ".join(solution_warnings(solution, solution.min_sigma_eigenvalue, init=False))


def solve_start_share(payload: dict[str, Any], share: int, shares: int) -> list[dict[str, Any]]:
    """Worker side: solve share ``share`` of ``shares`` of a cold task's certain starts, as records.

    The certain starts (:func:`mobisense.ocp.direct.strategy.certain_starts`: for strategy ``auto`` the cold
    solve and the first random starts) are cut into ``shares`` (:func:`~mobisense.ocp.direct.strategy.share_starts`);
    the records (:func:`mobisense.ocp.direct.solver.solve_starts`) go to the task that solves the problem
    (``payload["solved_elsewhere"]``), which adopts them. Nothing to share (another strategy, a field
    problem) or a problem that raises: an empty list, and the task solves everything itself.
    """
    from ..direct.solver import solve_starts
    from ..direct.strategy import share_starts

    try:
        problem = task_problem(payload)
        labels = shareable_starts(payload, problem)
        return solve_starts(problem, share_starts(labels, shares)[share]) if labels else []
    except Exception:  # noqa: BLE001  (the deciding task solves the start itself and reports any error)
        return []


def shareable_starts(payload: dict[str, Any], problem: Any = None) -> list[str]:
    """The starts of a task that other workers can solve for it: its strategy's certain starts, or none.

    None for a field problem (the shooting method has no starts) or a multi-start guess (one start, its own).
    ``problem`` is the task's validated problem, if already at hand.
    """
    from ..direct.strategy import certain_starts

    problem = problem if problem is not None else task_problem(payload)
    if problem.solver.method == "shooting" or payload.get("guess_seed") is not None:
        return []
    return certain_starts(problem)


def task_problem(payload: dict[str, Any]) -> Any:
    """The task's :class:`~mobisense.ocp.problem.Problem`: as sent (validated by the client), or validated here."""
    from ..problem import Problem

    problem = payload["problem"]
    return problem if isinstance(problem, Problem) else Problem.from_dict(problem, source="task")


def worker_name() -> str:
    """The dask worker this runs on, or ``"local"`` outside a worker."""
    try:
        from dask.distributed import get_worker

        return str(get_worker().name)
    except (ImportError, ValueError):
        return "local"


def dask_setup(worker: Any) -> None:
    """Preload hook of local dask workers: ignore SIGINT.

    Ctrl-C in a terminal goes to the whole process group; ignored by the workers, it reaches only the client,
    which closes the cluster, and no worker prints a traceback.
    """
    import signal

    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread of the worker process
        pass
