"""Replay a scenario in closed loop: ``mobisense replay SCENARIO.yaml --out DIR``.

Two kinds of scenario file, told apart by their keys:

* ``field: …`` — formation control + level-curve tracking (or an optimised reference for the centre) +
  cooperative filter on a field (:class:`~formation.replay_scenario.FieldReplayScenario`). Writes
  ``result.nc`` (``z_true, z_est, grad_true, grad_est, r, v, a, b, theta`` …, level ``C`` as attribute),
  ``summary.json`` (final ``|z − C|``, mean ``|θ|`` over the last quarter, RMS estimation errors, shape
  and reference-tracking errors) and ``paths.png``, ``z_estimate.png``, ``shape.png``, ``heading.png``;
  ``--animate`` adds ``replay.mp4`` or ``replay.gif`` (skipped when no encoder exists).
* ``solution: …`` — an optimised plan flown by Newtonian platforms, then Monte Carlo validation of the
  Kalman filter along the flown paths against the optimiser's Σ(t)
  (:class:`~formation.ocp_replay.OcpReplayScenario`). Writes ``result.nc``, ``summary.json``,
  ``paths.png``, ``covariance.png``, ``nees.png`` (and ``solution.nc`` if it had to be solved first).

The file (and every file it references) is validated before anything is written: exit 2 with one line
``FILE: key.path: …``. Exit 1 if the closed loop becomes singular or a solver fails.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``replay`` arguments."""
    parser.add_argument("scenario", type=Path, help="scenario YAML file (see problems/replay_*.yaml)")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default out/<scenario name>)")
    parser.add_argument("--seed", type=int, default=None, help="override the scenario's random seed")
    parser.add_argument("--no-plot", action="store_true", help="skip the figures")
    parser.add_argument(
        "--animate", action="store_true", help="also write replay.mp4 (or .gif) of a field replay"
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """Validate, replay, write the outputs; return the exit status."""
    from ocp.config import ConfigError, read_yaml

    data = read_yaml(args.scenario)
    if isinstance(data, dict) and "field" in data:
        return _run_field(args, data)
    if isinstance(data, dict) and "solution" in data:
        return _run_ocp(args, data)
    raise ConfigError(
        f"{args.scenario}: (top level): expected a field replay (key 'field') or a replay of an optimised "
        "solution (key 'solution')"
    )


def _out(args: argparse.Namespace, name: str) -> Path:
    return args.out if args.out is not None else Path("out") / name


def _run_field(args: argparse.Namespace, data: Any) -> int:
    from formation.replay_scenario import FieldReplayScenario
    from formation.replay_simulation import ReplayError, build_system, simulate
    from ocp.config import parse_config

    scenario = parse_config(data, FieldReplayScenario, source=str(args.scenario))
    system = build_system(scenario, args.scenario)  # reads referenced files: ConfigError before any output
    seed = scenario.seed if args.seed is None else args.seed
    try:
        record = simulate(system, seed, progress=not args.quiet and sys.stderr.isatty())
    except ReplayError as err:
        print(f"mobisense: error: {args.scenario}: {err}", file=sys.stderr)
        return 1
    from formation.replay_results import replay_dataset, replay_summary
    from ocp.files import write_json, write_netcdf

    ds = replay_dataset(record, system, seed)
    summary = {"file": str(args.scenario), "seed": seed, **replay_summary(ds, record, system)}
    out = _out(args, scenario.name)
    out.mkdir(parents=True, exist_ok=True)
    write_netcdf(out / "result.nc", ds)
    files = ["result.nc", "summary.json"]
    if not args.no_plot:
        from formation.replay_plots import save_animation, save_figures

        files += [p.name for p in save_figures(ds, system.field, scenario, out)]
        if args.animate:
            movie = save_animation(ds, system.field, scenario, out)
            files += [] if movie is None else [movie.name]
    summary["files"] = files
    write_json(out / "summary.json", summary)
    _report_field(summary, out)
    return 0


def _report_field(s: dict[str, Any], out: Path) -> None:
    u = s["units"]
    rate = s["simulated_time_per_wall_second"]
    print(
        f"{s['scenario']}: {s['platforms']} platforms, {s['duration']:g} {u['time']} in "
        f"{s['wall_time_s']:.2f} s ({rate:.3g} {u['time']} per wall second), {s['derivatives']}"
    )
    if "level" in s:
        print(f"  level {s['level']:g} {u['field']}: final |z − C| = {s['final_level_error']:.3g}, "
              f"RMS over the last half {s['rms_level_error_last_half']:.3g}; "
              f"mean |θ| (last quarter) = {s['mean_abs_theta_last_quarter']:.3g} rad")  # fmt: skip
    print(
        f"  estimates: RMS z error {s['rms_z_error']:.3g} {u['field']}, RMS gradient error "
        f"{s['rms_gradient_error']:.3g} {u['field']}/{u['length']}, "
        f"mean NEES {s['mean_nees']:.3g} (3 if consistent)"
    )
    b = "" if s["b_final"] is None or s["b_final"] != s["b_final"] else f", b = {s['b_final']:.4g}"
    print(f"  shape error (RMS, last half) {s['shape_error_rms_last_half']:.3g} {u['length']}; "
          f"final a = {s['a_final']:.4g}{b} {u['length']}")  # fmt: skip
    if "reference_tracking_rms" in s:
        print(
            f"  reference tracking: RMS {s['reference_tracking_rms']:.3g}, "
            f"max {s['reference_tracking_max']:.3g}"
        )
    print(f"results in {out}/: {', '.join(s['files'])}")


def _run_ocp(args: argparse.Namespace, data: Any) -> int:
    from formation.ocp_replay import OcpReplayScenario, replay_solution, resolve
    from formation.ocp_replay_reference import load_or_solve
    from ocp.config import ConfigError, parse_config

    scenario = parse_config(data, OcpReplayScenario, source=str(args.scenario))
    solution_path = resolve(args.scenario, scenario.solution)
    try:
        solution, note = load_or_solve(solution_path, resolve(args.scenario, scenario.problem))
    except RuntimeError as err:
        print(f"mobisense: error: {args.scenario}: {err}", file=sys.stderr)
        return 1
    N = solution.problem.N
    if scenario.initial_offset is not None and len(scenario.initial_offset) != N:
        raise ConfigError(
            f"{args.scenario}: initial_offset: expected {N} offsets (one per sensor of the solution), "
            f"got {len(scenario.initial_offset)}"
        )
    print(note)
    ds, summary = replay_solution(scenario, solution, args.seed)
    from ocp.files import write_json, write_netcdf

    out = _out(args, scenario.name)
    out.mkdir(parents=True, exist_ok=True)
    write_netcdf(out / "result.nc", ds)
    files = ["result.nc", "summary.json"]
    if not solution_path.is_file():
        write_netcdf(out / "solution.nc", solution.to_dataset())
        files.append("solution.nc")
    if not args.no_plot:
        from formation.ocp_replay_plots import save_ocp_figures

        files += [p.name for p in save_ocp_figures(ds, solution.problem.matrices()["locations"], out)]
    seed = scenario.seed if args.seed is None else args.seed
    summary = {
        "scenario": scenario.name,
        "file": str(args.scenario),
        "solution": note,
        "seed": seed,
        **summary,
    }
    summary["files"] = files
    write_json(out / "summary.json", summary)
    mc = summary["monte_carlo"]
    print(f"{scenario.name}: tracking error max {summary['tracking_error_max']:.3g}, RMS "
          f"{summary['tracking_error_rms']:.3g} (L)")  # fmt: skip
    print(
        f"  Monte Carlo ({mc['runs']} runs, Δt = {mc['time_step']:.3g}): average NEES "
        f"{mc['nees_predicted_mean']:.3f} (n = {solution.problem.n}); inside the "
        f"{100 * mc['confidence']:.0f}% band at "
        f"{100 * mc['fraction_inside_band_predicted']:.1f}% of the steps"
    )
    print(
        f"  terminal cost Tr[M Σ(tf)]: promised {mc['terminal_cost_promised']:.4g}, delivered "
        f"{mc['terminal_cost_delivered']:.4g} (sampled filter {mc['terminal_cost_filter']:.4g})"
    )
    print(f"results in {out}/: {', '.join(files)}")
    return 0
