"""Direct-collocation performance, measured in one run (ratios are what matter; absolute times vary).

Prints: the default problem's transcription build, cold first step and full 20-step homotopy (median of
repeats) with the chosen Ipopt/MUMPS options; the same transcription with Ipopt's default MUMPS
matching/scaling (and other orderings) as ratios; and a scaling table over sensors N, states n and intervals K.

Targets on a 2-core machine: cold solve < 0.15 s, 20-step homotopy < 0.5 s, time ≈ linear in K. The scaling
table reports the cost per Ipopt iteration (the linear algebra) separately from the iteration count (which
depends on how hard each synthetic problem's first continuation step is).

Usage: ``python benchmarks/bench_direct.py [--repeats 5] [--quick]``
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from rich.console import Console
from rich.table import Table

from mobisense import Problem, load_problem
from mobisense.ocp import Structure
from mobisense.ocp.direct import DirectCollocation, solve_direct

console = Console(width=150)

MUMPS_VARIANTS = {
    "chosen (matching/scaling off, AMD ordering)": {},
    "Ipopt default MUMPS (permuting_scaling 7, scaling 77, auto ordering)": {
        "mumps_permuting_scaling": 7,
        "mumps_scaling": 77,
        "mumps_pivot_order": 7,
    },
    "matching/scaling off, auto ordering (METIS here)": {"mumps_pivot_order": 7},
    "matching/scaling off, PORD ordering": {"mumps_pivot_order": 4},
}


def time_variants(problem: Problem, variants: dict[str, dict], repeats: int) -> dict[str, dict[str, float]]:
    """Median cold-step time, homotopy time and iterations of each Ipopt option set.

    Repetitions are interleaved (variant A, B, C, …, A, B, C, …) so that load changes on a shared machine
    affect every variant alike.
    """
    c = problem.solver.collocation
    out: dict[str, dict[str, float]] = {}
    transcriptions = {}
    for name, options in variants.items():
        t0 = time.perf_counter()
        transcriptions[name] = DirectCollocation(
            Structure.of(problem), c.scheme, c.degree, c.intervals, ipopt_options=options
        )
        build = time.perf_counter() - t0
        t0 = time.perf_counter()
        first = solve_direct(problem, transcription=transcriptions[name])  # creates the two Ipopt instances
        out[name] = {
            "build": build,
            "first_call": time.perf_counter() - t0,
            "cost": first.cost,
            "colds": [],
            "totals": [],
            "iters": [],
        }
    for _ in range(repeats):
        for name, tr in transcriptions.items():
            s = solve_direct(problem, transcription=tr)
            assert s.success, s.message
            out[name]["colds"].append(s.homotopy[0].time_s)
            out[name]["totals"].append(sum(h.time_s for h in s.homotopy))
            out[name]["iters"].append(sum(h.iterations for h in s.homotopy))
    for r in out.values():
        r["cold"] = statistics.median(r.pop("colds"))
        r["homotopy"] = statistics.median(r.pop("totals"))
        r["iterations"] = statistics.median(r.pop("iters"))
    return out


def synthetic_problem(n: int, N: int, K: int) -> Problem:
    """n coupled states on a circle of radius 3, N sensors starting on a circle of radius 10."""
    rng = np.random.default_rng(n * 100 + N)
    A = -0.5 * np.eye(n) + 0.1 * rng.standard_normal((n, n))
    angles = 2 * np.pi * np.arange(n) / n
    sensors = []
    for i in range(N):
        phi = 2 * np.pi * (i + 0.5) / N
        p0 = 10 * np.array([np.cos(phi), np.sin(phi)])
        sensors.append(
            {
                "name": f"s{i}",
                "p0": p0.tolist(),
                "v0": (-0.1 * p0 + [0.0, 0.5]).tolist(),
                "noise": {"model": "quadratic_range", "beta": 2.0, "gamma": 1.0},
            }
        )
    data = {
        "name": f"synthetic_n{n}_N{N}",
        "horizon": {"t0": 0.0, "tf": 10.0},
        "process": {
            "A": A.tolist(),
            "B": np.eye(n).tolist(),
            "Q": np.eye(n).tolist(),
            "Sigma0": (50 * np.eye(n)).tolist(),
            "locations": (3 * np.column_stack([np.cos(angles), np.sin(angles)])).tolist(),
        },
        "sensors": sensors,
        "cost": {"M": (10 * np.eye(n)).tolist(), "K": np.eye(n).tolist(), "alpha": 0.05},
        "solver": {"collocation": {"intervals": K}, "homotopy": {"mode": "fixed", "step": 0.25}},
    }
    return Problem.from_dict(data)


def main() -> None:
    """Run the benchmark and print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="smaller scaling table")
    args = parser.parse_args()

    problem = load_problem("problems/hussein2008.yaml")
    results = time_variants(problem, MUMPS_VARIANTS, args.repeats)
    chosen = results[next(iter(MUMPS_VARIANTS))]
    table = Table(title=f"default problem (K = 100, Radau d = 3), median of {args.repeats}")
    for col in (
        "Ipopt/MUMPS options",
        "build s",
        "cold step s",
        "20-step homotopy s",
        "iterations",
        "homotopy ratio vs chosen",
    ):
        table.add_column(col, justify="right" if col != "Ipopt/MUMPS options" else "left")
    for name, r in results.items():
        table.add_row(
            name,
            f"{r['build']:.3f}",
            f"{r['cold']:.4f}",
            f"{r['homotopy']:.4f}",
            f"{r['iterations']:.0f}",
            f"{r['homotopy'] / chosen['homotopy']:.2f}",
        )
    console.print(table)
    console.print(
        f"targets: cold {chosen['cold']:.4f} s (< 0.15: {'met' if chosen['cold'] < 0.15 else 'MISSED'}), "
        f"homotopy {chosen['homotopy']:.4f} s (< 0.5: {'met' if chosen['homotopy'] < 0.5 else 'MISSED'}); "
        f"first call incl. Ipopt set-up {chosen['first_call']:.3f} s; J = {chosen['cost']:.10f}"
    )

    # one factor at a time around (N = 2, n = 2, K = 100); the full grid would take many minutes
    configs = [(1, 1, K) for K in (50, 100, 200, 400)] + [(N, 1, 100) for N in (1, 2, 4, 8)]
    configs += [(2, n, 100) for n in (1, 2, 4)] + [(2, 2, K) for K in (50, 200, 400)]
    if args.quick:
        configs = configs[:2]
    scaling = Table(title="scaling: 4-step homotopy (δ = 0.25), median of 2 solves")
    for col in ("N", "n", "K", "NLP vars", "build s", "solve s", "iterations", "ms/iteration", "ms/it per 1000 vars"):
        scaling.add_column(col, justify="right")
    for N, n, K in configs:
        p = synthetic_problem(n, N, K)
        c = p.solver.collocation
        t0 = time.perf_counter()
        tr = DirectCollocation(Structure.of(p), c.scheme, c.degree, K)
        build = time.perf_counter() - t0
        solve_direct(p, transcription=tr)
        runs = [solve_direct(p, transcription=tr) for _ in range(2)]
        total = statistics.median(sum(h.time_s for h in s.homotopy) for s in runs)
        its = statistics.median(sum(h.iterations for h in s.homotopy) for s in runs)
        ok = all(s.success for s in runs)
        per_it = 1000 * total / its
        scaling.add_row(
            str(N),
            str(n),
            str(K),
            str(tr.nw),
            f"{build:.2f}",
            f"{total:.3f}" + ("" if ok else " (failed)"),
            f"{its:.0f}",
            f"{per_it:.2f}",
            f"{1000 * per_it / tr.nw:.2f}",
        )
    console.print(scaling)


if __name__ == "__main__":
    main()
