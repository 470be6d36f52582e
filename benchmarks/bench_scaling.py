"""Scaling of the direct method and the reference with K, N and n: time, iterations, memory, where time goes.

Each point is one cold ε = 1 solve from the coasting guess (tolerance 1e-9), of the synthetic problem
``reference_transcription.synthetic_problem(n, N, 0)`` on K Radau-3 intervals, by mobisense
(:class:`mobisense.ocp.direct.DirectCollocation`, kernels compiled and cached beforehand) and by the
independent reference transcription (:mod:`reference_transcription`, no mobisense code), each in a fresh
process so that the peak resident memory (``ru_maxrss``, imports included) is that solve's. Ipopt's own
timing statistics split the solve's wall time into

* **linear solve**: ``StdAugSystemSolverMultiSolve`` (MUMPS factorisation and back-solves of the KKT system),
* **evaluations**: ``Function Evaluations`` (objective, constraints, derivatives: CasADi),
* **other**: the rest of ``OverallAlgorithm`` (Ipopt's vector algebra, line search, convergence checks).

The growth exponent of a column along one axis is the least-squares slope of log(value) against
log(axis) (time ∝ K^p). Default run (≈ 5 minutes on 2 cores): K = 50–800 at n = 1, N = 2; N = 1–8 at
n = 1, K = 100; n = 1–4 at N = 2, K = 100. ``--full``: every combination of K ∈ {50, 100, 200, 400, 800},
N ∈ {1, 2, 4, 8}, n ∈ {1, 2, 3, 4} (hours).

Usage: ``python benchmarks/bench_scaling.py [--full] [--markdown FILE]``
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
#: default axes: (name, values, the other two fixed) as (n, N, K) tuples
AXES: dict[str, list[tuple[int, int, int]]] = {
    "K": [(1, 2, K) for K in (50, 100, 200, 400, 800)],
    "N": [(1, N, 100) for N in (1, 2, 4, 8)],
    "n": [(n, 2, 100) for n in (1, 2, 3, 4)],
}
FULL = [(n, N, K) for n in (1, 2, 3, 4) for N in (1, 2, 4, 8) for K in (50, 100, 200, 400, 800)]
#: Ipopt timing-statistics lines read from its output file: key -> (label in the file)
TIMERS = {
    "overall": "OverallAlgorithm",
    "linear": "StdAugSystemSolverMultiSolve",
    "evaluations": "Function Evaluations",
}


def ipopt_timers(text: str) -> dict[str, float]:
    """Wall seconds of :data:`TIMERS` from Ipopt's ``print_timing_statistics`` output."""
    out = {}
    for key, label in TIMERS.items():
        match = re.search(rf"^\s*{re.escape(label)}\.*:\s*\S+ \(sys:\s*\S+ wall:\s*(\S+)\)", text, re.MULTILINE)
        out[key] = float(match.group(1)) if match else float("nan")
    return out


def one(which: str, n: int, N: int, K: int) -> dict[str, Any]:
    """Build and solve one point in this process (see module docstring); what was measured."""
    import resource
    import time

    sys.path.insert(0, str(HERE))
    from reference_transcription import ReferenceOCP, synthetic_problem

    data = synthetic_problem(n, N, 0, intervals=K)
    with tempfile.TemporaryDirectory() as folder:
        log = Path(folder) / "ipopt.txt"
        timing = {"print_timing_statistics": "yes", "output_file": str(log), "file_print_level": 3}
        t0 = time.perf_counter()
        if which == "reference":
            ref = ReferenceOCP(data, intervals=K, ipopt_options=timing)
            build = time.perf_counter() - t0
            r = ref.solve()
            iterations, success, solve_s, size = r.iterations, r.success, r.solve_s, (ref.nw, ref.ng)
        else:
            from mobisense import Problem
            from mobisense.ocp import Structure
            from mobisense.ocp.direct import DirectCollocation, coasting_start

            problem = Problem.from_dict(data)
            tr = DirectCollocation(Structure.of(problem), "radau", 3, K, ipopt_options=timing, codegen="on")
            build = time.perf_counter() - t0
            P, w0 = coasting_start(problem, tr)
            r = tr.solve(P, w0)
            iterations, success, solve_s, size = r.iterations, r.success, r.time_s, (tr.nw, tr.ng)
        timers = ipopt_timers(log.read_text(encoding="utf-8"))
    return {
        "which": which,
        "n": n,
        "N": N,
        "K": K,
        "build_s": build,
        "solve_s": solve_s,
        "iterations": iterations,
        "success": success,
        "size": size,
        "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        **timers,
    }


