"""Validate problem files without solving: one line per file, exit 2 at the first invalid one."""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``validate`` arguments."""
    parser.add_argument("files", type=Path, nargs="+", help="problem YAML files")


def run(args: argparse.Namespace) -> int:
    """Validate each file; print a one-line description of each valid problem."""
    from ocp.problem import load_problem

    for path in args.files:
        problem = load_problem(path)  # ConfigError -> exit 2 with file and key path
        c = problem.solver.collocation
        print(
            f"{path}: valid — problem {problem.name!r}: n = {problem.n} states, N = {problem.N} sensors, "
            f"t ∈ [{problem.horizon.t0:g}, {problem.horizon.tf:g}], {problem.solver.method} "
            f"({c.scheme} d = {c.degree}, {c.intervals} intervals), hash {problem.digest()}"
        )
    return 0
