"""Optimum quality and iteration counts of the direct method's solve strategies (issue targets, PASS/MISS).

On a set of seeded synthetic problems (``reference_transcription.synthetic_problem``: n = 1–4 states,
N = 1–4 sensors, random geometry, drift and noise; K intervals) this solves:

* the **default** (``solve_direct(problem)``: strategy ``auto``, docs/theory/direct.md §5.6);
* the candidates it must not lose to, each on its own: the **cold** ε = 1 solve from coasting, the
  **homotopy** (20 fixed steps δ = 0.05, warm-started, *no* iteration budget) and a **4-start multistart**
  (random feasible guesses, :func:`mobisense.ocp.direct.random_guess` seeds 1–4), all from one
  ``thorough`` solve with the budget switched off;
* the independent **reference** transcription's cold solve (iterations only);
* strategy ``cold`` alone (wall time of the default ÷ the cold solve's) and strategy ``homotopy`` with its
  default budget (the budgeted continuation's iterations ÷ its cold solve's).

Targets: the default's cost is never worse than the best of {cold, homotopy, multistart} by more than 1e-6
relative; cold iterations no worse than the reference's (median ratio ≤ 1); the budgeted continuation
never costs more than 1.5 × its cold solve (plus the one iteration in which the budget callback fires).

Usage: ``python benchmarks/bench_ocp_quality.py [--K 50] [--problems 24]``; ``--cold-seeds 6``: only the
cold solve against the reference's, on 96 problems (information, not a target).
"""

from __future__ import annotations

import argparse
import os
import random
import statistics
import sys
import time

from reference_transcription import ReferenceOCP, synthetic_problem

from mobisense import Problem
from mobisense.ocp.direct import solve_direct

#: (n, N, seed): every (n, N) of 1–4 × 1–4 with seed 0, then eight with seed 1
PROBLEMS = [(n, N, 0) for n in range(1, 5) for N in range(1, 5)] + [
    (1, 1, 1),
    (1, 3, 1),
    (2, 2, 1),
    (2, 4, 1),
    (3, 1, 1),
    (3, 3, 1),
    (4, 2, 1),
    (4, 4, 1),
]


def verdict(ok: bool) -> str:
    """PASS or MISS."""
    return "PASS" if ok else "MISS"


def median_interval(values: list[float], resamples: int = 10_000, seed: int = 0) -> tuple[float, float]:
    """The 2.5 % and 97.5 % quantiles of the median of ``values`` resampled with replacement (bootstrap)."""
    rng = random.Random(seed)
    medians = sorted(statistics.median(rng.choices(values, k=len(values))) for _ in range(resamples))
    return medians[int(0.025 * resamples)], medians[int(0.975 * resamples) - 1]


def starts(solution) -> dict[str, dict]:  # noqa: ANN001
    """label -> summary of every start of a solve (cost None when it did not reach ε = 1)."""
    return {s["start"]: s for s in solution.stats["strategy"]["starts"]}


def cold_against_reference(seeds: int, K: int) -> int:
    """Cold ε = 1 iterations ÷ the reference's on every (n, N) of 1–4 × 1–4 with seeds 0 … ``seeds`` − 1.

    The 24 problems of the quality table are too few to tell a median of 1.2 from 1 (their cold solves follow
    different paths to different local optima); this prints the same ratio over more of them, with its
    bootstrap interval. Information, not a target.
    """
    rows = []
    for seed in range(seeds):
        for n in range(1, 5):
            for N in range(1, 5):
                data = synthetic_problem(n, N, seed, intervals=K)
                ref = ReferenceOCP(data, intervals=K).solve()
                cold = starts(solve_direct(Problem.from_dict(data).with_solver(strategy="cold")))["cold"]
                if ref.success and cold["cost"] is not None:
                    rows.append((cold["iterations"], ref.iterations, (cold["cost"] - ref.J) / abs(ref.J)))
                    print(f"{n}, {N}, {seed}: cold {cold['iterations']}, reference {ref.iterations} iterations; J "
                          f"{cold['cost']:.8g} ({rows[-1][2]:+.1e} relative to the reference's)", flush=True)
                else:
                    print(f"{n}, {N}, {seed}: not compared (cold reached ε = 1: {cold['cost'] is not None}, "
                          f"reference solved: {ref.success})", flush=True)
    ratios = [ours / theirs for ours, theirs, _ in rows]
    low, high = median_interval(ratios)
    print(
        f"cold ε = 1 iterations ÷ reference's on {len(ratios)} of {16 * seeds} problems: median "
        f"{statistics.median(ratios):.2f} (95 % bootstrap interval {low:.2f}–{high:.2f}), ≤ 1 on "
        f"{sum(r <= 1 for r in ratios)}, Σ iterations {sum(r[0] for r in rows)} against {sum(r[1] for r in rows)}; "
        f"lower J than the reference's on {sum(r[2] < -1e-6 for r in rows)}, higher on "
        f"{sum(r[2] > 1e-6 for r in rows)} (other local optima; information, not a target)"
    )
    return 0


