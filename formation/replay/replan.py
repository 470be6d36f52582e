"""``kind: replan`` scenario files: plan, fly, re-plan under a current (docs/theory/path_constraints.md §5).

Example (``problems/replan_drift.yaml``)::

    kind: replan
    problem: hussein2008.yaml                    # relative to this file
    replan: {every: 0.5, horizon: shrinking}     # or {every: 0.5, horizon: receding, length: 4.0}
    disturbance: {drift: [0.3, -0.2], force_noise_std: 0.05, seed: 1}
    monte_carlo: {runs: 20, time_step: 0.01}

``replan.warm_start`` (``shifted``, the default; ``reused``; ``cold``) says how each re-solve starts
(:mod:`mobisense.ocp.replan_window`). ``length`` must satisfy ``every ≤ length ≤ tf − t0``.

``mobisense replay FILE`` flies the closed loop (re-planned), the open loop (first plan) and no control
with the same noise draws (:func:`mobisense.ocp.replan.replan_monte_carlo`) and writes ``summary.json``
(``closed_loop``, ``open_loop``, ``no_control``: ``{cost_mean, cost_std, cost_stderr}``,
``replan_solve_time_s``, ``replan_iterations``, ``replan_every_s``, ``horizon``, ``replan_failures``,
``replan_flown_unconverged``, ``replan_relaxed``, ``replan_relaxation_max`` and, with path constraints,
``flown_violation``), ``result.nc`` (the flown
paths and Σ of every closed-loop run and the plans made along every run, ``run × plan × plan_node``) and
``replan.png`` (the plans of run 0 fanning out along its flown path).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator

from ...core.config import FiniteFloat, InvalidValue, NonNegativeFloat, PositiveFloat, Seed, StrictModel
from ..simulation_result import SimulationResult

__all__ = [
    "ReplanOptions",
    "DisturbanceOptions",
    "MonteCarloOptions",
    "ReplanScenario",
    "run_replan",
    "check_against_problem",
]


class ReplanOptions(StrictModel):
    """When and over what horizon to re-plan."""

    every: PositiveFloat = Field(description="re-plan period (T)")
    horizon: Literal["shrinking", "receding"] = Field(
        "shrinking", description="re-solve over [t, tf] (shrinking) or [t, min(t + length, tf)] (receding)"
    )
    length: PositiveFloat | None = Field(None, description="receding-horizon window length L (T), every ≤ L ≤ tf − t0")
    warm_start: Literal["shifted", "reused", "cold"] = Field(
        "shifted", description="start of each re-solve: the previous plan shifted onto the new grid, reused, or cold"
    )

    @model_validator(mode="after")
    def _window(self) -> ReplanOptions:
        if self.horizon == "receding" and self.length is None:
            raise InvalidValue("length", "a receding horizon needs its window length (T), e.g. length: 5.0")
        if self.horizon == "shrinking" and self.length is not None:
            raise InvalidValue("length", "only a receding horizon has a window length (set horizon: receding)")
        if self.length is not None and self.every > self.length:
            raise InvalidValue("every", f"expected every ≤ length = {self.length:g}, got {self.every:g}")
        return self


class DisturbanceOptions(StrictModel):
    """The current the plan does not know and the force noise."""

    drift: list[FiniteFloat] = Field([0.0, 0.0], min_length=2, max_length=2, description="current (L/T)")
    force_noise_std: NonNegativeFloat = 0.0
    seed: Seed = 1


class MonteCarloOptions(StrictModel):
    """Runs and the platforms' integration step."""

    runs: int = Field(20, ge=1, le=100_000)
    time_step: PositiveFloat = 0.01


