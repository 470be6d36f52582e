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

import ocp  # noqa: F401  (sets OPENBLAS_NUM_THREADS before CasADi loads)
from ocp.direct import solve_direct
from ocp.model import Structure
from ocp.problem import Problem, load_problem
from ocp.transcription import DirectCollocation

console = Console()

MUMPS_VARIANTS = {
    "chosen (matching/scaling off, auto ordering)": {},
    "Ipopt default MUMPS (permuting_scaling 7, scaling 77)": {"mumps_permuting_scaling": 7, "mumps_scaling": 77},
    "chosen + AMD ordering": {"mumps_pivot_order": 0},
    "chosen + PORD ordering": {"mumps_pivot_order": 4},
}


def time_homotopy(problem: Problem, options: dict, repeats: int) -> dict[str, float]:
    """Median cold-step time, homotopy time and iterations over ``repeats`` solves of one transcription."""
    c = problem.solver.collocation
    t0 = time.perf_counter()
    tr = DirectCollocation(Structure.of(problem), c.scheme, c.degree, c.intervals, ipopt_options=options)
    build = time.perf_counter() - t0
    t0 = time.perf_counter()
    first = solve_direct(problem, transcription=tr)  # includes creating the two Ipopt instances
    first_total = time.perf_counter() - t0
    colds, totals, iters = [], [], []
    for _ in range(repeats):
        s = solve_direct(problem, transcription=tr)
        assert s.success, s.message
        colds.append(s.homotopy[0].time_s)
        totals.append(sum(h.time_s for h in s.homotopy))
        iters.append(sum(h.iterations for h in s.homotopy))
    return {
        "build": build,
        "first_call": first_total,
        "cold": statistics.median(colds),
        "homotopy": statistics.median(totals),
        "iterations": statistics.median(iters),
        "steps": len(first.homotopy),
        "cost": first.cost,
    }


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
    results = {name: time_homotopy(problem, opts, args.repeats) for name, opts in MUMPS_VARIANTS.items()}
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

    Ns, ns, Ks = ([1, 2, 4, 8], [1, 2, 4], [50, 100, 200, 400]) if not args.quick else ([1, 4], [1, 2], [50, 200])
    scaling = Table(title="scaling: 4-step homotopy (δ = 0.25), median of 2 solves")
    for col in ("N", "n", "K", "NLP vars", "build s", "solve s", "iterations", "ms/iteration", "(ms/it)/K vs first K"):
        scaling.add_column(col, justify="right")
    for N in Ns:
        for n in ns:
            base_per_K = None
            for K in Ks:
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
                per_K = total / its / K
                base_per_K = base_per_K or per_K
                scaling.add_row(
                    str(N),
                    str(n),
                    str(K),
                    str(tr.nw),
                    f"{build:.2f}",
                    f"{total:.3f}" + ("" if ok else " (failed)"),
                    f"{its:.0f}",
                    f"{1000 * total / its:.2f}",
                    f"{per_K / base_per_K:.2f}",
                )
            console.print(f"  done N={N} n={n}", style="dim")
    console.print(scaling)


if __name__ == "__main__":
    main()
