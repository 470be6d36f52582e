"""``kind: replan`` scenario files: plan, fly, re-plan under a current (docs/theory/path_constraints.md §5).

Example (``problems/replan_drift.yaml``)::

    kind: replan
    problem: hussein2008.yaml                    # relative to this file
    replan: {every: 0.5, horizon: shrinking}
    disturbance: {drift: [0.3, -0.2], force_noise_std: 0.05, seed: 1}
    monte_carlo: {runs: 20, time_step: 0.01}

``mobisense replay FILE`` flies the closed loop (re-planned), the open loop (first plan) and no control
with the same noise draws (:func:`mobisense.ocp.replan.replan_monte_carlo`) and writes ``summary.json``
(``closed_loop``, ``open_loop``, ``no_control``: ``{cost_mean, cost_std, cost_stderr}``,
``replan_solve_time_s``, ``replan_every_s``), ``result.nc`` (the flown paths and Σ of every closed-loop
run, the plans made along run 0) and ``replan.png`` (the plans fanning out along the flown path).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field

from ...core.config import FiniteFloat, NonNegativeFloat, PositiveFloat, StrictModel
from ..simulation_result import SimulationResult

__all__ = ["ReplanOptions", "DisturbanceOptions", "MonteCarloOptions", "ReplanScenario", "run_replan"]


class ReplanOptions(StrictModel):
    """When and over what horizon to re-plan."""

    every: PositiveFloat = Field(description="re-plan period (T)")
    horizon: Literal["shrinking"] = Field("shrinking", description="re-solve over [t, tf] (receding: not yet)")


class DisturbanceOptions(StrictModel):
    """The current the plan does not know and the force noise."""

    drift: list[FiniteFloat] = Field([0.0, 0.0], min_length=2, max_length=2, description="current (L/T)")
    force_noise_std: NonNegativeFloat = 0.0
    seed: int = 1


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


class ReplanResult(SimulationResult):
    """Closed loop vs open loop vs no control, with the plans of run 0."""

    kind = "replan"

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
        n_plans = ds.sizes["plan"]
        for j in range(n_plans):
            for i in range(ds.sizes["sensor"]):
                ax.plot(*ds["plan_p"].values[j, :, i].T, color=cmap(j / max(n_plans - 1, 1)), lw=0.9, alpha=0.8)
        ax.plot([], [], color=cmap(0.0), lw=0.9, label="plans (first → last: dark → light)")
        for i in range(ds.sizes["sensor"]):
            ax.plot(*ds["p"].values[0, :, i].T, "k", lw=2.0, label="flown (run 0)" if i == 0 else None)
        locs = np.asarray(ds.attrs["process_locations"]).reshape(-1, 2)
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


def run_replan(config: ReplanScenario, source: Path, seed: int | None = None) -> ReplanResult:
    """Run a ``kind: replan`` scenario (see module docstring)."""
    import xarray as xr

    from ...ocp.problem import load_problem
    from ...ocp.replan import Disturbance, replan_monte_carlo

    problem = load_problem(Path(source).parent / config.problem)
    d = config.disturbance
    r = replan_monte_carlo(
        problem,
        Disturbance(tuple(d.drift), d.force_noise_std),  # type: ignore[arg-type]
        runs=config.monte_carlo.runs,
        every=config.replan.every,
        time_step=config.monte_carlo.time_step,
        seed=d.seed if seed is None else seed,
    )
    flights = r.pop("flights")
    plans = flights[0].plans
    names = [s.name for s in problem.sensors]
    data: dict[str, Any] = {
        "p": (("run", "time", "sensor", "xy"), np.stack([f.p for f in flights]), {"units": "L"}),
        "Sigma": (("run", "time", "row", "col"), np.stack([f.Sigma for f in flights])),
        "cost": (("run",), np.array([f.cost for f in flights])),
        "plan_time": (("plan",), np.array([t for t, _ in plans]), {"long_name": "instant the plan was made"}),
        "plan_p": (("plan", "plan_node", "sensor", "xy"), np.stack([p for _, p in plans]), {"units": "L"}),
    }
    coords = {"time": flights[0].t, "sensor": names, "xy": ["x", "y"]}
    attrs = {"process_locations": np.asarray(problem.process.locations, float).ravel()}
    summary = {"kind": "replan", "problem": problem.name, **r}
    return ReplanResult(xr.Dataset(data, coords=coords, attrs=attrs), summary)
