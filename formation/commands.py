"""The closed-loop simulation commands: ``mobisense replay`` and ``mobisense simulate``.

``replay SCENARIO.yaml`` — two kinds of file, told apart by their keys:

* ``field: …`` — formation control + level-curve tracking (or an optimised reference for the centre) +
  cooperative filter on a field. Writes ``result.nc`` (``z_true, z_est, grad_true, grad_est, r, v, a, b,
  theta`` …, level ``C`` as attribute), ``summary.json`` (final ``|z − C|``, mean ``|θ|`` over the last
  quarter, RMS estimation errors, shape and reference-tracking errors) and ``paths.png``,
  ``z_estimate.png``, ``shape.png``, ``heading.png``; ``--animate`` adds ``replay.mp4`` or ``replay.gif``
  (skipped when no encoder exists).
* ``solution: …`` — an optimised plan flown by Newtonian platforms, then Monte Carlo validation of the
  Kalman filter along the flown paths against the optimiser's Σ(t). Writes ``result.nc``,
  ``summary.json``, ``paths.png``, ``covariance.png``, ``nees.png`` (and ``solution.nc`` if it had to be
  solved first).

``simulate leader-follower SCENARIO.yaml`` — unicycle leader–follower formations: ``result.nc`` (every
run along ``run``: per agent ``x, y, phi, v, omega``; per follower ``d, beta, gamma, d0, beta0, xe, ye,
deviation`` and the estimates used by the control; in ring mode the switching filter's ``active`` pairs
and ``selected_pair``), ``summary.json`` (per run and follower: final and maximum errors, monotonicity of
``|β − β0|``, mean distance, path deviation, estimation error and switching statistics) and the figures
``paths.png``, ``formation_errors.png``, ``reference_point_errors.png``, ``deviation.png`` (and, when
relevant, ``references.png``, ``active_pairs.png``).

``simulate distributed SCENARIO.yaml`` — the distributed constrained cooperative Kalman filter in an
advection–diffusion field: ``result.nc`` (``z_true``, ``z_measured``, ``z_unconstrained``,
``z_constrained`` over cell × time, sensor positions, …), ``summary.json`` (the per-cell error table and
formation metrics), ``paths.png`` and ``estimates.png``.

Every file (and every file it references) is validated before anything is written: exit 2 with one line
``FILE: key.path: …``. Exit 1 if the closed loop becomes singular, a control meets its singular set, the
mesh folds (results up to that step are written) or a solver fails.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..core.output import output_path

__all__ = ["ReplayCommand", "SimulateCommand", "SIMULATION_KINDS", "check_scenario"]

#: ``mobisense simulate KIND`` -> scenario kind of :mod:`mobisense.formation.scenarios`
SIMULATION_KINDS: dict[str, str] = {"leader-follower": "leader_follower", "distributed": "distributed"}


class ReplayCommand:
    """Replay a scenario in closed loop: a formation on a field, or an optimised plan flown and validated."""

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        """Add the ``replay`` arguments."""
        from ..core.budget import add_budget_argument

        parser.add_argument(
            "scenario", type=Path, help="scenario YAML file (see problems/replay_*.yaml) or a shipped example's name"
        )
        parser.add_argument("--out", type=output_path, default=None, help="output folder (default out/<file name>)")
        parser.add_argument("--seed", type=_seed, default=None, help="override the scenario's random seed")
        parser.add_argument("--no-plot", action="store_true", help="skip the figures")
        parser.add_argument(
            "--animate", action="store_true", help="also write replay.mp4 (or .gif) of a field replay"
        )
        parser.add_argument("--quiet", action="store_true", help="no progress bar or summary lines (as solve)")
        add_budget_argument(parser, "solver.time_limit in a plan's problem file (when its plan is solved again)")

    @staticmethod
    def run(args: argparse.Namespace) -> int:
        """Validate, replay, write the outputs; return the exit status."""
        progress = not args.quiet and sys.stderr.isatty()
        return _simulate(args, "replay", lambda scenario: scenario.run(args.seed, progress=progress,
                                                                        animate=args.animate))  # fmt: skip


class SimulateCommand:
    """Run a closed-loop simulation scenario: leader–follower formations or the distributed filter."""

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        """Add the ``simulate`` arguments."""
        from ..core.budget import add_budget_argument

        parser.add_argument("kind", choices=sorted(SIMULATION_KINDS), help="which simulation")
        parser.add_argument("scenario", type=Path, help="scenario YAML file, or a shipped example's name")
        parser.add_argument("--out", type=output_path, default=None, help="output folder (default out/<file name>)")
        parser.add_argument("--no-plot", action="store_true", help="skip the figures")
        parser.add_argument("--seed", type=_seed, default=None, help="override the scenario's random seed")
        add_budget_argument(parser)

    @staticmethod
    def run(args: argparse.Namespace) -> int:
        """Validate, simulate, write the outputs; return the exit status."""
        progress = sys.stderr.isatty()
        return _simulate(args, SIMULATION_KINDS[args.kind], lambda scenario: scenario.run(args.seed, progress=progress))


def _seed(text: str) -> int:
    """The argparse type of ``--seed``: an integer in 0 … 2⁶³ − 1 (numpy's generators refuse negative seeds)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text[:40]!r}") from None
    if not 0 <= value < 2**63:
        raise argparse.ArgumentTypeError(f"expected an integer in 0 … 2^63 - 1, got {text[:40]}")
    return value


def _simulate(args: argparse.Namespace, kind: str, run: Callable[[Any], Any]) -> int:
    """Load, budget, check the output folder, lock it, simulate, save; the exit status."""
    from ..core.budget import check_budget
    from ..core.errors import numerical_failures
    from ..core.examples import resolve_input
    from ..core.output import OutputFolder, default_output_folder, input_files
    from .scenarios import load_scenario

    args.scenario = resolve_input(args.scenario)
    source = str(args.scenario)
    scenario = load_scenario(args.scenario, kind)  # ConfigError -> exit 2, nothing written
    if getattr(args, "animate", False) and scenario.kind != "field_replay":
        from ..core.errors import ConfigError

        raise ConfigError(f"{source}: --animate: only a field replay is animated, this is a {scenario.kind} file")
    check_budget(scenario.estimates(), args.max_memory, source, args.max_time)
    folder = OutputFolder.check(args.out if args.out is not None else default_output_folder(args.scenario),
                                inputs=input_files(args.scenario, scenario.config))
    with folder.lock():
        with numerical_failures(f"simulating {source}"):
            result = run(scenario)
        problem = result.non_finite()
        if problem is not None:
            print(f"mobisense: error: {source}: the simulation diverged: {problem}", file=sys.stderr)
            return 1
        with numerical_failures(f"writing the results of {source}"):
            result.save(folder.path, figures=not args.no_plot)
        if not getattr(args, "quiet", False):
            result.report(folder.path)
    if result.summary.get("warning"):
        print(f"mobisense: warning: {result.summary['warning']}", file=sys.stderr)
    status = result.summary.get("status", "ok")
    if status != "ok":
        print(f"mobisense: {status}", file=sys.stderr)
        return 1
    return 0


def check_scenario(data: dict, path: Path, kind: str) -> str:
    """Validate a scenario file of ``kind`` (and the files it names); one line saying what it is."""
    from ..core.config import parse_config
    from .scenarios import scenario_model

    config = parse_config(data, scenario_model(kind), source=str(path))
    if kind == "plan_replay":
        from .replay.plan import resolve
        from .replay.reference import reference_status

        status = reference_status(
            resolve(path, config.solution), resolve(path, config.problem), config.task, config.tracking, str(path)
        )
        runs = config.monte_carlo.runs
        return f"plan replay {config.name!r}: {status}; Monte Carlo with {runs} runs"
    if kind == "field_replay":
        return (
            f"field replay {config.name!r}: {config.platforms.count} platforms, {config.formation.kind} formation, "
            f"{config.motion.kind.replace('_', ' ')} motion on the field {config.field.kind!r} for "
            f"{config.duration:g} {config.units.time}"
        )
    if kind == "replan":
        from .replay.replan import check_against_problem

        check_against_problem(config, path)  # the problem it flies must be valid, and the window within it
        window = "" if config.replan.length is None else f" of length {config.replan.length:g}"
        return (
            f"re-planning of {config.problem!r} every {config.replan.every:g} ({config.replan.horizon} horizon"
            f"{window}), {config.monte_carlo.runs} Monte Carlo runs"
        )
    if kind == "leader_follower":
        runs = ", ".join(f"{name} ({control})" for name, control, _, _ in config.resolved_runs())
        return (
            f"leader–follower simulation {config.name!r}: a leader and {len(config.followers)} follower(s) "
            f"for {config.duration:g} s; runs {runs}"
        )
    n_sensors, n_cells = len(config.network.positions), len(config.network.cells)
    return (
        f"distributed-filter simulation {config.name!r}: {n_sensors} sensors in {n_cells} cells, "
        f"{config.time.duration:g} s sampled every {config.time.step:g} s"
    )
