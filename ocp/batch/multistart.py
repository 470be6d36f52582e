"""Multi-start: solve from several initial guesses on dask workers and count the distinct local optima.

Start 0 is the ordinary solve (the problem's ``solver.strategy``: by default ``auto``, a cold solve and random
starts until they agree, see docs/theory/direct.md §5.6). Start k > 0 solves ε = 1 directly from a random
feasible trajectory (:func:`mobisense.ocp.direct.guesses.random_guess` with seed k).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..problem import Problem
from ..solution import Solution
from ..solving import as_problem
from .cluster import check_count

__all__ = ["distinct_optima", "solve_multistart"]


def distinct_optima(solutions: list[Solution], rtol: float = 1e-6) -> list[dict[str, Any]]:
    """Group converged solutions whose costs agree to ``rtol``; return one entry per optimum, best first."""
    groups: list[dict[str, Any]] = []
    for k, s in sorted(enumerate(solutions), key=lambda item: item[1].cost):
        if not s.success:
            continue
        for g in groups:
            if abs(s.cost - g["cost"]) <= rtol * max(abs(g["cost"]), 1e-12):
                g["starts"].append(k)
                break
        else:
            groups.append({"cost": s.cost, "starts": [k], "final_positions": s.p[-1].tolist()})
    return groups


def solve_multistart(
    problem: Problem | str | Path,
    starts: int,
    scheduler: str | None = None,
    workers: int | None = None,
    security: Any = None,
) -> Solution:
    """Solve from ``starts`` initial guesses through the dask engine; return the best, with the optima found.

    ``problem`` is what :func:`~mobisense.ocp.solving.solve` takes: a Problem, the path of its YAML file or a
    shipped example's name. ``scheduler`` (with dask ``security``) or ``workers`` local processes (default one
    per core, at most ``starts``) run the starts; ``starts`` and ``workers`` are integers in 1 … 4096, as
    ``--multistart`` and ``--workers`` take.

    The returned solution's ``stats["multistart"]`` holds ``starts``, ``converged`` and ``optima``
    (one entry per distinct local optimum: cost, which starts reached it, final sensor positions).
    """
    from .engine import open_client, run_tasks

    check_count("starts", starts, "multistart")
    if workers is not None:
        check_count("workers", workers, "multistart")
    problem = as_problem(problem, "multistart")
    payloads = [{"problem": problem.normalised(), "guess_seed": None if k == 0 else k} for k in range(starts)]
    solutions: list[Solution | None] = [None] * starts
    errors: list[str] = []

    def on_result(i: int, result: dict[str, Any]) -> None:
        if "dataset" in result:
            solutions[i] = Solution.from_dataset(result["dataset"].to_xarray())
        else:
            errors.append(f"start {i}: {result['row'].get('error', '')}")

    import os

    local = None if scheduler else min(starts, workers or os.cpu_count() or 1)
    with open_client(scheduler, local, security) as client:
        run_tasks(client, payloads, on_result, warm_start=False)
    done = [s for s in solutions if s is not None]
    optima = distinct_optima(done)
    converged = [s for s in done if s.success]
    if not done:
        raise RuntimeError("every multi-start task failed: " + "; ".join(errors))
    index = {id(s): k for k, s in enumerate(solutions)}
    for group in optima:
        group["starts"] = sorted(index[id(done[k])] for k in group["starts"])
    # the best optimum, represented by its lowest start (start 0, the ordinary solve, when it found it)
    best = solutions[optima[0]["starts"][0]] if optima else done[0]
    best.stats["multistart"] = {"starts": starts, "converged": len(converged), "optima": optima, "errors": errors}
    from ..direct.plan_check import record_plan_check

    record_plan_check(best)  # the plan returned, checked as a single solve's is
    return best
