"""Figures of a distributed-filter simulation: cell-centre paths over level curves, estimates vs truth.

Both functions take the ``xarray.Dataset`` of :func:`mobisense.formation.distributed.simulation.simulate` and
return a matplotlib Figure (for :func:`mobisense.core.files.write_figure` or a notebook).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ...estimation.fields.base import Field

__all__ = ["plot_paths", "plot_estimates"]


def _draw_mesh(ax: Any, ds: Any, k: int, color: str, label: str) -> None:
    positions = ds["sensor_position"].isel(time=k).values
    for j, corners in enumerate(ds["cell_sensors"].values):
        polygon = positions[corners[corners >= 0]]
        closed = np.vstack([polygon, polygon[:1]])
        ax.plot(closed[:, 0], closed[:, 1], color=color, lw=0.8, label=label if j == 0 else None)
    ax.plot(positions[:, 0], positions[:, 1], "o", color=color, ms=3)


def plot_paths(ds: Any, field: Field, length_unit: str = "m") -> Any:
    """Cell-centre paths over the field's level curves at the first and the last sample (two panels).

    Parameters
    ----------
    ds : xarray.Dataset
        Simulation result.
    field : Field
        The true field (its level curves are drawn at t = 0 and t = T).
    length_unit : str
        Label of the length unit L.
    """
    import matplotlib.pyplot as plt

    centres = ds["centre"].values  # (cell, time, 2)
    sensors = ds["sensor_position"].values
    times = ds["time"].values
    lo = np.minimum(centres.min(axis=(0, 1)), sensors.min(axis=(0, 1)))
    hi = np.maximum(centres.max(axis=(0, 1)), sensors.max(axis=(0, 1)))
    pad = 0.1 * (hi - lo).max()
    x = np.linspace(lo[0] - pad, hi[0] + pad, 160)
    y = np.linspace(lo[1] - pad, hi[1] + pad, 160)
    grid = np.stack(np.meshgrid(x, y), axis=-1)
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.4), sharex=True, sharey=True, constrained_layout=True)
    for ax, k, title in ((axes[0], 0, "initial"), (axes[1], -1, "final")):
        levels = ax.contour(x, y, field.value(grid, times[k]), levels=12, cmap="viridis", linewidths=0.8)
        ax.clabel(levels, fontsize=7, fmt="%.2f")
        for j in ds["cell"].values:
            ax.plot(centres[j, :, 0], centres[j, :, 1], lw=1.0, label=f"cell {j}")
        _draw_mesh(ax, ds, 0, "tab:gray", "initial formation")
        _draw_mesh(ax, ds, -1, "black", "final formation")
        ax.set_title(f"Cell-centre paths; level curves of z at t = {times[k]:g} s ({title})")
        ax.set_xlabel(f"x ({length_unit})")
        ax.set_aspect("equal")
    axes[0].set_ylabel(f"y ({length_unit})")
    axes[1].legend(loc="center left", bbox_to_anchor=(1.02, 0.5), fontsize=8)
    return fig


def plot_estimates(ds: Any, cells: Sequence[int], field_unit: str = "field unit") -> Any:
    """Estimates of z at the centres of ``cells`` vs time: truth, measured mean, unconstrained, constrained.

    Parameters
    ----------
    ds : xarray.Dataset
        Simulation result.
    cells : sequence of int
        The cells to show, one panel each.
    field_unit : str
        Label of the field's unit.
    """
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(cells), 1, figsize=(10, 3.2 * len(cells)), sharex=True, squeeze=False)
    t = ds["time"].values
    styles = (
        ("z_measured", "mean of the cell's measurements", dict(color="tab:blue", lw=0.6, ls="--", alpha=0.7)),
        ("z_unconstrained", "unconstrained filter", dict(color="tab:red", lw=1.0)),
        ("z_constrained", "constrained filter", dict(color="goldenrod", lw=1.2)),
        ("z_true", "true value", dict(color="purple", lw=1.2)),
    )
    for ax, j in zip(axes[:, 0], cells, strict=True):
        for var, label, style in styles:
            ax.plot(t, ds[var].sel(cell=j).values, label=label, **style)
        ax.set_ylabel(f"z at centre ({field_unit})")
        ax.set_title(f"Cell {j}: field value at the cell centre")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel("time t (s)")
    fig.tight_layout()
    return fig
