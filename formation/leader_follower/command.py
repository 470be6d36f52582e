"""Leader–follower unicycle formations (SPEC §3): ``mobisense simulate leader-follower SCENARIO.yaml --out DIR``.

Writes into ``DIR``

* ``result.nc`` — every run of the scenario along ``run``: per agent ``x, y, phi, v, omega``; per follower
  ``d, beta, gamma, d0, beta0, xe, ye, deviation`` (eq. 54) and the estimates used by the control; in ring
  mode the switching filter's ``active`` pairs and ``selected_pair`` over time
  (see :func:`formation.leader_follower_simulation.simulate`);
* ``summary.json`` — per run and follower: final and maximum errors, monotonicity of ``|β − β0|``, mean
  distance, path deviation, estimation error and switching statistics;
* figures ``paths.png``, ``formation_errors.png``, ``reference_point_errors.png``, ``deviation.png`` and, when
  relevant, ``references.png`` and ``active_pairs.png`` (skipped with ``--no-plot``).

The scenario is validated completely before anything is written (exit 2, one line naming the key). Exit 1
if a control meets its singular set or the integrator fails (nothing is written then).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

__all__ = ["run_scenario"]


def run_scenario(scenario: Path, out: Path, args: argparse.Namespace) -> int:
    """Load, simulate and write a leader–follower scenario.

    Parameters
    ----------
    scenario : Path
        The YAML file (:class:`~formation.leader_follower_scenario.LeaderFollowerScenario`).
    out : Path
        Output folder (created).
    args : argparse.Namespace
        ``.seed`` (int or None) overrides the file's seed; ``.no_plot`` skips the figures.

    Returns
    -------
    int
        0 on success, 1 on a singular control or an integrator failure.
    """
    from formation.leader_follower_controls import FormationSingularityError
    from formation.leader_follower_runs import simulate_scenario, summarize
    from formation.leader_follower_scenario import LeaderFollowerScenario
    from ocp.config import load_config
    from ocp.files import write_json, write_netcdf

    config = load_config(scenario, LeaderFollowerScenario)  # raises ConfigError before any output
    seed = getattr(args, "seed", None)
    started = time.perf_counter()
    try:
        result = simulate_scenario(config, seed=seed)
    except (FormationSingularityError, RuntimeError) as err:
        print(f"mobisense: error: {scenario}: {err}", file=sys.stderr)
        return 1
    wall_time = time.perf_counter() - started
    summary = {
        "scenario": config.name,
        "file": str(scenario),
        "seed": config.seed if seed is None else seed,
        "duration_s": config.duration,
        "step_s": config.step,
        "gain_per_s": config.gain,
        "followers": len(config.followers),
        "wall_time_s": wall_time,
        "runs": summarize(result),
    }
    out.mkdir(parents=True, exist_ok=True)
    write_netcdf(out / "result.nc", result)
    figures = []
    if not getattr(args, "no_plot", False):
        from formation.leader_follower_plots import save_figures

        figures = [p.name for p in save_figures(result, out)]
    summary["files"] = ["result.nc", "summary.json", *figures]
    write_json(out / "summary.json", summary)
    _report(summary, out)
    return 0


def _report(summary: dict, out: Path) -> None:
    """Print one line per run and follower, and where the files went."""
    print(f"{summary['scenario']}: {summary['followers']} follower(s), {summary['wall_time_s']:.2f} s wall time")
    for run, entry in summary["runs"].items():
        for follower, m in entry["followers"].items():
            line = (
                f"  {run:>12} R{follower}: |xe|,|ye|(T) = {m['final_abs_xe']:.2e}, {m['final_abs_ye']:.2e} m; "
                f"max|β−β0| = {m['max_abs_bearing_error']:.3f} rad (monotone: {m['bearing_error_monotone']}); "
                f"mean dev = {m['mean_deviation']:.3g} m"
            )
            if "rms_position_error" in m and m["rms_position_error"] is not None:
                line += f"; RMS estimate error = {m['rms_position_error']:.3g} m"
            print(line)
    print(f"results in {out}/: {', '.join(summary['files'])}")
