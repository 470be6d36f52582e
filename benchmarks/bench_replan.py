"""Re-planning in real time: warm re-solve time against the re-plan interval (real-time factor), warm starts compared.

    .venv/bin/python benchmarks/bench_replan.py [--runs 4] [--every 0.5] [--length 4.0] [--field-runs 2]

Flies ``problems/hussein2008.yaml`` (100 intervals) under a current of (0.3, −0.2) L/T and force noise
0.05, re-planning every ``--every`` T (docs/theory/path_constraints.md §5), and prints, measured in this one
run with the same noise draws for every row:

* per configuration — shrinking and receding (window ``--length``) horizon, each with the shifted
  warm start (the default), and the shrinking horizon with the previous point reused on the plan's grid
  and with cold starts — the closed-loop, open-loop and no-control costs (mean ± standard error), the
  median and largest Ipopt iterations and wall time per re-solve;
* the real-time factor (largest re-solve time / re-plan interval) of the default configuration (target:
  < 0.5, i.e. a re-plan leaves half the interval for the rest of the loop), and the ratio of the median
  re-solve times shifted / reused and shifted / cold (target: shifted ≤ the others' 1.1x; the rows are
  interleaved run by run, so a load change hits them alike);
* the shipped 5 × 5 field (``field_mapping_5x5.yaml``) re-planned by shooting every 4 T in a current of
  (0.1, 0): its three costs and re-solve times (informational; ``--field-runs 0`` leaves it out).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from mobisense.ocp import Disturbance, load_problem, replan_monte_carlo

PROBLEM = Path(__file__).resolve().parent.parent / "problems" / "hussein2008.yaml"

#: label -> (receding length or None, warm start)
CONFIGURATIONS = {
    "shrinking, shifted": (None, "shifted"),
    "receding, shifted": ("length", "shifted"),
    "shrinking, reused": (None, "reused"),
    "shrinking, cold": (None, "cold"),
}


def main() -> int:
    """Run the benchmark; exit 0 on PASS, 1 on MISS."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=4)
    parser.add_argument("--every", type=float, default=0.5)
    parser.add_argument("--length", type=float, default=4.0)
    parser.add_argument("--field-runs", type=int, default=2, help="runs of the field rows (0: none)")
    args = parser.parse_args()
    problem = load_problem(PROBLEM)
    results: dict[str, list[dict]] = {label: [] for label in CONFIGURATIONS}
    for run in range(args.runs):  # interleaved: one run of every configuration, then the next
        for label, (length, warm) in CONFIGURATIONS.items():
            r = replan_monte_carlo(problem, Disturbance((0.3, -0.2), 0.05), runs=1, every=args.every,
                                   time_step=0.01, seed=run + 1, length=args.length if length else None,
                                   warm_start=warm)  # fmt: skip
            results[label].append(r)
    print(f"re-plan every {args.every:g} T, {args.runs} runs, load average {os.getloadavg()[0]:.2f}")
    print(f"{'':22s} {'closed loop':>17s} {'open loop':>17s} {'no control':>17s} {'iterations':>11s} "
          f"{'re-solve ms':>13s}")  # fmt: skip
    medians = {}
    for label, rs in results.items():
        cells = []
        for name in ("closed_loop", "open_loop", "no_control"):
            costs = np.array([r[name]["cost_mean"] for r in rs])
            stderr = costs.std(ddof=1) / np.sqrt(len(costs)) if len(costs) > 1 else 0.0
            cells.append(f"{costs.mean():8.4f} ± {stderr:6.4f}")
        times = np.concatenate([f.solve_times for r in rs for f in r["flights"]])
        iterations = np.concatenate([[x.iterations for x in f.records] for r in rs for f in r["flights"]])
        medians[label] = (np.median(times), np.max(times))
        print(f"{label:22s} {' '.join(cells)} {np.median(iterations):5.0f}/{np.max(iterations):<5.0f} "
              f"{1e3 * np.median(times):6.1f}/{1e3 * np.max(times):<6.1f}")  # fmt: skip
    median, largest = medians["shrinking, shifted"]
    factor = largest / args.every
    ok_rt = factor < 0.5
    print(f"real-time factor (shrinking, shifted): median {median / args.every:.3f}, max {factor:.3f} "
          f"(target max < 0.5): {'PASS' if ok_rt else 'MISS'}")  # fmt: skip
    ok = ok_rt
    for other in ("shrinking, reused", "shrinking, cold"):
        ratio = median / medians[other][0]
        print(f"median re-solve time shifted / {other.split(', ')[1]}: {ratio:.2f} (target ≤ 1.1): "
              f"{'PASS' if ratio <= 1.1 else 'MISS'}")  # fmt: skip
        ok = ok and ratio <= 1.1
    if args.field_runs:
        field_rows(args.field_runs)
    return 0 if ok else 1


def field_rows(runs: int) -> None:
    """The shipped 5 × 5 field re-planned by shooting every 4 T in a current (path_constraints.md §5.3).

    Informational, no target: each window's shooting graph is built with the re-solve and timed with it.
    """
    problem = load_problem(PROBLEM.parent / "field_mapping_5x5.yaml")
    r = replan_monte_carlo(problem, Disturbance((0.1, 0.0), 0.01), runs=runs, every=4.0, time_step=0.05)
    cells = [f"{name.replace('_', ' ')} {r[name]['cost_mean']:.4f} ± {r[name]['cost_stderr']:.4f}"
             for name in ("closed_loop", "open_loop", "no_control")]  # fmt: skip
    t, it = r["replan_solve_time_s"], r["replan_iterations"]
    print(f"field 5 × 5, every 4 T, {runs} runs: {', '.join(cells)} (plan {r['plan_cost']:.4f}); re-solves "
          f"{t['median']:.2f}/{t['max']:.2f} s, {it['median']:.0f}/{it['max']:.0f} iterations (median/max), "
          f"{r['replan_failures']} failed (informational)")  # fmt: skip


if __name__ == "__main__":
    raise SystemExit(main())
