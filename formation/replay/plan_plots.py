"""Figures of an OCP replay (:mod:`mobisense.formation.replay.plan`): flown vs planned paths, covariance, NEES band."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["save_ocp_figures"]


def _paths(ds: Any, locations: np.ndarray) -> Any:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.0, 5.2))
    for i, name in enumerate(ds["sensor"].values):
        ref, flown = ds["r_ref"].values[:, i], ds["r"].values[:, i]
        ax.plot(ref[:, 0], ref[:, 1], "k--", lw=1.2, label="optimised path" if i == 0 else None)
        ax.plot(flown[:, 0], flown[:, 1], lw=2, alpha=0.7, label=f"flown: {name}")
        ax.plot(*flown[0], "o", color="tab:green", label="start" if i == 0 else None)
    ax.plot(locations[:, 0], locations[:, 1], "r*", ms=12, label="process locations")
    err = ds["tracking_error"].values
    ax.set(xlabel="x (L)", ylabel="y (L)", aspect="equal",
           title=f"{ds.attrs['problem']}: replayed plan (max tracking error {err.max():.2g} L)")  # fmt: skip
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
    ax.set(xlabel="time (T)", ylabel="error variance (state unit²)",
           title=f"Promised vs delivered estimation error, Δt = {ds.attrs['time_step']:.3g} T")  # fmt: skip
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    return fig


def _nees(ds: Any) -> Any:
    import matplotlib.pyplot as plt

    t = ds["time"].values
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    ax.plot(t, ds["nees_predicted"].values, lw=1, label="against the optimiser's Σ(t)")
    ax.plot(t, ds["nees_filter"].values, lw=1, alpha=0.7, label="against the filter's P_k")
    lo, hi = ds.attrs["band_low"], ds.attrs["band_high"]
    ax.axhspan(lo, hi, color="tab:green", alpha=0.15, label=f"{100 * ds.attrs['confidence']:.0f}% χ² band")
    ax.axhline(1.0, color="k", lw=0.8)
    ylim = (max(0.0, lo - 3 * (hi - lo)), hi + 3 * (hi - lo))
    ax.set(xlabel="time (T)", ylabel="average NEES / n (–)", ylim=ylim,
           title="Normalised estimation error squared, averaged over the runs")  # fmt: skip
    ax.legend(fontsize=8)
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
