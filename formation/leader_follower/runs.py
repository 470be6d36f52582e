"""From a validated scenario to simulated runs and their summary metrics (``mobisense simulate leader-follower``).

:func:`build_problem` turns one run of a :class:`~mobisense.formation.leader_follower.scenario.LeaderFollowerScenario`
into a :class:`~mobisense.formation.leader_follower.simulation.LeaderFollowerProblem`; :func:`simulate_scenario` runs
them all in order (a run may take its constant ``d0`` from an earlier run's mean distance) and stacks the
results along a ``run`` dimension; :func:`summarize` computes the metrics written to ``summary.json``;
:func:`run_leader_follower` does all of it and returns a :class:`LeaderFollowerResult`.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from ...estimation.tracking.range_ring import RangeSensorRing
from ..simulation_result import SimulationResult
from .controls import WARN_COS, make_control, warn_near_singular
from .references import (
    BearingRampReference,
    ConstantReference,
    PathReference,
    ReferenceSchedule,
    SteppedReference,
)
from .scenario import (
    ConstantReferenceConfig,
    LeaderFollowerScenario,
    RampReferenceConfig,
    ReferenceConfig,
    RingSensingConfig,
    SensingConfig,
    SteppedReferenceConfig,
)
from .sensing import RingSpec
from .simulation import (
    IntegrationSettings,
    LeaderFollowerProblem,
    LeaderMotion,
    simulate,
)

__all__ = [
    "build_reference",
    "build_ring",
    "build_problem",
    "simulate_scenario",
    "summarize",
    "LeaderFollowerResult",
    "run_leader_follower",
]


def build_reference(config: ReferenceConfig, measured_distance: dict[str, float], duration: float) -> ReferenceSchedule:
    """Reference schedule of a run; warns (:class:`SingularityWarning`) if ``|β0|`` comes close to π/2."""
    if isinstance(config, ConstantReferenceConfig):
        distance = config.distance if config.distance is not None else measured_distance[config.distance_from_run]
        warn_near_singular(math.cos(config.bearing), "cos beta0")
        return ConstantReference(distance, config.bearing)
    if isinstance(config, RampReferenceConfig):
        schedule = BearingRampReference(
            config.distance,
            config.bearing,
            config.bearing_rate,
            config.distance_rate_amplitude,
            config.distance_rate_frequency,
        )
        beta_end = schedule.at(duration).bearing
        warn_near_singular(min(math.cos(config.bearing), math.cos(beta_end)), "min cos beta0(t)")
        return schedule
    if isinstance(config, SteppedReferenceConfig):
        warn_near_singular(min(math.cos(b) for b in config.bearing), "min cos beta0")
        return SteppedReference(config.switch_times, config.distances(), config.bearing)
    if math.cos(config.max_bearing) < WARN_COS:
        warn_near_singular(math.cos(config.max_bearing), "cos max_bearing")
    return PathReference(config.max_area, config.max_distance, config.max_bearing)


def build_ring(config: RingSensingConfig) -> RingSpec:
    """Sensor ring and switching-filter settings from the ``sensing: {mode: ring}`` block."""
    angles = np.deg2rad(config.mount_angles_deg)
    headings = np.deg2rad(config.headings_deg) if config.headings_deg is not None else angles
    ring = RangeSensorRing(
        mount_radius=config.mount_radius,
        mount_angles=angles,
        headings=headings,
        field_of_view=math.radians(config.field_of_view_deg),
        max_range=config.max_range,
        noise_std=config.noise_std,
        target_radius=config.target_radius,
        pairs=np.asarray(config.pairs, dtype=int) - 1,
    )
    return RingSpec(ring, config.acceleration_std, config.merge, config.initial_velocity_std)


def build_problem(
    scenario: LeaderFollowerScenario,
    control: str,
    reference: ReferenceConfig,
    sensing: SensingConfig,
    measured_distance: dict[str, float] | None = None,
    seed: int | None = None,
) -> LeaderFollowerProblem:
    """The simulation problem of one run (``control``, ``reference``, ``sensing`` as resolved for that run)."""
    leader = scenario.leader
    return LeaderFollowerProblem(
        leader=LeaderMotion(
            np.asarray(leader.pose, dtype=float),
            leader.speed,
            leader.turn_rate,
            leader.turn_rate_amplitude,
            leader.turn_rate_period,
        ),
        follower_poses=np.asarray([f.pose for f in scenario.followers], dtype=float),
        control=make_control(control),
        reference=build_reference(reference, measured_distance or {}, scenario.duration),
        gain=scenario.gain,
        duration=scenario.duration,
        step=scenario.step,
        ring=build_ring(sensing) if isinstance(sensing, RingSensingConfig) else None,
        integration=IntegrationSettings(**scenario.integration.model_dump()),
        seed=scenario.seed if seed is None else seed,
    )


def simulate_scenario(scenario: LeaderFollowerScenario, seed: int | None = None) -> xr.Dataset:
    """Simulate every run of ``scenario`` in order; results stacked along ``run``.

    Every run uses the same noise seed (common random numbers), so runs differ only by their settings.
    The returned dataset also carries per-run labels ``control``, ``reference_kind`` and ``sensing_mode``.
    """
    results = []
    measured_distance: dict[str, float] = {}
    for name, control, reference, sensing in scenario.resolved_runs():
        problem = build_problem(scenario, control, reference, sensing, measured_distance, seed)
        result = simulate(problem)
        measured_distance[name] = float(result["d"].mean())
        results.append(result)
    n_pairs = max(r.sizes["pair"] for r in results)
    results = [r.reindex(pair=np.arange(1, n_pairs + 1), fill_value={"active": 0}) for r in results]
    runs = scenario.resolved_runs()
    out = xr.concat(results, dim="run", data_vars="all", coords="minimal", compat="override", join="outer")
    out = out.assign_coords(run=("run", [name for name, *_ in runs], {"long_name": "run name"}))
    out["control"] = ("run", [control for _, control, _, _ in runs], {"long_name": "control law of the run"})
    out["reference_kind"] = ("run", [reference.kind for _, _, reference, _ in runs],
                             {"long_name": "kind of formation parameters (constant, ramp or path)"})  # fmt: skip
    out["sensing_mode"] = ("run", [sensing.mode for _, _, _, sensing in runs],
                           {"long_name": "sensing: exact relative states or the range-sensor ring"})  # fmt: skip
    out.attrs.update(
        title=f"mobisense: leader-follower simulation '{scenario.name}'",
        scenario=scenario.name, gain=scenario.gain, seed=scenario.seed if seed is None else seed,
    )  # fmt: skip
    return out


def _monotone_nonincreasing(values: np.ndarray, tolerance: float) -> bool:
    return bool(np.all(np.diff(values) <= tolerance))


def summarize(result: xr.Dataset) -> dict[str, Any]:
    """Per-run, per-follower metrics for ``summary.json``.

    Metrics: final ``|x_e|, |y_e|`` and ``|d − d0|, |β − β0|`` (m, rad); their maxima; whether ``|β − β0|`` is
    non-increasing (to 1e-9 rad); mean and minimum distance (m); mean and maximum path deviation (eq. 54,
    m) over the whole run and over its second half (after the start-up transient); in ring mode, RMS and
    maximum position-estimation error (m), fraction of samples with at least one active pair and number of
    switches of the selected sub-filter (None for a combining merge).
    """
    summary: dict[str, Any] = {}
    for run in result["run"].values:
        r = result.sel(run=run)
        half = r.sizes["time"] // 2
        per_follower = {}
        for f in r["follower"].values:
            s = r.sel(follower=f)
            beta_err = np.abs(np.remainder(s["beta"].values - s["beta0"].values + np.pi, 2 * np.pi) - np.pi)
            d_err = np.abs(s["d"].values - s["d0"].values)
            entry = {
                "final_abs_xe": float(abs(s["xe"].values[-1])),
                "final_abs_ye": float(abs(s["ye"].values[-1])),
                "max_reference_point_error": float(np.hypot(s["xe"], s["ye"]).max()),
                "final_abs_distance_error": float(d_err[-1]),
                "final_abs_bearing_error": float(beta_err[-1]),
                "max_abs_bearing_error": float(beta_err.max()),
                "bearing_error_monotone": _monotone_nonincreasing(beta_err, 1e-9),
                "mean_distance": float(s["d"].mean()),
                "min_distance": float(s["d"].min()),
                "mean_deviation": float(s["deviation"].mean()),
                "max_deviation": float(s["deviation"].max()),
                "mean_deviation_second_half": float(s["deviation"][half:].mean()),
                "max_deviation_second_half": float(s["deviation"][half:].max()),
            }
            if str(r["sensing_mode"].values) == "ring":
                err = s["position_error"].values
                err = err[np.isfinite(err)]
                selected = s["selected_pair"].values
                entry.update(
                    rms_position_error=float(np.sqrt(np.mean(err**2))) if err.size else None,
                    max_position_error=float(err.max()) if err.size else None,
                    fraction_with_active_pair=float(np.mean(s["active"].values.any(axis=-1))),
                    # None when the merge combines sub-filters (information) instead of picking one
                    selected_pair_switches=(
                        int(np.count_nonzero(np.diff(selected[selected > 0]))) if np.any(selected > 0) else None
                    ),
                )
            per_follower[str(int(f))] = entry
        summary[str(run)] = {
            "control": str(r["control"].values),
            "reference": str(r["reference_kind"].values),
            "sensing": str(r["sensing_mode"].values),
            "followers": per_follower,
        }
    return summary


class LeaderFollowerResult(SimulationResult):
    """Every run of a leader–follower scenario (dataset along ``run``), its metrics and figures."""

    kind = "leader_follower"

    def plot(self, folder: str | Path) -> list[Path]:
        """``paths.png``, ``formation_errors.png``, ``reference_point_errors.png``, ``deviation.png`` (+ more)."""
        from .plots import save_figures

        return save_figures(self.dataset, Path(folder))

    def report(self, folder: Path) -> None:
        """One line per run and follower, and where the files went."""
        s = self.summary
        print(f"{s['scenario']}: {s['followers']} follower(s), {s['wall_time_s']:.2f} s wall time")
        for run, entry in s["runs"].items():
            for follower, m in entry["followers"].items():
                monotone = "monotone" if m["bearing_error_monotone"] else "not monotone"
                line = (
                    f"  {run:>12}, follower {follower}: final reference-point error |x_e|, |y_e| = "
                    f"{m['final_abs_xe']:.2e}, {m['final_abs_ye']:.2e} m; largest bearing error |β − β0| "
                    f"{m['max_abs_bearing_error']:.3f} rad ({monotone}); mean distance from the predecessor's path "
                    f"{m['mean_deviation']:.3g} m"
                )
                if "rms_position_error" in m and m["rms_position_error"] is not None:
                    line += f"; RMS error of the predecessor's estimated position {m['rms_position_error']:.3g} m"
                print(line)
        super().report(folder)


def run_leader_follower(
    scenario: LeaderFollowerScenario, seed: int | None = None, source: str | Path | None = None
) -> LeaderFollowerResult:
    """Simulate every run of ``scenario`` and compute its metrics.

    Parameters
    ----------
    scenario : LeaderFollowerScenario
    seed : int, optional
        Overrides ``scenario.seed``.
    source : str or Path, optional
        The scenario file (recorded in the summary).

    Raises
    ------
    FormationSingularityError
        A control met its singular set.
    RuntimeError
        The integrator failed.
    """
    started = time.perf_counter()
    result = simulate_scenario(scenario, seed=seed)
    summary = {
        "scenario": scenario.name,
        "file": None if source is None else str(source),
        "seed": scenario.seed if seed is None else seed,
        "duration_s": scenario.duration,
        "step_s": scenario.step,
        "gain_per_s": scenario.gain,
        "followers": len(scenario.followers),
        "wall_time_s": time.perf_counter() - started,
        "runs": summarize(result),
    }
    return LeaderFollowerResult(result, summary)
