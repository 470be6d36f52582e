"""Re-planning in real time: warm re-solve time against the re-plan interval (real-time factor).

    .venv/bin/python benchmarks/bench_replan.py [--runs 4] [--every 0.5]

Flies ``problems/hussein2008.yaml`` (100 intervals) under a current of (0.3, −0.2) L/T and force noise
0.05, re-planning every ``--every`` T over the shrinking horizon, warm-started from the previous solution
(docs/theory/path_constraints.md §5), and prints, measured in this one run:

* the median and largest warm re-solve time and their ratio to the re-plan interval (real-time factor;
  target: the largest < 0.5, i.e. a re-plan leaves half the interval for the rest of the loop);
* the closed-loop, open-loop and no-control costs, mean ± standard error over the runs.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from mobisense.ocp import Disturbance, load_problem, replan_monte_carlo

PROBLEM = Path(__file__).resolve().parent.parent / "problems" / "hussein2008.yaml"


def main() -> int:
    """Run the benchmark; exit 0 on PASS, 1 on MISS."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=4)
    parser.add_argument("--every", type=float, default=0.5)
    args = parser.parse_args()
    problem = load_problem(PROBLEM)
    r = replan_monte_carlo(problem, Disturbance((0.3, -0.2), 0.05), runs=args.runs, every=args.every, time_step=0.01)
    times = r["replan_solve_time_s"]
    load = os.getloadavg()[0]
    print(f"re-plan every {args.every:g} T, {args.runs} runs, load average {load:.2f}")
    for name in ("closed_loop", "open_loop", "no_control"):
        c = r[name]
        print(f"  {name:12s} J = {c['cost_mean']:.4f} ± {c['cost_stderr']:.4f} (standard error)")
    ratio_median, ratio_max = times["median"] / args.every, times["max"] / args.every
    print(f"  warm re-solve: median {1e3 * times['median']:.1f} ms, max {1e3 * times['max']:.1f} ms")
    verdict = "PASS" if ratio_max < 0.5 else "MISS"
    print(f"  real-time factor: median {ratio_median:.3f}, max {ratio_max:.3f} (target max < 0.5): {verdict}")
    return 0 if verdict == "PASS" else 1


if __name__ == "__main__":
    raise SystemExit(main())