class ReplanScenario(StrictModel):
    """A ``kind: replan`` file."""

    kind: Literal["replan"] = "replan"
    problem: str = Field(description="problem YAML file (relative to this file)")
    replan: ReplanOptions
    disturbance: DisturbanceOptions = DisturbanceOptions()
    monte_carlo: MonteCarloOptions = MonteCarloOptions()

    @model_validator(mode="after")
    def _step(self) -> ReplanScenario:
        if self.replan.every < self.monte_carlo.time_step:
            step = self.monte_carlo.time_step
            message = f"expected at least monte_carlo.time_step = {step:g} (one re-plan per step at most)"
            raise InvalidValue("replan.every", f"{message}, got {self.replan.every:g}")
        return self


class ReplanResult(SimulationResult):
    """Closed loop vs open loop vs no control, with the plans of run 0."""

    kind = "replan"

    def report(self, folder: Path) -> None:
        """The three policies' realised costs (mean ± standard error over the runs), the re-solves, the files."""
        s = self.summary

        def cost(policy: str) -> str:
            c = s[policy]
            return f"{c['cost_mean']:.6g} ± {c['cost_stderr']:.2g}"

        runs = self.dataset.sizes.get("run", 0)
        print(
            f"{s['problem']}: re-planned every {s['replan_every_s']:g} ({s['horizon']['kind']} horizon, "
            f"{s['warm_start']} warm start) on {runs} runs: realised J closed loop {cost('closed_loop')}, "
            f"open loop {cost('open_loop')}, no control {cost('no_control')} (the plan promised {s['plan_cost']:.6g})"
        )
        print(
            f"  re-solves: median {1e3 * s['replan_solve_time_s']['median']:.1f} ms, max "
            f"{1e3 * s['replan_solve_time_s']['max']:.1f} ms, {s['replan_iterations']['median']:g} iterations "
            f"(median); {s['replan_failures']} failed{_unconverged(s)}{_relaxations(s)}"
        )
        if "flown_violation" in s:
            print(f"  flown paths: {_violations(s['flown_violation'])}")
        super().report(folder)

    def plot(self, folder: str | Path) -> list[Path]:
        """``replan.png``: the plans made at each instant fanning out along the flown path of run 0."""
        from ...core.files import write_figure

        path = Path(folder) / "replan.png"
        write_figure(path, self._figure)
        return [path]

    def _figure(self) -> Any:
        import matplotlib.pyplot as plt

        ds = self.dataset
        fig, ax = plt.subplots(figsize=(6.4, 5.6))
        cmap = plt.get_cmap("viridis")
        n_plans = int(np.sum(np.isfinite(ds["plan_instant"].values[0])))
        for j in range(n_plans):
            for i in range(ds.sizes["sensor"]):
                ax.plot(*ds["plan_p"].values[0, j, :, i].T, color=cmap(j / max(n_plans - 1, 1)), lw=0.9, alpha=0.8)
        ax.plot([], [], color=cmap(0.0), lw=0.9, label="plans (first → last: dark → light)")
        for i in range(ds.sizes["sensor"]):
            ax.plot(*ds["p"].values[0, :, i].T, "k", lw=2.0, label="flown (run 0)" if i == 0 else None)
        locs = np.asarray(ds.attrs["process_locations"]).reshape(-1, 2)
        if ds.attrs.get("process_field", 0):
            ax.plot(*locs.T, ".", color="0.6", ms=4, label="field grid cells")
        else:
            ax.plot(*locs.T, "r*", ms=12, label="process locations")
        ax.set_aspect("equal")
        ax.set_xlabel("x (L)")
        ax.set_ylabel("y (L)")
        s = self.summary
        ax.set_title(
            f"re-plan every {s['replan_every_s']:g}: J closed {s['closed_loop']['cost_mean']:.3f}, "
            f"open {s['open_loop']['cost_mean']:.3f}",
            fontsize=10,
        )
        ax.legend(fontsize=8, loc="best")
        return fig


