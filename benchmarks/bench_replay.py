"""Closed-loop replay throughput: simulated seconds per wall second of the four-platform isotherm replay.

    .venv/bin/python benchmarks/bench_replay.py [--hours 12]

Runs ``problems/replay_isotherm13.yaml`` (cross of four platforms, cooperative filter + curvature Hessian
in the loop, adaptive shape, ``solve_ivp`` between the 3-minute samples) for the given simulated duration,
and prints, measured in this one run:

* simulated time per wall time (the scenario is in hours: ×3600 for seconds). Target: ≥ 1e4, i.e. a
  two-day mission replays in under 20 s;
* the share of the wall time spent in the ODE integration (controllers), in the filter steps and in the
  shape adaptation (step 3A);
* the same replay with the true field fed to the controllers (filter still running for the outputs):
  the ratio of the two rates shows what the estimate-driven loop costs.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import yaml

import mobisense.estimation.cooperative.formation_design as formation_design  # patched to time its calls
from mobisense.core import parse_config
from mobisense.formation.replay import ClosedLoopEstimator, FieldReplayScenario, build_system, simulate

SCENARIO = Path(__file__).resolve().parent.parent / "problems" / "replay_isotherm13.yaml"


class Stopwatch:
    """Accumulate the wall time spent in wrapped callables."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    def wrap(self, name, fn):  # noqa: ANN001, ANN201
        def timed(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - t0

        return timed


def run(hours: float, derivatives: str) -> float:
    data = yaml.safe_load(SCENARIO.read_text())
    data["duration"] = hours
    data["motion"]["derivatives"] = derivatives
    system = build_system(parse_config(data, FieldReplayScenario, str(SCENARIO)), SCENARIO)
    t0 = time.perf_counter()
    simulate(system)
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=12.0, help="simulated duration (h)")
    args = parser.parse_args()
    watch = Stopwatch()
    import scipy.integrate  # the replay imports solve_ivp at call time, so the wrapper below is seen

    original = {
        "ode": scipy.integrate.solve_ivp,
        "filter": ClosedLoopEstimator.step,
        "adapt": formation_design.adaptive_shape_step,
    }
    scipy.integrate.solve_ivp = watch.wrap("ode", original["ode"])
    ClosedLoopEstimator.step = watch.wrap("filter", original["filter"])
    formation_design.adaptive_shape_step = watch.wrap("adapt", original["adapt"])
    try:
        wall = run(args.hours, "estimated")
    finally:
        scipy.integrate.solve_ivp = original["ode"]
        ClosedLoopEstimator.step = original["filter"]
        formation_design.adaptive_shape_step = original["adapt"]
    wall_true = run(args.hours, "true_field")
    rate, rate_true = args.hours * 3600 / wall, args.hours * 3600 / wall_true
    print(
        f"four-platform isotherm replay, {args.hours:g} h simulated ({int(args.hours / 0.05)} filter steps)"
    )
    print(
        f"  filter in the loop: {wall:.2f} s wall -> {rate:,.0f} simulated s per wall s "
        f"({'meets' if rate >= 1e4 else 'MISSES'} the 1e4 target)"
    )
    for name in ("ode", "filter", "adapt"):
        print(f"    {name:>6}: {100 * watch.seconds.get(name, 0.0) / wall:5.1f}% of the wall time")
    print(
        f"  true field to the controllers: {wall_true:.2f} s wall -> {rate_true:,.0f} simulated s per wall s "
        f"(estimate-driven / true-field rate = {rate / rate_true:.2f})"
    )


if __name__ == "__main__":
    main()