def run_point(which: str, n: int, N: int, K: int) -> dict[str, Any]:
    """:func:`one` in a fresh process."""
    argv = [sys.executable, str(Path(__file__).resolve()), "--one", which, str(n), str(N), str(K)]
    out = subprocess.run(argv, capture_output=True, text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def slope(x: list[float], y: list[float]) -> float:
    """Least-squares slope of log y against log x."""
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def table(points: list[tuple[int, int, int]], results: dict[tuple, dict]) -> list[str]:
    """Markdown rows of every point: mobisense and reference side by side."""
    lines = [
        "| n, N, K | NLP size (mobisense; reference) | iterations | solve s | ms/iteration | peak RSS MB | "
        "mobisense time: linear solve / evaluations / other | reference: linear / evaluations / other |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for p in points:
        m, r = results[("mobisense", *p)], results[("reference", *p)]

        def split(d: dict) -> str:
            total = d["overall"]
            ev, lin = d["evaluations"], d["linear"]
            return f"{100 * lin / total:.0f} % / {100 * ev / total:.0f} % / {100 * (total - lin - ev) / total:.0f} %"

        lines.append(
            f"| {p[0]}, {p[1]}, {p[2]} | {m['size'][0]} × {m['size'][1]}; {r['size'][0]} × {r['size'][1]} | "
            f"{m['iterations']}; {r['iterations']} | {m['solve_s']:.2f}; {r['solve_s']:.2f} | "
            f"{1e3 * m['solve_s'] / max(m['iterations'], 1):.1f}; {1e3 * r['solve_s'] / max(r['iterations'], 1):.1f} | "
            f"{m['rss_mb']:.0f}; {r['rss_mb']:.0f} | {split(m)} | {split(r)} |"
        )
    return lines


def exponents(results: dict[tuple, dict]) -> list[str]:
    """Growth exponents along each default axis (see module docstring)."""
    lines = [
        "| axis | range | ms/iteration ∝ | iterations ∝ | solve time ∝ | peak RSS ∝ | build ∝ |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for axis, points in AXES.items():
        index = "nNK".index(axis)
        x = [float(p[index]) for p in points]
        cells = []
        for key in ("per_it", "iterations", "solve_s", "rss_mb", "build_s"):
            pair = []
            for which in ("mobisense", "reference"):
                rows = [results[(which, *p)] for p in points]
                y = [r["solve_s"] / max(r["iterations"], 1) if key == "per_it" else float(r[key]) for r in rows]
                pair.append(f"{slope(x, y):.2f}")
            cells.append(" ; ".join(pair))
        lines.append(f"| {axis} | {int(min(x))}–{int(max(x))} | " + " | ".join(f"{axis}^({c})" for c in cells) + " |")
    return lines


def main() -> int:
    """Run the grid, print the tables (and write them to ``--markdown``)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="every combination of K, N, n (hours)")
    parser.add_argument("--markdown", type=Path, help="also write the tables to this file")
    parser.add_argument("--one", nargs=4, metavar=("WHICH", "n", "N", "K"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        which, *sizes = args.one
        print(json.dumps(one(which, *(int(v) for v in sizes))))
        return 0
    load = os.getloadavg()[0]
    points = sorted({p for axis in AXES.values() for p in axis} | (set(FULL) if args.full else set()))
    for n, N in sorted({(n, N) for n, N, _ in points}):  # compile the kernels of each structure once, untimed
        run_point("mobisense", n, N, 4)
    results: dict[tuple, dict] = {}
    for p in points:
        for which in ("mobisense", "reference"):
            results[(which, *p)] = run_point(which, *p)
        print(
            f"done {p}: mobisense {results[('mobisense', *p)]['solve_s']:.2f} s, "
            f"reference {results[('reference', *p)]['solve_s']:.2f} s",
            file=sys.stderr,
        )
    lines = [
        f"load average before: {load:.2f}, after: {os.getloadavg()[0]:.2f} (2 cores). Cells: mobisense; reference.",
        "",
        *table(points, results),
        "",
        "Growth exponents (least-squares slope in log–log; mobisense ; reference):",
        "",
        *exponents(results),
    ]
    print("\n".join(lines))
    if args.markdown:
        args.markdown.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