def main() -> int:
    """Print the table and the three verdicts."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--K", type=int, default=50)
    parser.add_argument("--problems", type=int, default=len(PROBLEMS))
    parser.add_argument(
        "--cold-seeds", type=int, default=0, metavar="S",
        help="instead: only the cold solve against the reference's, on n, N = 1–4 with seeds 0 … S−1 (16·S problems)",
    )  # fmt: skip
    args = parser.parse_args()
    if args.cold_seeds:
        return cold_against_reference(args.cold_seeds, args.K)
    print(f"load average before: {os.getloadavg()[0]:.2f} (2 cores); K = {args.K}")
    print(
        "| n, N, seed | best J | default J (excess) | kept | default it | cold (excess, it) | "
        "homotopy (excess, it) | multistart-4 (excess) | reference cold it | cold ÷ reference it | "
        "budgeted continuation ÷ cold it | default s | cold s | default ÷ cold (it; s) |"
    )
    print("| --- | " + " | ".join("---" for _ in range(13)) + " |")
    excess_default, ratios_ref, ratios_hom, elapsed, ratios_default = [], [], [], [], []
    for n, N, seed in PROBLEMS[: args.problems]:
        data = synthetic_problem(n, N, seed, intervals=args.K)
        problem = Problem.from_dict(data)
        t0 = time.perf_counter()
        default = solve_direct(problem)
        elapsed.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        alone = solve_direct(problem.with_solver(strategy="cold"))
        cold_s = time.perf_counter() - t0
        budgeted = starts(solve_direct(problem.with_solver(strategy="homotopy")))
        everything = solve_direct(
            problem.with_solver(strategy="thorough", homotopy={"mode": "fixed", "step": 0.05, "budget": None})
        )
        ref = ReferenceOCP(data, intervals=args.K).solve()
        runs = starts(everything)
        cold, hom = runs["cold"], runs["homotopy"]
        multi = [s["cost"] for label, s in runs.items() if label.startswith("random start") and s["cost"] is not None]
        candidates = [c for c in (cold["cost"], hom["cost"], min(multi, default=None)) if c is not None]
        best = min(candidates)

        def excess(J: float | None, best: float = best) -> str:
            return "fail" if J is None else f"{(J - best) / abs(best):.1e}"

        d = starts(default)
        J = default.cost if default.success else float("inf")
        excess_default.append((J - best) / abs(best))
        if ref.success and cold["cost"] is not None:
            ratios_ref.append(cold["iterations"] / ref.iterations)
        hom_ratio = budgeted["homotopy"]["iterations"] / budgeted["cold"]["iterations"]
        ratios_hom.append((hom_ratio, budgeted["cold"]["iterations"]))
        default_it = sum(s["iterations"] for s in d.values())
        cold_it = starts(alone)["cold"]["iterations"]
        ratios_default.append((default_it / cold_it, elapsed[-1] / cold_s))
        print(
            f"| {n}, {N}, {seed} | {best:.8g} | {J:.8g} ({excess(J)}) | {default.stats['strategy']['kept']} | "
            f"{default_it} | {excess(cold['cost'])}, {cold['iterations']} | "
            f"{excess(hom['cost'])}, {hom['iterations']} | {excess(min(multi, default=None))} | "
            f"{ref.iterations if ref.success else 'fail'} | "
            f"{cold['iterations'] / ref.iterations:.2f} | {hom_ratio:.2f} | {elapsed[-1]:.2f} | {cold_s:.2f} | "
            f"{ratios_default[-1][0]:.2f}; {ratios_default[-1][1]:.2f} |"
        )
        sys.stdout.flush()
    worst = max(excess_default)
    within = sum(e <= 1e-6 for e in excess_default)
    print(
        f"\noptimum quality: default within 1e-6 of the best of {{cold, homotopy, 4-start}} on {within}/"
        f"{len(excess_default)} problems, worst excess {worst:.1e}: {verdict(worst <= 1e-6)}"
    )
    median_ref = statistics.median(ratios_ref)
    low, high = median_interval(ratios_ref)
    print(
        f"cold ε = 1 iterations ÷ reference's: median {median_ref:.2f} (range {min(ratios_ref):.2f}–"
        f"{max(ratios_ref):.2f}, ≤ 1 on {sum(r <= 1 for r in ratios_ref)}/{len(ratios_ref)}): "
        f"{verdict(median_ref <= 1.0)} (median), {verdict(max(ratios_ref) <= 1.0)} (every problem)"
    )
    print(
        f"  95 % bootstrap interval of that median over problems like these: {low:.2f}–{high:.2f} (the cold solves "
        "of nonconvex problems take different paths to different optima: information, not a target)"
    )
    over = [r for r, c in ratios_hom if r > 1.5 + 1.0 / c]
    print(
        f"budgeted continuation ÷ its cold solve (iterations): max {max(r for r, _ in ratios_hom):.2f}, "
        f"over 1.5 (+1 iteration) on {len(over)}/{len(ratios_hom)}: {verdict(not over)}"
    )
    print(f"default solve wall time: median {statistics.median(elapsed):.2f} s, max {max(elapsed):.2f} s")
    it_r, s_r = zip(*ratios_default, strict=True)
    print(
        f"default ÷ cold solve: iterations median {statistics.median(it_r):.2f} (range {min(it_r):.2f}–"
        f"{max(it_r):.2f}), wall time median {statistics.median(s_r):.2f} (range {min(s_r):.2f}–{max(s_r):.2f})"
    )
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
