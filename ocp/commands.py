"""Solve a mobile-sensor problem file and write summary.json, solution.nc and figures."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

__all__ = ["add_arguments", "run", "apply_overrides"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``solve`` arguments."""
    parser.add_argument("problem", type=Path, help="problem YAML file (see problems/hussein2008.yaml)")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default: out/<problem name>)")
    parser.add_argument("--method", choices=["direct", "indirect", "both"], default=None, help="override solver.method")
    parser.add_argument("--intervals", type=int, default=None, help="override solver.collocation.intervals")
    parser.add_argument("--degree", type=int, default=None, help="override solver.collocation.degree")
    parser.add_argument(
        "--scheme", choices=["radau", "legendre"], default=None, help="override solver.collocation.scheme"
    )
    parser.add_argument(
        "--homotopy", choices=["fixed", "adaptive", "none"], default=None, help="override solver.homotopy.mode"
    )
    parser.add_argument("--step", type=float, default=None, help="override solver.homotopy.step (δ)")
    parser.add_argument("--no-plot", action="store_true", help="skip the figures")
    parser.add_argument("--quiet", action="store_true", help="no progress display or table")
    parser.add_argument(
        "--multistart",
        type=int,
        default=None,
        metavar="K",
        help="solve from K initial guesses (start 0: the homotopy; others: random feasible "
        "trajectories solved at ε = 1) on dask workers and keep the best",
    )
    parser.add_argument("--workers", type=int, default=None, help="local worker processes for --multistart")
    parser.add_argument("--scheduler", default=None, help="dask scheduler address for --multistart")


def apply_overrides(data: dict[str, Any], args: argparse.Namespace) -> dict[str, Any]:
    """Apply command-line overrides to the raw problem dict (validated afterwards like the file)."""
    solver = data.setdefault("solver", {}) if isinstance(data, dict) else {}
    if not isinstance(solver, dict):
        return data
    if args.method is not None:
        solver["method"] = args.method
    collocation = {
        k: v
        for k, v in (("intervals", args.intervals), ("degree", args.degree), ("scheme", args.scheme))
        if v is not None
    }
    if collocation:
        solver.setdefault("collocation", {}).update(collocation)
    homotopy = {k: v for k, v in (("mode", args.homotopy), ("step", args.step)) if v is not None}
    if homotopy:
        solver.setdefault("homotopy", {}).update(homotopy)
    return data


def run(args: argparse.Namespace) -> int:
    """Validate, solve, write outputs; exit 0 (solved), 1 (solver failure, partial results kept), 2 (bad input)."""
    from ocp.config import ConfigError, read_yaml
    from ocp.problem import Problem
    from ocp.reporting import SolveReporter

    data = apply_overrides(read_yaml(args.problem), args)
    problem = Problem.from_dict(data, source=str(args.problem))  # ConfigError -> exit 2, nothing written
    out = args.out if args.out is not None else Path("out") / problem.name
    reporter = SolveReporter(problem, quiet=args.quiet)
    if args.multistart is not None:
        if args.multistart < 1 or problem.solver.method != "direct":
            raise ConfigError(f"{args.problem}: --multistart: expected K >= 1 with solver.method 'direct'")
        from ocp.multistart import solve_multistart

        solution = solve_multistart(problem, args.multistart, args.scheduler, args.workers)
    else:
        solution = reporter.run(problem.solver.method)
    solution.save(out)
    if not args.no_plot:
        from ocp.plots import save_figures

        save_figures(solution, out)
    reporter.report(solution, out)
    if not solution.success:
        print(f"mobisense: solver failure: {solution.message}", file=sys.stderr)
        return 1
    return 0
