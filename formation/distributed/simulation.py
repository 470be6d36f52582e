"""Closed-loop simulation of a sensor mesh in an advection–diffusion field (docs/theory/distributed.md §9), YAML form.

The scenario is that of Zhang et al. (2023), §8.

Each step k (Δt apart): the sensors move by the gradient-based formation law using the constrained
estimates of step k−1, measure ``p_i = z(r_i, t_k) + n_i`` (i.i.d. Gaussian, σ from the SNR), and the
distributed filter runs Algorithm 1 (intra-cell update, messages, projection). The result is an
:class:`xarray.Dataset` (see :func:`simulate`); :func:`error_table` makes the paper's Table 1 from it.

Noise level: ``snr`` is the ratio of the field's mean power over a spatial period at t = 0, ``A²/4``
for the product of sines of amplitude A, to the noise variance, so ``σ = A/(2√snr)``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator

from ...core.config import InvalidValue, NonNegativeFloat, PositiveFloat, Seed, StrictModel, Vector2
from ...estimation.distributed.filter import DistributedFilter, FilterOptions, PdeModel
from ...estimation.distributed.mesh import MeshError, SensorMesh
from ...estimation.fields.advection_diffusion import AdvectionDiffusionField
from ..simulation_result import SimulationResult
from .gradient_formation import FormationOptions, GradientFormation

__all__ = [
    "TimeGrid",
    "AdvectionDiffusionSpec",
    "NoiseSpec",
    "NetworkSpec",
    "OutputSpec",
    "DistributedScenario",
    "simulate",
    "error_table",
    "summarise",
    "DistributedResult",
    "run_distributed",
]


class TimeGrid(StrictModel):
    """Sampling interval Δt and duration T (s); ``T/Δt`` must be a whole number of steps."""

    step: PositiveFloat = 1.0
    duration: PositiveFloat = 600.0

    @model_validator(mode="after")
    def _whole_steps(self) -> TimeGrid:
        steps = self.duration / self.step
        if abs(steps - round(steps)) > 1e-9 * steps or round(steps) < 2:
            raise InvalidValue(
                "duration", f"expected a whole number (≥ 2) of steps {self.step}, got {steps:g}"
            )
        return self

    @property
    def n_steps(self) -> int:
        """Number K of filter steps; samples are taken at ``t_k = k Δt``, k = 0..K."""
        return round(self.duration / self.step)


class AdvectionDiffusionSpec(StrictModel):
    """The field ``∂z/∂t = θΔz + v·∇z`` (:class:`AdvectionDiffusionField`); the filter knows θ and v."""

    kind: Literal["advection_diffusion"] = "advection_diffusion"
    diffusivity: PositiveFloat = Field(2.0, description="θ (L²/s)")
    velocity: Vector2 = Field([0.5, 1.0], description="v (L/s)")
    wavenumber: PositiveFloat = Field(0.003, description="k (1/L)")
    amplitude: PositiveFloat = 1.0
    variant: Literal["exact", "paper"] = "exact"
    temporal_wavenumber: PositiveFloat = Field(1e-4, description="k₂ of variant 'paper' (1/L)")

    def build(self) -> AdvectionDiffusionField:
        """The field object."""
        return AdvectionDiffusionField(**self.model_dump(exclude={"kind"}))


class NoiseSpec(StrictModel):
    """Measurement noise: ``snr`` = (A²/4)/σ² (see the module docstring)."""

    snr: PositiveFloat = 10.0


class NetworkSpec(StrictModel):
    """Initial sensor positions (L) and the cells as lists of 0-based sensor indices in polygon order."""

    positions: list[Vector2]
    cells: list[list[int]]

    @model_validator(mode="after")
    def _valid_mesh(self) -> NetworkSpec:
        try:
            SensorMesh(self.cells, np.asarray(self.positions, dtype=float))
        except MeshError as err:
            raise InvalidValue("cells", str(err)) from None
        return self

    def mesh(self) -> SensorMesh:
        """The validated :class:`SensorMesh`."""
        return SensorMesh(self.cells, np.asarray(self.positions, dtype=float))


class OutputSpec(StrictModel):
    """What to report: the two cells whose estimates are plotted, and the start of the statistics window."""

    plot_cells: list[int] = Field([0, 5], min_length=1, max_length=4)
    statistics_from: NonNegativeFloat = Field(0.0, description="error statistics over t ≥ this (s), t ≥ Δt")


class DistributedScenario(StrictModel):
    """A ``mobisense simulate distributed`` scenario file."""

    kind: Literal["distributed"] | None = Field(None, description="file kind (optional: 'network' tells it)")
    name: str = "distributed"
    seed: Seed = 0
    time: TimeGrid = TimeGrid()
    field: AdvectionDiffusionSpec = AdvectionDiffusionSpec()
    noise: NoiseSpec = NoiseSpec()
    network: NetworkSpec
    filter: FilterOptions
    formation: FormationOptions
    output: OutputSpec = OutputSpec()

    @model_validator(mode="after")
    def _cells_exist(self) -> DistributedScenario:
        n_cells = len(self.network.cells)
        bad = [j for j in self.output.plot_cells if not 0 <= j < n_cells]
        if bad:
            raise InvalidValue("output.plot_cells", f"expected cell indices in 0..{n_cells - 1}, got {bad}")
        if self.output.statistics_from >= self.time.duration:
            raise InvalidValue("output.statistics_from", f"expected < duration {self.time.duration}")
        return self

    @property
    def noise_std(self) -> float:
        """σ of the measurement noise (field unit)."""
        return self.field.amplitude / (2.0 * np.sqrt(self.noise.snr))


def simulate(scenario: DistributedScenario, seed: int | None = None, progress: bool = False) -> Any:
    """Run the closed loop and return an ``xarray.Dataset``.

    Parameters
    ----------
    scenario : DistributedScenario
    seed : int, optional
        Overrides ``scenario.seed`` (``numpy.random.default_rng``).
    progress : bool
        Show a ``rich`` progress bar.

    Returns
    -------
    xarray.Dataset
        Dims ``cell``, ``time`` (s), ``sensor``, ``axis`` (x, y), ``link``, ``corner``. Variables:
        ``z_true``, ``z_measured`` (mean of the cell's measurements), ``z_unconstrained``,
        ``z_constrained`` (cell × time, at the cell centre), ``gradient_*`` (cell × time × axis),
        ``centre`` (cell × time × axis), ``sensor_position`` (sensor × time × axis), ``measurement``
        (sensor × time), ``distance`` / ``desired_distance`` of the intra-cell links (link × time),
        ``link_sensors`` and ``cell_sensors`` (−1 padded). ``attrs['status']`` is ``"ok"`` or says at
        which time the mesh folded; the data then stop at the last valid step.
    """
    import xarray as xr

    rng = np.random.default_rng(scenario.seed if seed is None else seed)
    field = scenario.field.build()
    mesh = scenario.network.mesh()
    dt, K = scenario.time.step, scenario.time.n_steps
    sigma = scenario.noise_std
    assumed = scenario.filter.assumed_pde
    if assumed is None:
        pde = PdeModel(field.diffusivity, field.velocity, dt)
    else:  # the constraint uses other θ, v than the field (docs/theory/distributed.md §10.1)
        pde = PdeModel(assumed.diffusivity, np.asarray(assumed.velocity, dtype=float), dt)
    network = DistributedFilter(mesh, scenario.filter, sigma, pde)
    formation = GradientFormation(
        mesh, scenario.formation, np.asarray(scenario.network.positions, dtype=float)
    )
    links = formation.links

    t = dt * np.arange(K + 1)
    noise = sigma * rng.standard_normal((K + 1, mesh.n_sensors))
    positions = np.empty((K + 1, mesh.n_sensors, 2))
    measured = np.empty((K + 1, mesh.n_sensors))
    z = {name: np.empty((K + 1, mesh.n_cells)) for name in ("constrained", "unconstrained")}
    grad = {name: np.empty((K + 1, mesh.n_cells, 2)) for name in ("constrained", "unconstrained")}
    desired = np.full((K + 1, len(links)), np.nan)

    positions[0] = scenario.network.positions
    measured[0] = field.value(positions[0], t[0]) + noise[0]
    network.start(positions[0], measured[0])
    status, last = "ok", K
    started = time.perf_counter()
    with _progress(progress, K) as advance:
        for k in range(K + 1):
            for name, constrained in (("constrained", True), ("unconstrained", False)):
                z[name][k], grad[name][k] = network.estimates(constrained)
            if k == K:
                desired[k] = formation.desired_distances(positions[k], grad["constrained"][k])
                break
            u, desired[k] = formation.velocities(positions[k], grad["constrained"][k], measured[k])
            positions[k + 1] = positions[k] + dt * u  # docs/theory/distributed.md, eq. distributed.16
            measured[k + 1] = field.value(positions[k + 1], t[k + 1]) + noise[k + 1]
            try:
                network.step(positions[k + 1], measured[k + 1])
            except MeshError as err:
                status, last = f"mesh folded at t = {t[k + 1]:g} s: {err}", k
                break
            advance()
    runtime = time.perf_counter() - started

    keep = slice(0, last + 1)
    positions, measured, t = positions[keep], measured[keep], t[keep]
    centres = mesh.centres(positions)  # (time, cell, 2)
    counts = mesh.membership.sum(axis=0)
    cell_sensors = np.full((mesh.n_cells, max(map(len, mesh.cells))), -1)
    for j, cell in enumerate(mesh.cells):
        cell_sensors[j, : len(cell)] = cell
    distance = np.linalg.norm(positions[:, links[:, 1]] - positions[:, links[:, 0]], axis=-1)

    def cell_time(a: np.ndarray) -> np.ndarray:
        return np.swapaxes(a, 0, 1)

    data = {
        "z_true": (("cell", "time"), cell_time(field.value(centres, t[:, None]))),
        "z_measured": (("cell", "time"), cell_time(measured @ mesh.membership / counts)),
        "gradient_true": (("cell", "time", "axis"), cell_time(field.gradient(centres, t[:, None]))),
        "centre": (("cell", "time", "axis"), cell_time(centres)),
        "sensor_position": (("sensor", "time", "axis"), cell_time(positions)),
        "measurement": (("sensor", "time"), measured.T),
        "distance": (("link", "time"), distance.T),
        "desired_distance": (("link", "time"), desired[keep].T),
        "link_sensors": (("link", "end"), links),
        "cell_sensors": (("cell", "corner"), cell_sensors),
    }
    for name in ("unconstrained", "constrained"):
        data[f"z_{name}"] = (("cell", "time"), cell_time(z[name][keep]))
        data[f"gradient_{name}"] = (("cell", "time", "axis"), cell_time(grad[name][keep]))
    ds = xr.Dataset(
        data,
        coords={
            "cell": np.arange(mesh.n_cells),
            "time": t,
            "sensor": np.arange(mesh.n_sensors),
            "axis": ["x", "y"],
        },
        attrs={
            "scenario": scenario.name,
            "seed": scenario.seed if seed is None else seed,
            "status": status,
            "noise_std": sigma,
            "snr": scenario.noise.snr,
            "field": repr(field),
            "projection": scenario.filter.projection,
            "runtime_s": runtime,
        },
    )
    ds.attrs["title"] = f"mobisense: distributed-filter simulation '{scenario.name}'"
    for name, description in _DESCRIPTIONS.items():
        ds[name].attrs.update(long_name=description, units=_UNITS.get(name, "1"))
    return ds


#: units of the variables and coordinates (lengths in m, time in s, the field's values dimensionless)
_UNITS = {
    "time": "s", "gradient_true": "m-1", "gradient_unconstrained": "m-1", "gradient_constrained": "m-1",
    "centre": "m", "sensor_position": "m", "distance": "m", "desired_distance": "m",
}  # fmt: skip


_DESCRIPTIONS = {
    "z_true": "true field value at the cell centre",
    "z_measured": "mean of the cell's noisy measurements",
    "z_unconstrained": "estimate of the unconstrained cooperative filter at the cell centre",
    "z_constrained": "estimate of the PDE-constrained cooperative filter at the cell centre",
    "gradient_true": "true field gradient at the cell centre",
    "gradient_unconstrained": "gradient estimate of the unconstrained filter",
    "gradient_constrained": "gradient estimate of the constrained filter (drives the formation)",
    "centre": "cell centre (mean of its sensors)",
    "sensor_position": "sensor position",
    "measurement": "noisy field measurement of the sensor",
    "distance": "distance between the two sensors of an intra-cell link",
    "desired_distance": "desired distance of the link (Zhang et al. (2023), eq. 39, times its shape ratio)",
    "link_sensors": "the two sensors of each intra-cell link",
    "cell_sensors": "sensors at the cell's vertices, counter-clockwise, -1 padded",
    "time": "time of the samples",
    "cell": "cell number",
    "sensor": "sensor number",
}


class _progress:
    """Context manager yielding an ``advance()`` callable; a ``rich`` bar when enabled, else a no-op."""

    def __init__(self, enabled: bool, total: int) -> None:
        self.enabled, self.total = enabled, total

    def __enter__(self) -> Any:
        if not self.enabled:
            return lambda: None
        from rich.progress import Progress

        self._bar = Progress(transient=True)
        self._bar.__enter__()
        task = self._bar.add_task("simulating", total=self.total)
        return lambda: self._bar.advance(task)

    def __exit__(self, *exc: object) -> None:
        if self.enabled:
            self._bar.__exit__(*exc)


def error_table(ds: Any, statistics_from: float = 0.0) -> list[dict[str, float]]:
    """Per-cell means and standard deviations of the errors (estimate − truth), like the paper's Table 1.

    Parameters
    ----------
    ds : xarray.Dataset
        From :func:`simulate`.
    statistics_from : float
        Use the samples with ``t ≥ max(statistics_from, Δt)`` (s): the filter's first update is at Δt.

    Returns
    -------
    list of dict
        One row per cell: ``cell``, ``mean_noise``, ``mean_unconstrained``, ``mean_constrained``,
        ``std_noise``, ``std_unconstrained``, ``std_constrained`` (field unit), ``n_samples``.
    """
    t = ds["time"].values
    first = max(statistics_from, t[1] if len(t) > 1 else 0.0)
    window = ds.sel(time=t[t >= first - 1e-9 * max(1.0, abs(first))])
    rows = []
    for j in ds["cell"].values:
        row: dict[str, float] = {"cell": int(j)}
        truth = window["z_true"].sel(cell=j).values
        for label, var in (
            ("noise", "z_measured"),
            ("unconstrained", "z_unconstrained"),
            ("constrained", "z_constrained"),
        ):
            error = window[var].sel(cell=j).values - truth
            row[f"mean_{label}"] = float(error.mean())
            row[f"std_{label}"] = float(error.std())
        row["n_samples"] = int(window.sizes["time"])
        rows.append(row)
    return rows


def summarise(ds: Any, statistics_from: float = 0.0) -> dict[str, Any]:
    """The ``summary.json`` content: run facts, the per-cell error table and formation metrics.

    Parameters
    ----------
    ds : xarray.Dataset
        From :func:`simulate`.
    statistics_from : float
        Start of the statistics window (s), as in :func:`error_table`.
    """
    table = error_table(ds, statistics_from)
    window = ds.sel(time=ds["time"].values[ds["time"].values >= max(statistics_from, float(ds["time"][1]))])

    def rms(var: str) -> float:
        return float(np.sqrt(((window[var] - window["z_true"]) ** 2).mean()))

    def gradient_rms(var: str) -> float:
        return float(np.sqrt(((window[var] - window["gradient_true"]) ** 2).sum("axis").mean()))

    spacing_error = (ds["distance"] - ds["desired_distance"]) / ds["desired_distance"]
    return {
        "scenario": ds.attrs["scenario"],
        "seed": ds.attrs["seed"],
        "status": ds.attrs["status"],
        "noise_std": ds.attrs["noise_std"],
        "snr": ds.attrs["snr"],
        "projection": ds.attrs["projection"],
        "steps": int(ds.sizes["time"] - 1),
        "simulation_runtime_s": ds.attrs["runtime_s"],
        "statistics_from_s": float(window["time"][0]),
        "error_table": table,
        "cells_with_lower_constrained_std": [
            r["cell"] for r in table if r["std_constrained"] < r["std_unconstrained"]
        ],
        "rms_error": {name: rms(f"z_{name}") for name in ("measured", "unconstrained", "constrained")},
        "gradient_rms_error": {
            name: gradient_rms(f"gradient_{name}") for name in ("unconstrained", "constrained")
        },
        "formation": {
            "distance_min": float(ds["distance"].min()),
            "distance_max": float(ds["distance"].max()),
            "desired_distance_min": float(ds["desired_distance"].min()),
            "desired_distance_max": float(ds["desired_distance"].max()),
            "rms_relative_spacing_error": float(np.sqrt((spacing_error**2).mean())),
            "centre_start": ds["centre"].isel(time=0).mean("cell").values.tolist(),
            "centre_end": ds["centre"].isel(time=-1).mean("cell").values.tolist(),
        },
    }


class DistributedResult(SimulationResult):
    """A distributed-filter run: the dataset of :func:`simulate`, the per-cell error table, two figures."""

    kind = "distributed"

    def __init__(self, dataset: Any, summary: dict[str, Any], scenario: DistributedScenario) -> None:
        super().__init__(dataset, summary)
        self.scenario = scenario

    def plot(self, folder: str | Path) -> list[Path]:
        """``paths.png`` (cell-centre paths over level curves) and ``estimates.png`` (estimates vs truth)."""
        from ...core.files import write_figure
        from .plots import plot_estimates, plot_paths

        folder = Path(folder)
        field = self.scenario.field.build()
        write_figure(folder / "paths.png", lambda: plot_paths(self.dataset, field))
        cells = self.scenario.output.plot_cells
        write_figure(folder / "estimates.png", lambda: plot_estimates(self.dataset, cells, "dimensionless"))
        return [folder / "paths.png", folder / "estimates.png"]

    def report(self, folder: Path) -> None:
        """The per-cell error table (the paper's Table 1) and where the files went."""
        s = self.summary
        print(f"{s['scenario']}: {s['steps']} steps, noise σ = {s['noise_std']:.4g}, seed {s['seed']}")
        print("errors of the field value at each cell centre (estimate − truth): mean and standard deviation of")
        print("  the cell's averaged measurements, the unconstrained filter and the PDE-constrained filter")
        print(f"{'cell':>4} {'mean:':>6}{'meas.':>7} {'uncons.':>9} {'constr.':>9}  {'std:':>5}{'meas.':>6} "
              f"{'uncons.':>8} {'constr.':>8}")  # fmt: skip

        def number(x: float, width: int) -> str:  # fixed point, or exponent for a diverged estimate
            return f"{x:>{width}.4f}" if abs(x) < 1e4 else f"{x:>{width}.2e}"

        for row in s["error_table"]:
            means = " ".join(number(row[k], w) for k, w in (("mean_noise", 13), ("mean_unconstrained", 9),
                                                              ("mean_constrained", 9)))  # fmt: skip
            stds = " ".join(number(row[k], w) for k, w in (("std_noise", 12), ("std_unconstrained", 8),
                                                             ("std_constrained", 8)))  # fmt: skip
            print(f"{row['cell']:>4} {means} {stds}")
        worst = max(row["std_constrained"] for row in s["error_table"])
        if not worst < 1e3 * max(row["std_noise"] for row in s["error_table"]):
            print(f"the constrained estimate diverged (error std up to {worst:.2e}): projection "
                  f"'{self.scenario.filter.projection}' is unstable here (docs/theory/distributed.md §10.2)")
        better = s["cells_with_lower_constrained_std"]
        print(f"constrained std lower in {len(better)}/{len(s['error_table'])} cells; results in {folder}/")


def run_distributed(
    scenario: DistributedScenario, seed: int | None = None, progress: bool | None = None
) -> DistributedResult:
    """Simulate ``scenario`` and summarise it (``status`` is not ``"ok"`` if the mesh folded).

    Parameters
    ----------
    scenario : DistributedScenario
    seed : int, optional
        Overrides ``scenario.seed``.
    progress : bool, optional
        Show a progress bar (default: when standard error is a terminal).
    """
    ds = simulate(scenario, seed=seed, progress=sys.stderr.isatty() if progress is None else progress)
    return DistributedResult(ds, summarise(ds, scenario.output.statistics_from), scenario)
