"""Running a replay end to end: a validated scenario in, a :class:`SimulationResult` out.

Two kinds of replay: a formation on a field (:func:`run_field_replay`: formation control + level-curve
tracking or an optimised reference for the centre + cooperative filter) and an optimised plan flown by
Newtonian platforms with Monte Carlo validation of the promised covariance (:func:`run_plan_replay`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..simulation_result import SimulationResult

__all__ = ["FieldReplayResult", "PlanReplayResult", "run_field_replay", "run_plan_replay"]


class FieldReplayResult(SimulationResult):
    """A formation replay on a field: dataset, summary, figures and an optional animation."""

    kind = "field_replay"

    def __init__(
        self, dataset: Any, summary: dict[str, Any], system: Any, scenario: Any, animate: bool = False,
        spatial_noise: Any = None,
    ):  # fmt: skip
        super().__init__(dataset, summary)
        self.system = system
        self.scenario = scenario
        self.animate = animate
        #: the spatial-noise sample function ``w(points (M, 2)) -> (M,)`` of this run, or None
        self.spatial_noise = spatial_noise

    def plot(self, folder: str | Path) -> list[Path]:
        """``paths.png``, ``z_estimate.png``, ``shape.png``, ``heading.png`` (+ ``replay.mp4/gif`` if animated)."""
        from .plots import save_animation, save_figures

        folder = Path(folder)
        files = save_figures(self.dataset, self.system.field, self.scenario, folder)
        if self.animate:
            movie = save_animation(self.dataset, self.system.field, self.scenario, folder)
            files += [] if movie is None else [movie]
        return files

    def report(self, folder: Path) -> None:
        """Level error, estimation errors, shape error and where the files went."""
        from ...core.units import UnitSystem

        s = self.summary
        units = UnitSystem(s["units"]["length"], s["units"]["time"], {"field": s["units"]["field"]})

        def unit(**powers: int) -> str:
            text = units.of(**powers)
            return "" if text == "1" else f" {text}"

        rate = s["simulated_time_per_wall_second"]
        print(
            f"{s['scenario']}: {s['platforms']} platforms, {s['duration']:g}{unit(time=1)} simulated in "
            f"{s['wall_time_s']:.2f} s of wall time ({rate:.3g}{unit(time=1)} per second); derivatives from "
            f"{s['derivatives']}"
        )
        if "level" in s:
            print(f"  level z = {s['level']:g}{unit(field=1)}: final |z − level| = {s['final_level_error']:.3g}, "
                  f"RMS over the last half {s['rms_level_error_last_half']:.3g}; "
                  f"mean |θ| over the last quarter {s['mean_abs_theta_last_quarter']:.3g} rad")  # fmt: skip
        print(
            f"  estimates at the centre: RMS error of z {s['rms_z_error']:.3g}{unit(field=1)}, of ∇z "
            f"{s['rms_gradient_error']:.3g}{unit(field=1, length=-1)}; mean NEES {s['mean_nees']:.3g} "
            "(3 = consistent filter of z and ∇z)"
        )
        b = "" if s["b_final"] is None or s["b_final"] != s["b_final"] else f", b = {s['b_final']:.4g}"
        print(f"  shape error (RMS, last half) {s['shape_error_rms_last_half']:.3g}{unit(length=1)}; "
              f"final half distances a = {s['a_final']:.4g}{b}{unit(length=1)}")  # fmt: skip
        if "reference_tracking_rms" in s:
            print(
                f"  distance of the centre from its reference: RMS {s['reference_tracking_rms']:.3g}, "
                f"max {s['reference_tracking_max']:.3g}{unit(length=1)}"
            )
        super().report(folder)


class PlanReplayResult(SimulationResult):
    """An optimised plan flown by platforms: tracking errors and the Monte Carlo check of its covariance."""

    kind = "plan_replay"

    def __init__(self, dataset: Any, summary: dict[str, Any], solution: Any, solved_here: bool) -> None:
        super().__init__(dataset, summary)
        self.solution = solution
        self.solved_here = solved_here

    def plot(self, folder: str | Path) -> list[Path]:
        """``paths.png`` (flown vs planned), ``covariance.png`` and ``nees.png``."""
        from .plan_plots import save_ocp_figures

        return save_ocp_figures(self.dataset, self.solution.problem.matrices()["locations"], Path(folder))

    def extra_files(self, folder: Path) -> list[Path]:
        """``solution.nc`` when the plan was solved for this replay (no solution file existed)."""
        if not self.solved_here:
            return []
        from ...core.files import write_netcdf

        write_netcdf(folder / "solution.nc", self.solution.to_dataset())
        return [folder / "solution.nc"]

    def report(self, folder: Path) -> None:
        """Tracking errors, NEES statistics, promised vs delivered terminal cost."""
        s = self.summary
        mc = s["monte_carlo"]
        print(s["solution"])
        length = self.solution.problem.units.length
        print(f"{s['scenario']}: distance of the platforms from the planned paths: max {s['tracking_error_max']:.3g}, "
              f"RMS {s['tracking_error_rms']:.3g} {length}")  # fmt: skip
        print(
            f"  Monte Carlo ({mc['runs']} runs, Δt = {mc['time_step']:.3g} {self.solution.problem.units.time}): "
            "average normalised estimation error squared (NEES) "
            f"{mc['nees_predicted_mean']:.3f} (n = {self.solution.problem.n}); inside the "
            f"{100 * mc['confidence']:.0f}% band at "
            f"{100 * mc['fraction_inside_band_predicted']:.1f}% of the steps"
        )
        print(
            f"  terminal cost Tr[M Σ(tf)]: promised {mc['terminal_cost_promised']:.4g}, delivered "
            f"{mc['terminal_cost_delivered']:.4g} (sampled filter {mc['terminal_cost_filter']:.4g})"
        )
        super().report(folder)


def run_field_replay(
    scenario: Any, source: Path, seed: int | None = None, progress: bool = False, animate: bool = False
) -> FieldReplayResult:
    """Build the closed loop of a field-replay scenario, simulate it and summarise it.

    Parameters
    ----------
    scenario : FieldReplayScenario
    source : Path
        The scenario file (files it names are relative to its folder).
    seed : int, optional
        Overrides ``scenario.seed``.
    progress : bool
        Show a progress bar.
    animate : bool
        :meth:`FieldReplayResult.plot` also writes an animation.

    Raises
    ------
    ConfigError
        A file the scenario names is missing or invalid (raised before anything runs).
    ReplayError
        The closed loop became singular.
    """
    from .results import replay_dataset, replay_summary
    from .simulation import build_system, simulate

    system = build_system(scenario, source)
    seed = scenario.seed if seed is None else seed
    record = simulate(system, seed, progress=progress)
    ds = replay_dataset(record, system, seed)
    summary = {"file": str(source), "seed": seed, **replay_summary(ds, record, system)}
    return FieldReplayResult(ds, summary, system, scenario, animate, record.spatial_noise)


def run_plan_replay(scenario: Any, source: Path, seed: int | None = None) -> PlanReplayResult:
    """Fly the scenario's optimised plan (solving it first if its solution file is missing) and validate it.

    Parameters
    ----------
    scenario : OcpReplayScenario
    source : Path
        The scenario file (``solution:`` and ``problem:`` are relative to its folder).
    seed : int, optional
        Overrides ``scenario.seed``.

    Raises
    ------
    ConfigError
        The solution cannot be used and there is no problem to solve, the problem is invalid, or
        ``initial_offset`` does not match (:func:`~mobisense.formation.replay.reference.load_checked`).
    RuntimeError
        The plan had to be solved and the solver did not reach ε = 1.
    """
    from ...core.config import ConfigError
    from .plan import replay_solution, resolve
    from .reference import load_checked

    solution_path = resolve(source, scenario.solution)
    solution, note, solved_here = load_checked(solution_path, resolve(source, scenario.problem), scenario.task)
    N = solution.problem.N
    if scenario.initial_offset is not None and len(scenario.initial_offset) != N:
        raise ConfigError(
            f"{source}: initial_offset: expected {N} offsets (one per sensor of the solution), "
            f"got {len(scenario.initial_offset)}"
        )
    ds, summary = replay_solution(scenario, solution, seed, str(source))
    summary = {
        "scenario": scenario.name,
        "file": str(source),
        "solution": note,
        "seed": scenario.seed if seed is None else seed,
        **summary,
    }
    return PlanReplayResult(ds, summary, solution, solved_here=solved_here)
