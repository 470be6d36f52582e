"""Distributed constrained filter performance, measured in one run (ratios matter; absolute times vary).

Prints: the shipped 600 s scenario's simulation time (median of repeats) and its real-time factor; the
split of one replay of its data between the intra-cell update (eqs. 28-32), the inter-cell projection
(eq. 34) and the formation law; and the cost per cell-step on square grids of 9 to 144 cells, which
should stay flat (each cell computes from its own sensors and its neighbours' messages only).

Targets on a 2-core machine: the 600 s scenario in < 1.5 s (real-time factor > 400), cost per cell-step
within ±30 % from 9 to 144 cells.

Usage: ``python benchmarks/bench_distributed.py [--repeats 3]``
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from mobisense.core import load_config
from mobisense.estimation.distributed import DistributedFilter, PdeModel, SensorMesh, grid_network
from mobisense.formation.distributed import DistributedScenario, GradientFormation, simulate

SCENARIO = Path(__file__).resolve().parent.parent / "problems" / "distributed_advection_diffusion.yaml"
console = Console()


def replay_split(scenario: DistributedScenario, ds) -> dict[str, float]:
    """Seconds spent in the intra-cell updates, the projections and the formation law over one replay."""
    mesh = scenario.network.mesh()
    field = scenario.field.build()
    network = DistributedFilter(
        mesh, scenario.filter, scenario.noise_std, PdeModel(field.diffusivity, field.velocity, 1.0)
    )
    formation = GradientFormation(mesh, scenario.formation, np.asarray(scenario.network.positions))
    positions = np.moveaxis(ds["sensor_position"].values, 1, 0)
    measured = ds["measurement"].values.T
    gradients = np.moveaxis(ds["gradient_constrained"].values, 1, 0)
    spent = {"intra-cell update": 0.0, "projection": 0.0, "formation law": 0.0}
    network.start(positions[0], measured[0])
    for k in range(1, len(positions)):
        t0 = time.perf_counter()
        outbox = {
            c.index: c.update(positions[k, list(c.sensors)], measured[k, list(c.sensors)])
            for c in network.cells
        }
        t1 = time.perf_counter()
        for cell in network.cells:
            cell.constrain({n: outbox[n] for n in cell.neighbours})
        t2 = time.perf_counter()
        formation.velocities(positions[k], gradients[k], measured[k])
        t3 = time.perf_counter()
        spent["intra-cell update"] += t1 - t0
        spent["projection"] += t2 - t1
        spent["formation law"] += t3 - t2
    return spent


def per_cell_step(scenario: DistributedScenario, n: int, steps: int = 60) -> float:
    """Microseconds per cell and step of the filter on an n × n grid translating through the field."""
    positions, cells = grid_network(n, n, (30.0, 30.0))
    mesh = SensorMesh(cells, positions)
    field = scenario.field.build()
    network = DistributedFilter(
        mesh, scenario.filter, scenario.noise_std, PdeModel(field.diffusivity, field.velocity, 1.0)
    )
    rng = np.random.default_rng(0)
    network.start(
        positions, field.value(positions, 0.0) + scenario.noise_std * rng.standard_normal(len(positions))
    )
    t0 = time.perf_counter()
    for k in range(1, steps + 1):
        moved = positions + 0.5 * k
        network.step(
            moved, field.value(moved, float(k)) + scenario.noise_std * rng.standard_normal(len(moved))
        )
    return 1e6 * (time.perf_counter() - t0) / (steps * mesh.n_cells)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    scenario = load_config(SCENARIO, DistributedScenario)

    runs = [simulate(scenario) for _ in range(args.repeats)]
    runtime = statistics.median(ds.attrs["runtime_s"] for ds in runs)
    cell_steps = scenario.time.n_steps * len(scenario.network.cells)
    console.print(
        f"600 s scenario: {runtime:.3f} s (median of {args.repeats}), real-time factor "
        f"{scenario.time.duration / runtime:.0f}, {1e6 * runtime / cell_steps:.0f} µs per cell-step "
        "(target < 1.5 s)"
    )

    spent = replay_split(scenario, runs[0])
    total = sum(spent.values())
    table = Table(title="Replay of the scenario's data: where the time goes")
    table.add_column("part")
    table.add_column("share", justify="right")
    table.add_column("µs per step", justify="right")
    for part, seconds in spent.items():
        table.add_row(part, f"{seconds / total:.0%}", f"{1e6 * seconds / scenario.time.n_steps:.0f}")
    console.print(table)

    scaling = Table(title="Filter cost per cell-step on n × n square grids (flat = distributed)")
    for column in ("cells", "µs per cell-step", "ratio to 9 cells"):
        scaling.add_column(column, justify="right")
    base = None
    per_cell_step(scenario, 3, steps=5)  # warm-up (first calls into numpy/linalg)
    for n in (3, 6, 12):
        cost = per_cell_step(scenario, n)
        base = base or cost
        scaling.add_row(str(n * n), f"{cost:.0f}", f"{cost / base:.2f}")
    console.print(scaling)


if __name__ == "__main__":
    main()