def check_against_problem(config: ReplanScenario, source: Path) -> Any:
    """The problem the file flies, after checking the window and the step against its horizon; ``ConfigError``.

    The error names the scenario file and the key path (``replan.length``), or the problem file's own error.
    """
    from ...core.errors import ConfigError
    from ...ocp.problem import load_problem
    from ...ocp.replan_inputs import check_horizon

    try:
        problem = load_problem(Path(source).parent / config.problem)
    except ConfigError as err:
        raise ConfigError(f"{source}: problem: {err}") from None
    check_horizon(problem, config.replan.length, config.monte_carlo.time_step, str(source), "replan.length",
                  "monte_carlo.time_step")  # fmt: skip
    return problem


def run_replan(config: ReplanScenario, source: Path, seed: int | None = None) -> ReplanResult:
    """Run a ``kind: replan`` scenario (see module docstring)."""
    from ...ocp.replan import PlanFailed

    problem = check_against_problem(config, source)
    d = config.disturbance
    try:
        r = _monte_carlo(problem, config, d, seed)
    except PlanFailed as failure:  # nothing flown: the plan solved so far is kept, as `mobisense solve` keeps it
        return FailedPlanResult(failure.what, failure.solution)
    flights = r.pop("flights")
    summary = {"kind": "replan", "problem": problem.name, **r}
    return ReplanResult(_dataset(problem, flights), summary)


def _monte_carlo(problem: Any, config: ReplanScenario, d: DisturbanceOptions, seed: int | None) -> dict[str, Any]:
    """:func:`mobisense.ocp.replan.replan_monte_carlo` with the file's settings.

    The command checked the file's budget against its own ``--max-memory`` and ``--max-time`` before any work
    (:func:`mobisense.formation.sizes.scenario_estimates`): the API's check, whose defaults are the command's
    defaults, is passed the widest limits, so that a run the user allowed more is not refused here.
    """
    from ...core.budget import MEMORY_LIMITS, TIME_LIMITS
    from ...ocp.replan import Disturbance, replan_monte_carlo

    return replan_monte_carlo(
        problem,
        Disturbance(tuple(d.drift), d.force_noise_std),  # type: ignore[arg-type]
        runs=config.monte_carlo.runs,
        every=config.replan.every,
        time_step=config.monte_carlo.time_step,
        seed=d.seed if seed is None else seed,
        length=config.replan.length,
        warm_start=config.replan.warm_start,
        max_memory=int(MEMORY_LIMITS[1]),
        max_time=float(TIME_LIMITS[1]),
    )


class FailedPlanResult(SimulationResult):
    """A re-planning file whose starting plan failed: nothing flown, the failed solve kept.

    :meth:`save` writes that solve's ``solution.nc`` and ``summary.json`` (Ipopt's status and what was solved, as
    ``mobisense solve`` writes them); ``summary["status"]`` makes the command exit 1 after saving.
    """

    kind = "replan"

    def __init__(self, what: str, solution: Any) -> None:
        super().__init__(None, {"kind": "replan", "problem": solution.problem.name,
                                "status": f"{what} failed, nothing was flown: {solution.message}"})  # fmt: skip
        self.solution = solution

    def non_finite(self) -> str | None:
        """Nothing was flown: nothing to be finite."""
        return None

    def save(self, folder: str | Path, figures: bool = True) -> list[Path]:
        """The failed solve's ``solution.nc`` and ``summary.json`` (no figures: there is no flight to draw)."""
        folder = Path(folder)
        self.solution.save(folder)
        return [folder / "solution.nc", folder / "summary.json"]

    def report(self, folder: Path) -> None:
        """Where the failed plan was written."""
        print(f"the failed plan (what was solved) in {folder}/: solution.nc, summary.json")


def _unconverged(s: dict[str, Any]) -> str:
    """The failed re-solves whose plans were flown (stopped on a budget, feasible, better than the plan)."""
    flown = s.get("replan_flown_unconverged", 0)
    return f" ({flown} of them flown unconverged: feasible and better than the plan they replaced)" if flown else ""


