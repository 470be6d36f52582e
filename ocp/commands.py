"""The optimal-control commands: ``mobisense solve`` and ``mobisense sweep``, and their files' checks.

Each command is a class with a one-line docstring (its help text), ``add_arguments(parser)`` and
``run(args) -> int``; :mod:`mobisense.cli` registers them. Heavy modules are imported inside ``run``,
so that ``mobisense --help`` stays fast. :func:`check_problem` and :func:`check_sweep` validate a file
of each kind for ``mobisense validate`` (see :mod:`mobisense.core.kinds`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

__all__ = ["SolveCommand", "SweepCommand", "apply_overrides", "check_problem", "check_sweep"]


class SolveCommand:
    """Solve a mobile-sensor problem file and write summary.json, solution.nc and figures."""

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        """Add the ``solve`` arguments."""
        from .registries import HOMOTOPY_MODES, METHODS, SCHEMES

        parser.add_argument(
            "problem", type=Path, help="problem YAML file, or the name of a shipped example (mobisense examples)"
        )
        parser.add_argument("--out", type=Path, default=None, help="output folder (default: out/<file name>)")
        parser.add_argument("--method", choices=METHODS.names(), default=None, help="override solver.method")
        parser.add_argument("--intervals", type=int, default=None, help="override solver.collocation.intervals")
        parser.add_argument("--degree", type=int, default=None, help="override solver.collocation.degree")
        parser.add_argument(
            "--scheme", choices=SCHEMES.names(), default=None, help="override solver.collocation.scheme"
        )
        parser.add_argument(
            "--homotopy", choices=HOMOTOPY_MODES.names(), default=None, help="override solver.homotopy.mode"
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

    @staticmethod
    def run(args: argparse.Namespace) -> int:
        """Validate, solve, write outputs; exit 0 (solved), 1 (solver failure, partial results kept), 2 (bad input)."""
        from ..core.config import ConfigError, read_yaml
        from ..core.examples import resolve_input
        from ..core.output import default_output_folder
        from .problem import Problem
        from .reporting import SolveReporter

        args.problem = resolve_input(args.problem)
        data = apply_overrides(read_yaml(args.problem), args)
        problem = Problem.from_dict(data, source=str(args.problem))  # ConfigError -> exit 2, nothing written
        out = args.out if args.out is not None else default_output_folder(args.problem)
        reporter = SolveReporter(problem, quiet=args.quiet)
        if args.multistart is not None:
            if args.multistart < 1 or problem.solver.method != "direct":
                raise ConfigError(f"{args.problem}: --multistart: expected K >= 1 with solver.method 'direct'")
            from ..core.extras import require_extra

            require_extra("sweep", "mobisense solve --multistart")
            from .batch.multistart import solve_multistart

            solution = solve_multistart(problem, args.multistart, args.scheduler, args.workers)
        else:
            solution = reporter.run(problem.solver.method)
        solution.save(out)
        if not args.no_plot:
            from .plots import save_figures

            save_figures(solution, out)
        reporter.report(solution, out)
        if not solution.success:
            print(f"mobisense: solver failure: {solution.message}", file=sys.stderr)
            return 1
        return 0


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


def check_problem(data: dict[str, Any], path: Path, kind: str = "problem") -> str:
    """Validate a problem file's data; one line saying what it is (``ConfigError`` if invalid)."""
    from .problem import Problem

    problem = Problem.from_dict(data, source=str(path))
    c, u = problem.solver.collocation, problem.units
    grid = f"{c.scheme}, degree {c.degree}, {c.intervals} intervals"
    if problem.solver.method == "shooting":
        s, (nx, ny) = problem.solver.shooting, problem.process.field.grid
        grid = f"{nx}×{ny} field, {s.intervals} intervals after a {s.coarse_intervals}-interval homotopy"
    return (
        f"optimal-control problem {problem.name!r}: {_count(problem.n, 'process state')}, "
        f"{_count(problem.N, 'sensor')}, "
        f"t in [{problem.horizon.t0:g}, {problem.horizon.tf:g}] {u.time}, {problem.solver.method} method "
        f"({grid}), problem hash {problem.digest()}"
    )


def _count(number: int, noun: str) -> str:
    return f"{number} {noun}{'' if number == 1 else 's'}"


def check_sweep(data: dict[str, Any], path: Path, kind: str = "sweep") -> str:
    """Validate a sweep file, its base problem and every task it expands to; one line saying what it is."""
    from .batch.sweep import expand_sweep, load_sweep

    spec, base = load_sweep(path)
    tasks = expand_sweep(spec, base, source=str(path))
    sizes = " x ".join(f"{key} ({len(values)} values)" for key, values in spec.vary.items())
    return f"parameter sweep ({spec.mode}) of {len(tasks)} tasks over {sizes}, base problem {base.name!r}"


class SweepCommand:
    """Run a parameter sweep on dask (local processes or a cluster); resumable, results in results.parquet."""

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        """Add the ``sweep`` arguments."""
        parser.add_argument("sweep", type=Path, help="sweep YAML file (base problem, mode, vary) or a shipped example")
        parser.add_argument("--out", type=Path, default=None, help="output folder (default out/<file name>)")
        parser.add_argument("--scheduler", default=None, help="address of a running dask scheduler (tcp://…)")
        parser.add_argument(
            "--workers", type=int, default=None, help="local worker processes (default: one per core)"
        )
        parser.add_argument("--no-warm-start", action="store_true", help="solve every task from the coasting guess")
        parser.add_argument(
            "--time-limit",
            type=float,
            default=None,
            metavar="S",
            help="wall-clock limit of each Ipopt solve of a task (sets solver.time_limit)",
        )
        parser.add_argument("--quiet", action="store_true", help="no progress display")
        parser.add_argument("--no-plot", action="store_true", help="skip cost.png (the cost over the varied keys)")

    @staticmethod
    def run(args: argparse.Namespace) -> int:
        """Validate the whole sweep, then run the tasks not finished before; write rows as they complete."""
        from ..core.examples import resolve_input
        from ..core.extras import require_extra
        from ..core.output import default_output_folder
        from .batch.sweep_runner import run_sweep

        require_extra("sweep", "mobisense sweep")
        args.sweep = resolve_input(args.sweep)
        out = args.out if args.out is not None else default_output_folder(args.sweep)
        result = run_sweep(
            args.sweep,
            out,
            scheduler=args.scheduler,
            workers=args.workers,
            warm_start=not args.no_warm_start,
            time_limit=args.time_limit,
            quiet=args.quiet,
        )
        if not args.no_plot and len(result.table):
            from .batch.sweep_plots import save_sweep_figures

            save_sweep_figures(result)
        return 0 if result.summary["counts"]["error"] == 0 else 1
