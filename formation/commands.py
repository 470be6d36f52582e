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
from pathlib import Path

__all__ = ["ReplayCommand", "SimulateCommand", "SIMULATION_KINDS", "check_scenario"]

#: ``mobisense simulate KIND`` -> scenario kind of :mod:`mobisense.formation.scenarios`
SIMULATION_KINDS: dict[str, str] = {"leader-follower": "leader_follower", "distributed": "distributed"}


class ReplayCommand:
    """Replay a scenario in closed loop: a formation on a field, or an optimised plan flown and validated."""

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        """Add the ``replay`` arguments."""
        parser.add_argument(
            "scenario", type=Path, help="scenario YAML file (see problems/replay_*.yaml) or a shipped example's name"
        )
        parser.add_argument("--out", type=Path, default=None, help="output folder (default out/<file name>)")
        parser.add_argument("--seed", type=int, default=None, help="override the scenario's random seed")
        parser.add_argument("--no-plot", action="store_true", help="skip the figures")
        parser.add_argument(
            "--animate", action="store_true", help="also write replay.mp4 (or .gif) of a field replay"
        )
        parser.add_argument("--quiet", action="store_true", help="no progress bar")

    @staticmethod
    def run(args: argparse.Namespace) -> int:
        """Validate, replay, write the outputs; return the exit status."""
        from ..core.examples import resolve_input
        from .replay.simulation import ReplayError
        from .scenarios import load_scenario

        args.scenario = resolve_input(args.scenario)
        scenario = load_scenario(args.scenario, "replay")
        progress = not args.quiet and sys.stderr.isatty()
        try:
            result = scenario.run(args.seed, progress=progress, animate=args.animate)
        except (ReplayError, RuntimeError) as err:
            print(f"mobisense: error: {args.scenario}: {err}", file=sys.stderr)
            return 1
        return _save(result, args, args.scenario)


class SimulateCommand:
    """Run a closed-loop simulation scenario: leader–follower formations or the distributed filter."""

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        """Add the ``simulate`` arguments."""
        parser.add_argument("kind", choices=sorted(SIMULATION_KINDS), help="which simulation")
        parser.add_argument("scenario", type=Path, help="scenario YAML file, or a shipped example's name")
        parser.add_argument("--out", type=Path, default=None, help="output folder (default out/<file name>)")
        parser.add_argument("--no-plot", action="store_true", help="skip the figures")
        parser.add_argument("--seed", type=int, default=None, help="override the scenario's random seed")

    @staticmethod
    def run(args: argparse.Namespace) -> int:
        """Validate, simulate, write the outputs; return the exit status."""
        from ..core.examples import resolve_input
        from .leader_follower.controls import FormationSingularityError
        from .scenarios import load_scenario

        args.scenario = resolve_input(args.scenario)
        scenario = load_scenario(args.scenario, SIMULATION_KINDS[args.kind])
        try:
            result = scenario.run(args.seed, progress=sys.stderr.isatty())
        except (FormationSingularityError, RuntimeError) as err:
            print(f"mobisense: error: {args.scenario}: {err}", file=sys.stderr)
            return 1
        status = _save(result, args, args.scenario)
        if result.summary.get("status", "ok") != "ok":
            print(f"mobisense: {result.summary['status']}", file=sys.stderr)
            return 1
        return status


def _save(result: object, args: argparse.Namespace, source: Path) -> int:
    from ..core.output import default_output_folder

    out = args.out if args.out is not None else default_output_folder(source)
    result.save(out, figures=not args.no_plot)  # type: ignore[attr-defined]
    result.report(out)  # type: ignore[attr-defined]
    return 0


def check_scenario(data: dict, path: Path, kind: str) -> str:
    """Validate a scenario file of ``kind`` (and the files it names); one line saying what it is."""
    from ..core.config import parse_config
    from .scenarios import scenario_model

    config = parse_config(data, scenario_model(kind), source=str(path))
    if kind == "plan_replay":
        from .replay.plan import resolve
        from .replay.reference import reference_status

        status = reference_status(resolve(path, config.solution), resolve(path, config.problem))
        runs = config.monte_carlo.runs
        return f"plan replay {config.name!r}: {status}; Monte Carlo with {runs} runs"
    if kind == "field_replay":
        return (
            f"field replay {config.name!r}: {config.platforms.count} platforms, {config.formation.kind} formation, "
            f"{config.motion.kind.replace('_', ' ')} motion on the field {config.field.kind!r} for "
            f"{config.duration:g} {config.units.time}"
        )
    if kind == "replan":
        from ..ocp.problem import load_problem

        load_problem(path.parent / config.problem)  # the problem it flies must be valid too
        return (
            f"re-planning of {config.problem!r} every {config.replan.every:g} ({config.replan.horizon} horizon), "
            f"{config.monte_carlo.runs} Monte Carlo runs"
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