def _relaxations(summary: dict[str, Any]) -> str:
    """``"; 7 relaxed a constraint the measured state violated (keep_out[0] by up to 0.13)"``, or ``""``."""
    count, largest = summary.get("replan_relaxed", 0), summary.get("replan_relaxation_max", {})
    if not count:
        return ""
    groups = ", ".join(f"{group} by up to {value:.2g}" for group, value in largest.items())
    return f"; {count} relaxed a constraint the measured state violated ({groups})"


def _violations(flown: dict[str, dict[str, float]]) -> str:
    """Each policy's largest constraint violations along its flown paths, or that it held them."""
    parts = []
    for policy, groups in flown.items():
        broken = {g: v for g, v in groups.items() if v > 0}
        text = ", ".join(f"{g} by {v:.2g}" for g, v in broken.items()) if broken else "held every constraint"
        parts.append(f"{policy.replace('_', ' ')} {text}")
    return "; ".join(parts)


def _dataset(problem: Any, flights: list[Any]) -> Any:
    """``result.nc``: every closed-loop run's flown path, Σ, cost and plans, with CF names and units."""
    import xarray as xr

    u = problem.units.system()
    L, T = u.of(length=1), u.of(time=1)

    def attrs(long_name: str, units: str) -> dict[str, str]:
        return {"long_name": long_name, "units": units}

    from ...ocp.field import FULL_SIGMA_STATES  # as a field solution's file

    if problem.n <= FULL_SIGMA_STATES:
        sigma = {"Sigma": (("run", "time", "row", "col"), np.stack([f.Sigma for f in flights]),
                           attrs("filter error covariance along the flown path", u.of(state=2)))}  # fmt: skip
    else:  # a large field: its variance map (as a field solution's sigma_diag)
        sigma = {"sigma_diag": (("run", "time", "state"), np.stack([np.diagonal(f.Sigma, axis1=1, axis2=2)
                                                                    for f in flights]),
                                attrs("filter error variance of each state along the flown path", u.of(state=2)))}
    data: dict[str, Any] = {
        "p": (("run", "time", "sensor", "xy"), np.stack([f.p for f in flights]), attrs("flown sensor position", L)),
        **sigma,
        "cost": (("run",), np.array([f.cost for f in flights]), attrs("realised cost J of the closed loop",
                                                                      u.of(cost=1))),
        **_plan_variables(flights, L, T),
    }  # fmt: skip
    coords = {
        "run": ("run", np.arange(len(flights)), attrs("Monte Carlo run", "1")),
        "time": ("time", flights[0].t, attrs("time of the flight", T)),
        "sensor": ("sensor", [s.name for s in problem.sensors], {"long_name": "sensor name"}),
        "xy": ("xy", ["x", "y"], {"long_name": "planar component"}),
    }
    attributes = {"title": f"re-planning of {problem.name}",
                  "process_locations": problem.matrices()["locations"].ravel(),  # a field's: its grid cells' centres
                  "process_field": int(problem.process.field is not None)}  # fmt: skip
    return xr.Dataset(data, coords=coords, attrs=attributes)


def _plan_variables(flights: list[Any], L: str, T: str) -> dict[str, Any]:
    """Every run's plans (``run × plan × plan_node``), NaN-padded where a run made fewer plans."""
    runs, plans = len(flights), max(len(f.plans) for f in flights)
    _, times, p = flights[0].plans[0]
    instant = np.full((runs, plans), np.nan)
    t = np.full((runs, plans, times.size), np.nan)
    positions = np.full((runs, plans, *p.shape), np.nan)
    for r, flight in enumerate(flights):
        for j, (made, times, p) in enumerate(flight.plans):
            instant[r, j], t[r, j], positions[r, j] = made, times, p
    return {
        "plan_instant": (("run", "plan"), instant, {"long_name": "instant the plan was made", "units": T}),
        "plan_time": (("run", "plan", "plan_node"), t, {"long_name": "time of the planned position", "units": T}),
        "plan_p": (("run", "plan", "plan_node", "sensor", "xy"), positions,
                   {"long_name": "planned sensor position", "units": L}),
    }  # fmt: skip
