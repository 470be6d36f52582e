"""Indirect-method performance vs the direct method, measured in one run (ratios matter, not seconds).

On the default problem (problems/hussein2008.yaml, Radau d = 3, K = 100, δ = 0.05) prints, as medians of
``--repeats`` runs with every CasADi function already built:

- the direct homotopy (``solve_direct``, 20 Ipopt solves) — the reference time;
- the indirect continuation from the Kalman solution (collocation + arclength steps), with and without
  the final ``solve_bvp`` polish;
- the direct-seeded BVP at ε = 1 (``solve_bvp`` on the direct grid, and collocation Newton);

each as a ratio to the direct homotopy, plus one-off build times. ``--natural`` also runs what does *not*
work: natural-parameter continuation with ``solve_bvp`` (adaptive ε steps), which stalls at the fold of
the solution curve near ε = 0.0059 (with the paper's fixed δ = 0.05 it fails at its first step, ε = 0.05).

Usage: ``python benchmarks/bench_indirect.py [--repeats 3] [--natural]``
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from typing import Any

from rich.console import Console
from rich.table import Table

from mobisense import Problem, load_problem
from mobisense.ocp import Structure
from mobisense.ocp.direct import solve_direct, transcription_for
from mobisense.ocp.indirect import collocation_mesh, hamiltonian_system, refine_from_direct, solve_indirect

console = Console(width=150)


def timed(run: Callable[[], Any], repeats: int) -> tuple[float, Any]:
    """Median wall time of ``repeats`` calls and the last result."""
    times, result = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def build_times(problem: Problem) -> dict[str, float]:
    """One-off construction of the direct transcription and the collocation BVP (then cached)."""
    c = problem.solver.collocation
    t0 = time.perf_counter()
    transcription_for(problem)
    direct = time.perf_counter() - t0
    t0 = time.perf_counter()
    hamiltonian_system(Structure.of(problem))
    collocation_mesh(Structure.of(problem), c.scheme, c.degree, c.intervals)
    indirect = time.perf_counter() - t0
    return {"direct transcription": direct, "Hamiltonian system + collocation BVP": indirect}


def main() -> None:
    """Run the benchmark and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--natural", action="store_true", help="also time the failing solve_bvp continuation")
    args = parser.parse_args()

    problem = load_problem("problems/hussein2008.yaml")
    builds = build_times(problem)
    solve_direct(problem)  # first call creates the Ipopt instances
    unpolished = problem.with_solver(bvp={"polish": False})
    solve_indirect(unpolished)

    t_direct, direct = timed(lambda: solve_direct(problem), args.repeats)
    rows: list[tuple[str, float, str]] = [("direct homotopy (20 Ipopt solves)", t_direct, f"J = {direct.cost:.10f}")]
    t, s = timed(lambda: solve_indirect(unpolished), args.repeats)
    info = s.stats["indirect"]
    rows.append(
        (
            "indirect continuation (collocation, arclength)",
            t,
            f"J = {s.cost:.10f}; {info['arclength_steps']} arclength steps, {info['newton_iterations']} Newton "
            f"iterations, folds at ε = {', '.join(f'{f:.4g}' for f in info['folds'])}",
        )
    )
    t, s = timed(lambda: solve_indirect(problem), args.repeats)
    polish = s.stats["indirect"]["polish"]
    rows.append(
        (
            "indirect continuation + solve_bvp polish",
            t,
            f"J = {s.cost:.10f}; polish {polish['nodes']} nodes, {polish['time_s']:.3f} s, "
            f"cost change {polish['cost_change']:.1e}",
        )
    )
    for solver in ("scipy", "collocation"):
        t, bvp = timed(lambda solver=solver: refine_from_direct(direct, solver), args.repeats)
        rows.append(
            (
                f"direct-seeded BVP at ε = 1 ({solver})",
                t,
                f"J = {bvp.terminal_cost + bvp.running_cost:.10f}; {bvp.nodes} nodes, {bvp.iterations} iterations",
            )
        )
    if args.natural:
        natural = problem.with_solver(bvp={"solver": "scipy", "max_nodes": 5000}, homotopy={"mode": "adaptive"})
        t0 = time.perf_counter()
        s = solve_indirect(natural)
        rows.append(
            (
                "natural continuation, solve_bvp, adaptive ε (fails)",
                time.perf_counter() - t0,
                f"{s.status}: ε reached {s.eps:g} after {len(s.homotopy)} attempts",
            )
        )

    table = Table(title=f"default problem (Radau d = 3, K = 100), median of {args.repeats}")
    for col in ("solve", "time s", "ratio to direct homotopy", "result"):
        table.add_column(col, justify="left" if col in ("solve", "result") else "right")
    for name, seconds, result in rows:
        table.add_row(name, f"{seconds:.3f}", f"{seconds / t_direct:.2f}", result)
    console.print(table)
    console.print("one-off builds: " + ", ".join(f"{k} {v:.3f} s" for k, v in builds.items()))


if __name__ == "__main__":
    main()
