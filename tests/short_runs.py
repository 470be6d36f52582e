"""Short runs of every command's code path (small grids, short horizons) for the file and figure tests.

Each function returns the object the command would save (a Solution, a SimulationResult, a DesignStudy),
built from a shipped example with its horizon or grid cut down; the datasets have the same variables,
dimensions and attributes as the full runs.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml
from reference_problems import PROBLEMS, hussein2008


def small_solution(method: str = "direct", **changes: Any) -> Any:
    """The default problem on 20 intervals, 4 homotopy steps, solved by ``method``."""
    import mobisense as ms

    data = hussein2008(collocation={"intervals": 20}, homotopy={"step": 0.25}, method=method)
    data.update(changes)
    return ms.solve(ms.Problem.from_dict(data))


def field_problem(grid: tuple[int, int] = (2, 2), sensors: int = 1, **solver: Any) -> dict[str, Any]:
    """A small field problem (extent [0, 4]², Matérn-3/2, ℓ = 3, τ = 10, tf = 5) with point sensors on a line."""
    return {
        "name": "small_field",
        "horizon": {"t0": 0.0, "tf": 5.0},
        "process": {"field": {"grid": list(grid), "extent": [[0, 4], [0, 4]], "time_constant": 10.0,
                              "kernel": {"type": "matern32", "length_scale": 3.0, "variance": 1.0}}},
        "sensors": [{"name": f"g{i + 1}", "p0": [0.5 + i, 0.5], "v0": [0.0, 0.0], "measures": "point",
                     "noise": {"model": "constant", "variance_value": 0.1}} for i in range(sensors)],
        "cost": {"M": "mean", "K": "zero", "alpha": 0.05},
        "solver": {"tolerance": 1e-10, **solver},
    }  # fmt: skip


def field_solution(**solver: Any) -> Any:
    """The small field problem solved by the shooting method on 20 intervals."""
    import mobisense as ms

    shooting = {"intervals": 20, "coarse_intervals": 10, **solver.pop("shooting", {})}
    return ms.solve(ms.Problem.from_dict(field_problem(shooting=shooting, **solver)))


def _shortened(name: str, folder: Path, **changes: Any) -> Path:
    data = yaml.safe_load((PROBLEMS / f"{name}.yaml").read_text(encoding="utf-8"))
    data.update(changes)
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data, allow_unicode=True), encoding="utf-8")
    return path


def plan_replay(folder: Path, solution: Any) -> Any:
    """A plan replay of ``solution`` (50 Monte Carlo runs at Δt = 0.1)."""
    from mobisense.formation.scenarios import load_scenario

    solution.save(folder / "solution")
    (folder / "problem.yaml").write_text(yaml.safe_dump(solution.problem.normalised()), encoding="utf-8")
    scenario = folder / "plan.yaml"
    scenario.write_text(yaml.safe_dump({"name": "plan", "solution": "solution/solution.nc", "problem": "problem.yaml",
                                        "monte_carlo": {"runs": 50, "time_step": 0.1}}))  # fmt: skip
    return load_scenario(scenario).run()


def field_replay(folder: Path, name: str = "replay_two_charges", duration: float = 2.0) -> Any:
    """A shipped field replay cut to ``duration``."""
    from mobisense.formation.scenarios import load_scenario

    return load_scenario(_shortened(name, folder, duration=duration)).run()


def leader_follower(folder: Path, name: str = "leader_follower_khepera", duration: float = 0.5) -> Any:
    """A shipped leader–follower scenario cut to ``duration`` seconds."""
    from mobisense.formation.scenarios import load_scenario

    return load_scenario(_shortened(name, folder, duration=duration), "leader_follower").run()


def distributed(folder: Path, duration: float = 4.0) -> Any:
    """The shipped distributed-filter scenario cut to ``duration`` seconds."""
    from mobisense.formation.scenarios import load_scenario

    path = _shortened("distributed_advection_diffusion", folder, time={"step": 1.0, "duration": duration})
    return load_scenario(path, "distributed").run()


def steady_state(folder: Path) -> Any:
    """The cross-formation design on an 11 × 11 contour grid."""
    from mobisense.estimation.cooperative.design_study import design_formation

    return design_formation(_shortened("formation_cross", folder, contour_resolution=11))
