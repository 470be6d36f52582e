"""Figures of an OCP replay (:mod:`mobisense.formation.replay.plan`): flown vs planned paths, covariance, NEES band."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["save_ocp_figures"]


def _paths(ds: Any, locations: np.ndarray) -> Any:
    import matplotlib.pyplot as plt

    length = ds["r"].attrs["units"]
    fig, ax = plt.subplots(figsize=(6.0, 5.2))
    ax.plot(locations[:, 0], locations[:, 1], "r*", ms=12, label="process locations", zorder=2)
    for i, name in enumerate(ds["sensor"].values):
        ref, flown = ds["r_ref"].values[:, i], ds["r"].values[:, i]
        line = ax.plot(flown[:, 0], flown[:, 1], lw=3.5, alpha=0.6, label=f"flown: {name}", zorder=3)[0]
        ax.plot(ref[:, 0], ref[:, 1], "k--", lw=1.2, label="optimised path" if i == 0 else None, zorder=4)
        ax.plot(*flown[0], "o", color=line.get_color(), mec="k", ms=7, label="start" if i == 0 else None, zorder=5)
        ax.plot(*flown[-1], "s", mfc="none", mec=line.get_color(), mew=2, ms=12, label="end" if i == 0 else None,
                zorder=5)  # hollow: a process location under it stays visible  # fmt: skip
    err = ds["tracking_error"].values
    ax.set(xlabel=f"x ({length})", ylabel=f"y ({length})", aspect="equal",
           title=f"{ds.attrs['problem']}: replayed plan\n"
           f"(flown at most {err.max():.2g} {length} off the plan)")  # fmt: skip
    ax.legend(fontsize=8)
    return fig


def _covariance(ds: Any) -> Any:
    import matplotlib.pyplot as plt

    t = ds["time"].values
    trace = {
        k: np.trace(ds[k].values, axis1=1, axis2=2)
        for k in ("Sigma_predicted", "P_filter", "covariance_empirical")
    }
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ax.semilogy(t, trace["Sigma_predicted"], "k-", lw=2, label="optimiser's prediction Tr Σ(t)")
    ax.semilogy(t, trace["P_filter"], "--", color="tab:orange", label="sampled filter Tr P_k(+)")
    ax.semilogy(t, trace["covariance_empirical"], color="tab:blue", alpha=0.7,
                label=f"Monte Carlo Tr E[e e'] ({ds.attrs['runs']} runs)")  # fmt: skip
    time_unit, variance = ds["time"].attrs["units"], ds["Sigma_predicted"].attrs["units"]
    variance = "dimensionless" if variance == "1" else variance
    ax.set(xlabel=f"time ({time_unit})", ylabel=f"trace of the error covariance ({variance})",
           title="Promised vs delivered estimation error\n"
           f"(filter period {ds.attrs['time_step']:.3g} {time_unit})")  # fmt: skip
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    return fig


def _nees(ds: Any) -> Any:
    """The average NEES against the optimiser's Σ(t) with its χ² band, and (below) against the filter's P.

    The two normalisations differ by the small gap between the sampled filter's P and the Riccati Σ(t),
    so on one axis the second curve would hide behind the first: it gets its own panel, as the difference.
    """
    import matplotlib.pyplot as plt

    t = ds["time"].values
    time_unit = ds["time"].attrs["units"]
    fig, (ax, ax_diff) = plt.subplots(2, 1, figsize=(6.4, 5.6), sharex=True, height_ratios=(2.2, 1))
    lo, hi = ds.attrs["band_low"], ds.attrs["band_high"]
    ax.axhspan(lo, hi, color="tab:green", alpha=0.15, label=f"{100 * ds.attrs['confidence']:.0f}% χ² band")
    ax.axhline(1.0, color="k", lw=0.8)
    ax.plot(t, ds["nees_predicted"].values, lw=1, label="against the optimiser's Σ(t)")
    ylim = (max(0.0, lo - 3 * (hi - lo)), hi + 3 * (hi - lo))
    ax.set(ylabel="average NEES / n", ylim=ylim,
           title=f"Normalised estimation error squared, averaged over {ds.attrs['runs']} runs")  # fmt: skip
    ax.legend(fontsize=8, loc="upper left")
    difference = ds["nees_filter"].values - ds["nees_predicted"].values
    ax_diff.plot(t, difference, color="tab:orange", lw=1, label="NEES against the filter's P minus against Σ(t)")
    ax_diff.axhline(0.0, color="k", lw=0.8)
    ax_diff.set(xlabel=f"time ({time_unit})", ylabel="difference / n")
    ax_diff.legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    return fig


def save_ocp_figures(ds: Any, locations: np.ndarray, out: Path) -> list[Path]:
    """Write ``paths.png``, ``covariance.png`` and ``nees.png`` into ``out``; return their paths."""
    from ...core.files import write_figure

    n = len(ds["row"])
    ds = ds.assign(nees_predicted=ds["nees_predicted"] / n, nees_filter=ds["nees_filter"] / n)
    ds.attrs.update(band_low=ds.attrs["band_low"] / n, band_high=ds.attrs["band_high"] / n)
    figures = {"paths.png": lambda: _paths(ds, locations), "covariance.png": lambda: _covariance(ds),
               "nees.png": lambda: _nees(ds)}  # fmt: skip
    for name, draw in figures.items():
        write_figure(out / name, draw)
    return [out / name for name in figures]
