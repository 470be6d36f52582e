"""The optimal-control commands: ``mobisense solve`` and ``mobisense sweep``, and their files' checks.

Each command is a class with a one-line docstring (its help text), ``add_arguments(parser)`` and
``run(args) -> int``; :mod:`mobisense.cli` registers them. Heavy modules are imported inside ``run``,
so that ``mobisense --help`` stays fast. :func:`check_problem` and :func:`check_sweep` validate a file
of each kind for ``mobisense validate`` (see :mod:`mobisense.core.kinds`).
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path
from typing import Any

from ..core.output import output_path

__all__ = ["SolveCommand", "SweepCommand", "apply_overrides", "check_problem", "check_sweep"]


class SolveCommand:
    """Solve a mobile-sensor problem file and write summary.json, solution.nc and figures."""

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        """Add the ``solve`` arguments."""
        from ..core.budget import add_budget_argument
        from .batch.cluster import add_cluster_arguments, positive_int
        from .registries import HOMOTOPY_MODES, METHODS, SCHEMES, STRATEGIES

        parser.add_argument(
            "problem", type=Path, help="problem YAML file, or the name of a shipped example (mobisense examples)"
        )
        parser.add_argument("--out", type=output_path, default=None, help="output folder (default: out/<file name>)")
        parser.add_argument("--method", choices=METHODS.names(), default=None, help="override solver.method")
        parser.add_argument(
            "--intervals", type=int, default=None,
            help="override solver.collocation.intervals (solver.shooting.intervals with the shooting method)",
        )  # fmt: skip
        parser.add_argument("--degree", type=int, default=None, help="override solver.collocation.degree")
        parser.add_argument(
            "--scheme", choices=SCHEMES.names(), default=None, help="override solver.collocation.scheme"
        )
        parser.add_argument(
            "--homotopy",
            choices=HOMOTOPY_MODES.names(),
            default=None,
            help="override solver.homotopy.mode (the ε-continuation: always started by --strategy homotopy, by auto "
            "only when its starts disagree; both within --homotopy-budget)",
        )
        parser.add_argument("--step", type=float, default=None, help="override solver.homotopy.step (δ)")
        parser.add_argument(
            "--homotopy-budget", type=_homotopy_budget, default=None, metavar="B",
            help="override solver.homotopy.budget: the continuation may take at most B × the cold solve's Ipopt "
            "iterations (default 1.5; beyond, it stops and the cold solve is kept), or 'none': no limit, the "
            "continuation runs to ε = 1 (with --strategy homotopy, then without a cold solve)",
        )  # fmt: skip
        parser.add_argument(
            "--strategy",
            choices=STRATEGIES.names(),
            default=None,
            help="override solver.strategy (direct method: which starts to solve, docs/theory/direct.md §5.6)",
        )
        figures = parser.add_mutually_exclusive_group()
        figures.add_argument("--no-plot", action="store_true", help="skip the figures")
        figures.add_argument(
            "--plot",
            type=_names,
            default=None,
            metavar="NAMES",
            help="write only these figures, a comma list of paths, covariance, controls, homotopy, continuation "
            "(field problems: variance_maps, trace, controls, homotopy); default: all",
        )
        parser.add_argument(
            "--sensitivities",
            action="store_true",
            help="direct method: add dJ*/d(value) of every number of the file to summary.json "
            "(envelope theorem, docs/theory/path_constraints.md §4)",
        )
        parser.add_argument("--quiet", action="store_true", help="no progress display or table")
        parser.add_argument(
            "--multistart",
            type=positive_int,
            default=None,
            metavar="K",
            help="solve from K initial guesses (start 0: the problem's solve strategy, solver.strategy; others: "
            "random feasible trajectories solved at ε = 1) on dask workers and keep the best",
        )
        add_cluster_arguments(parser, "--multistart")
        parser.add_argument(
            "--time-limit",
            type=float,
            default=None,
            metavar="S",
            help="wall-clock limit of each Ipopt solve (sets solver.time_limit; a solve it stops exits 1 and keeps "
            "what was solved)",
        )
        add_budget_argument(parser, "--time-limit (solver.time_limit in the problem file)")

    @staticmethod
    def run(args: argparse.Namespace) -> int:
        """Validate, solve, write outputs; exit 0 (solved), 1 (solver failure, partial results kept), 2 (bad input)."""
        # the figure workers start first: their imports (≈ 0.7 s) overlap the validation, the build and the solve
        with _figure_workers(args) as figures:
            return _solve(args, figures)


def _solve(args: argparse.Namespace, figures: Any) -> int:
    """The solve command once the figure workers (``None`` with ``--no-plot``) are started."""
    from ..core.budget import check_budget
    from ..core.config import ConfigError, read_yaml
    from ..core.errors import numerical_failures
    from ..core.examples import resolve_input
    from ..core.kinds import check_command_kind
    from ..core.output import OutputFolder, default_output_folder, input_files
    from .batch.cluster import Cluster
    from .problem import Problem
    from .reporting import SolveReporter
    from .sizes import problem_estimates

    args.problem = resolve_input(args.problem)
    source = str(args.problem)
    data = read_yaml(args.problem)
    check_command_kind(data, source, ("problem",))  # a formation, sweep, … file: the command that runs it
    data = apply_overrides(data, args)
    if _given_method(data) == "shooting":  # the flags first: the file's model would name their keys instead
        if args.degree is not None or args.scheme is not None:
            raise ConfigError(f"{source}: --degree/--scheme: the shooting method has no collocation polynomials (its "
                              "grid is solver.shooting: --intervals sets K)")  # fmt: skip
        given = [flag for flag, value in (("--strategy", args.strategy), ("--homotopy", args.homotopy),
                                          ("--step", args.step), ("--homotopy-budget", args.homotopy_budget))
                 if value is not None]  # fmt: skip
        if given:  # accepted and silently without effect before (field audit)
            raise ConfigError(f"{source}: {'/'.join(given)}: the shooting method runs its own ε schedule (0.03 … 1 on "
                              "a coarse grid, then ε = 1 on the fine one: docs/theory/field.md §3.4); leave "
                              f"{'them' if len(given) > 1 else 'it'} out")  # fmt: skip
    try:
        problem = Problem.from_dict(data, source=source)  # ConfigError -> exit 2, nothing written
    except ConfigError as err:
        raise _named_flag(err, source, args) from None
    cluster = Cluster.from_args(args)
    if args.multistart is None and (cluster.scheduler or cluster.workers):
        raise ConfigError(f"{source}: --workers/--scheduler: only used with --multistart")
    if args.plot is not None:
        from .plots import figure_names

        field = problem.process.field is not None
        known = figure_names(field)
        unknown = ", ".join(repr(name) for name in args.plot if name not in known)
        kind = "field problem" if field else "problem"
        if unknown:  # the file decides which figures exist (a field's are others)
            raise ConfigError(f"--plot: no figure {unknown} for the {kind} of {source}; expected some of "
                              f"{', '.join(known)}")  # fmt: skip
        if "continuation" in args.plot and problem.solver.method not in ("indirect", "both"):
            raise ConfigError(f"--plot continuation: only the indirect method draws it (--method indirect or both); "
                              f"{source} is solved by the {problem.solver.method} method")  # fmt: skip
    if args.sensitivities and problem.solver.method != "direct":
        raise ConfigError(f"{source}: --sensitivities: expected solver.method 'direct'")
    if args.multistart is not None:
        from ..core.extras import require_extra

        if problem.solver.method != "direct":
            hint = "; a field's shooting draws random starts itself: solver.shooting.starts" if (
                problem.solver.method == "shooting") else ""
            raise ConfigError(f"{source}: --multistart: expected solver.method 'direct', got "
                              f"{problem.solver.method!r}{hint}")  # fmt: skip

        require_extra("sweep", "mobisense solve --multistart")
    starts = args.multistart or 1
    local = 0 if args.multistart is None or cluster.scheduler else min(starts, _local_workers(cluster.workers))
    estimates = problem_estimates(problem, starts=starts, local_workers=local)
    check_budget(estimates, args.max_memory, source, args.max_time)
    folder = OutputFolder.check(args.out if args.out is not None else default_output_folder(args.problem),
                                inputs=input_files(args.problem))
    reporter = SolveReporter(problem, quiet=args.quiet)
    with folder.lock():
        out = folder.path
        with numerical_failures(f"solving {source}"):
            if args.multistart is not None:
                from .batch.multistart import solve_multistart

                solution = solve_multistart(problem, starts, cluster.scheduler, cluster.workers, cluster.security)
            else:
                solution = reporter.run(problem.solver.method)
            if args.sensitivities and solution.success and solution.nlp is not None:
                from .direct.sensitivities import solution_sensitivities
                from .direct.transcription import transcription_for

                solution.stats["sensitivities"] = solution_sensitivities(transcription_for(problem), solution)
        from .plots import figure_names

        # an earlier run's figures in this folder would describe another solution: removed, the new ones drawn
        folder.remove_previous([f"{name}.png" for name in {*figure_names(True), *figure_names(False)}])
        if figures is not None:
            figures.send(solution, out, args.plot)  # drawn by the workers while solution.nc is written
        solution.save(out)
        if figures is not None:
            with numerical_failures(f"plotting {source}"):
                figures.wait()
        reporter.report(solution, out)
    if not solution.success:
        print(f"mobisense: solver failure: {solution.message}", file=sys.stderr)
        return 1
    warning = solution.summary().get("warning")
    if warning:
        print(f"mobisense: warning: {warning}", file=sys.stderr)
    return 0


def _figure_workers(args: argparse.Namespace) -> Any:
    """Figure workers started before the solve (importing matplotlib meanwhile), or nothing with ``--no-plot``."""
    if args.no_plot:
        return contextlib.nullcontext()
    from .figure_workers import FigureWorkers, figure_worker_count

    return FigureWorkers(figure_worker_count(len(args.plot) if args.plot else None))


def _names(text: str) -> list[str]:
    """``a,b, c`` -> ``["a", "b", "c"]`` (argparse type of ``--plot``)."""
    names = [name.strip().removesuffix(".png") for name in text.split(",") if name.strip()]
    if not names:
        raise argparse.ArgumentTypeError("expected a comma list of figure names")
    return names


#: what ``--homotopy-budget`` accepts for "no limit" (YAML ``budget: null``)
_NO_BUDGET = "none"


def _homotopy_budget(text: str) -> float | str:
    """The argparse type of ``--homotopy-budget``: a number in (0, 1000] or ``none``."""
    if text.strip().lower() == _NO_BUDGET:
        return _NO_BUDGET
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number in (0, 1000] or 'none', got {text[:40]!r}") from None
    if not 0.0 < value <= 1000.0:
        raise argparse.ArgumentTypeError(f"expected a number in (0, 1000] or 'none', got {text[:40]}")
    return value


def _local_workers(requested: int | None) -> int:
    import os

    return requested or os.cpu_count() or 1


#: the command-line flags that override keys of the file, and those keys
FLAG_KEYS = {
    "--intervals": ("solver.collocation.intervals", "solver.shooting.intervals", "solver.shooting.coarse_intervals"),
    "--degree": ("solver.collocation.degree",),
    "--step": ("solver.homotopy.step",),
    "--time-limit": ("solver.time_limit",),
}


def _named_flag(err: Exception, source: str, args: argparse.Namespace) -> Exception:
    """``err`` about a key a flag set, reworded to name the flag (the file holds another value), else ``err``."""
    from ..core.config import ConfigError

    text = str(err)
    for flag, keys in FLAG_KEYS.items():
        value = getattr(args, flag[2:].replace("-", "_"), None)
        for key in keys:
            prefix = f"{source}: {key}:"
            if value is not None and text.startswith(prefix):
                return ConfigError(f"{source}: {flag} {value:g}: {text[len(prefix) :].strip()} (it sets {key})")
    return err


def _given_method(data: Any) -> str | None:
    """``solver.method`` of a raw problem dict as its model will decide it (None for a malformed file)."""
    if not isinstance(data, dict) or not isinstance(data.get("solver", {}), dict):
        return None
    process = data.get("process")
    field = isinstance(process, dict) and process.get("field") is not None
    return data.get("solver", {}).get("method", "shooting" if field else "direct")


def apply_overrides(data: dict[str, Any], args: argparse.Namespace) -> dict[str, Any]:
    """Apply command-line overrides to the raw problem dict (validated afterwards like the file)."""
    if not isinstance(data, dict):  # the model says what a file of another shape lacks
        return data
    solver = data.setdefault("solver", {})
    if not isinstance(solver, dict):
        return data
    if args.method is not None:
        solver["method"] = args.method
    if getattr(args, "time_limit", None) is not None:
        solver["time_limit"] = args.time_limit
    if args.strategy is not None:
        solver["strategy"] = args.strategy
    collocation = {
        k: v
        for k, v in (("intervals", args.intervals), ("degree", args.degree), ("scheme", args.scheme))
        if v is not None
    }
    if "intervals" in collocation and _given_method(data) == "shooting":
        shooting = solver.setdefault("shooting", {})  # the grid this method solves on (no collocation)
        if isinstance(shooting, dict):
            from .field import ShootingOptions

            shooting["intervals"] = K = collocation.pop("intervals")
            coarse = shooting.get("coarse_intervals", ShootingOptions.model_fields["coarse_intervals"].default)
            if isinstance(K, int) and isinstance(coarse, int) and K < coarse:  # the homotopy's grid no finer
                shooting["coarse_intervals"] = max(K, 2)
    if collocation:
        solver.setdefault("collocation", {}).update(collocation)
    homotopy = {k: v for k, v in (("mode", args.homotopy), ("step", args.step)) if v is not None}
    budget = getattr(args, "homotopy_budget", None)
    if budget is not None:
        homotopy["budget"] = None if budget == _NO_BUDGET else budget
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
        f"t in [{problem.horizon.t0:.10g}, {problem.horizon.tf:.10g}] {u.time}, {problem.solver.method} method "
        f"({grid}), problem hash {problem.digest()}"
    )


def _count(number: int, noun: str) -> str:
    return f"{number} {noun}{'' if number == 1 else 's'}"


def check_sweep(data: dict[str, Any], path: Path, kind: str = "sweep") -> str:
    """Validate a sweep file, its base problem and every task it expands to; one line saying what it is."""
    from .batch.sweep import iter_tasks, load_sweep

    spec, base = load_sweep(path)
    count = sum(1 for _ in iter_tasks(spec, base, source=str(path)))  # one validated task in memory at a time
    sizes = " x ".join(f"{key} ({len(values)} values)" for key, values in spec.vary.items())
    return f"parameter sweep ({spec.mode}) of {count} tasks over {sizes}, base problem {base.name!r}"


class SweepCommand:
    """Run a parameter sweep on dask (local processes or a cluster); resumable, results in results.parquet."""

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        """Add the ``sweep`` arguments."""
        from ..core.budget import add_budget_argument
        from .batch.cluster import add_cluster_arguments

        parser.add_argument("sweep", type=Path, help="sweep YAML file (base problem, mode, vary) or a shipped example")
        parser.add_argument("--out", type=output_path, default=None, help="output folder (default out/<file name>)")
        add_cluster_arguments(parser, "the tasks")
        parser.add_argument("--no-warm-start", action="store_true", help="solve every task from the coasting guess")
        parser.add_argument(
            "--time-limit",
            type=float,
            default=None,
            metavar="S",
            help="wall-clock limit of each Ipopt solve of a task (sets solver.time_limit)",
        )
        parser.add_argument("--quiet", action="store_true", help="no progress display")
        add_budget_argument(parser, "--time-limit (solver.time_limit of each task)")
        parser.add_argument("--no-plot", action="store_true", help="skip cost.png (the cost over the varied keys)")

    @staticmethod
    def run(args: argparse.Namespace) -> int:
        """Validate the whole sweep, then run the tasks not finished before; write rows as they complete."""
        from ..core.examples import resolve_input
        from ..core.extras import require_extra
        from ..core.output import default_output_folder
        from .batch.cluster import Cluster
        from .batch.sweep_runner import run_sweep

        require_extra("sweep", "mobisense sweep")
        args.sweep = resolve_input(args.sweep)
        cluster = Cluster.from_args(args)
        out = args.out if args.out is not None else default_output_folder(args.sweep)
        result = run_sweep(
            args.sweep,
            out,
            scheduler=cluster.scheduler,
            workers=cluster.workers,
            warm_start=not args.no_warm_start,
            time_limit=args.time_limit,
            quiet=args.quiet,
            security=cluster.security,
            max_memory=args.max_memory,
            max_time=args.max_time,
        )
        if not args.no_plot and len(result.table):
            from ..core.errors import numerical_failures
            from .batch.sweep_plots import save_sweep_figures

            with numerical_failures(f"plotting {args.sweep}"):
                save_sweep_figures(result)
        elif args.no_plot:  # an earlier run's cost.png shows fewer tasks than the results now hold
            (result.folder / "cost.png").unlink(missing_ok=True)
        counts = result.summary["counts"]
        if counts.get("warned"):
            first = result.summary["first_warning"]
            print(
                f"mobisense: warning: {counts['warned']} of {counts['solved']} solved tasks have warnings (column "
                f"'warning' of results.parquet); task #{first['index']}: {first['warning']}",
                file=sys.stderr,
            )
        unsolved = counts["failed"] + counts["error"]
        if unsolved:  # like solve: exit 1 when a solve did not converge; every row, and why, is in the results
            print(
                f"mobisense: {unsolved} of {counts['tasks']} tasks not solved ({counts['failed']} failed, "
                f"{counts['error']} errors; their rows give the reason) in {result.folder}",
                file=sys.stderr,
            )
            return 1
        return 0
