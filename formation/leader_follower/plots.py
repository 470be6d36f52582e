"""Figures of a leader–follower result.

The dataset is the one of :func:`mobisense.formation.leader_follower.runs.simulate_scenario`.

Each function returns a matplotlib ``Figure`` (to be saved with :func:`mobisense.core.files.write_figure`):
paths (Karasalo & Hu (2010), Figs. 10, 14–15), ``d − d0`` and ``β − β0`` (Fig. 11), ``x_e, y_e`` (Figs. 12, 21), path
deviation (eq. 54, Fig. 16), the formation parameters ``d0(t), β0(t)`` (Figs. 17–19) and the switching
filter's active pairs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import xarray as xr

from ...core.files import write_figure

__all__ = [
    "plot_paths",
    "plot_formation_errors",
    "plot_reference_point_errors",
    "plot_deviation",
    "plot_references",
    "plot_active_pairs",
    "save_figures",
]

_RUN_STYLES = ("-", "--", ":", "-.")


def _width(r: int, runs: int) -> float:
    """Line width of run ``r``: earlier runs wider, so runs whose curves coincide stay visible as layers."""
    return 1.0 + 1.5 * (runs - 1 - r)


def _lines(result: xr.Dataset):
    """``(run, follower, label, style)`` for every run × follower curve; ``style`` holds colour, ls, lw."""
    import matplotlib.pyplot as plt

    colours = plt.get_cmap("tab10")
    many_followers = result.sizes["follower"] > 1
    runs = result.sizes["run"]
    for r, run in enumerate(result["run"].values):
        control = str(result["control"].sel(run=run).values)
        for f, follower in enumerate(result["follower"].values):
            label = (str(run) if str(run) == control else f"{run} ({control})") + (
                f", follower {int(follower)}" if many_followers else ""
            )
            style = {
                "color": colours(f if many_followers else r),
                "ls": _RUN_STYLES[r % len(_RUN_STYLES)] if many_followers else "-",
                "lw": _width(r, runs),
                "alpha": 0.85,
            }
            yield run, follower, label, style


def _wrapped(values: xr.DataArray) -> xr.DataArray:
    return np.remainder(values + np.pi, 2 * np.pi) - np.pi


def plot_paths(result: xr.Dataset):  # noqa: ANN201  (matplotlib Figure)
    """Agent paths, one panel per run: leader solid black, followers dashed (○ start, ▲ end)."""
    import matplotlib.pyplot as plt

    runs = result["run"].values
    fig, axes = plt.subplots(1, len(runs), figsize=(5.2 * len(runs), 4.8), squeeze=False)
    colours = plt.get_cmap("tab10")
    for ax, run in zip(axes[0], runs, strict=True):
        r = result.sel(run=run)
        for a in r["agent"].values:
            x, y = r["x"].sel(agent=a).values, r["y"].sel(agent=a).values
            leader = a == r["agent"].values[0]
            style = dict(color="k", lw=1.8) if leader else dict(color=colours(int(a) - 2), lw=1.3, ls="--")
            ax.plot(x, y, label="leader (agent 1)" if leader else f"follower (agent {int(a)})", **style)
            ax.plot(x[0], y[0], "o", color=style["color"], ms=5)
            ax.plot(x[-1], y[-1], "^", color=style["color"], ms=6)
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(f"{run}: {str(r['control'].values)}, {str(r['reference_kind'].values)} formation parameters")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="best", fontsize=8)
    fig.suptitle(f"{result.attrs.get('scenario', '')}: paths (○ start, ▲ end)")
    fig.tight_layout()
    return fig


def plot_formation_errors(result: xr.Dataset):  # noqa: ANN201
    """``d − d0`` and ``β − β0`` over time for every run and follower (Karasalo & Hu (2010), Figs. 11, 20)."""
    import matplotlib.pyplot as plt

    fig, (ax_d, ax_b) = plt.subplots(2, 1, figsize=(8, 6.4), sharex=True)
    t = result["time"].values
    for run, follower, label, style in _lines(result):
        s = result.sel(run=run, follower=follower)
        ax_d.plot(t, s["d"] - s["d0"], label=label, **style)
        ax_b.plot(t, _wrapped(s["beta"] - s["beta0"]), label=label, **style)
    ax_d.set_ylabel("distance error d − d0 (m)")
    ax_b.set_ylabel("bearing error β − β0 (rad)")
    ax_b.set_xlabel("time (s)")
    for ax in (ax_d, ax_b):
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.grid(alpha=0.3)
    ax_d.legend(fontsize=8)
    ax_d.set_title(f"{result.attrs.get('scenario', '')}: formation errors")
    fig.tight_layout()
    return fig


def plot_reference_point_errors(result: xr.Dataset):  # noqa: ANN201
    """``x_e``, ``y_e`` and ``‖(x_e, y_e)‖`` (log scale, with ``‖e(0)‖ e^{−kt}`` dotted) — the paper's Figs. 12, 21."""
    import matplotlib.pyplot as plt

    fig, (ax_x, ax_y, ax_n) = plt.subplots(3, 1, figsize=(8, 8.4), sharex=True)
    t = result["time"].values
    gain = float(result.attrs.get("gain", 1.0))
    for run, follower, label, style in _lines(result):
        s = result.sel(run=run, follower=follower)
        norm = np.hypot(s["xe"].values, s["ye"].values)
        ax_x.plot(t, s["xe"], label=label, **style)
        ax_y.plot(t, s["ye"], label=label, **style)
        ax_n.semilogy(t, norm, label=label, **style)
    first = result.isel(run=0, follower=0)
    e0 = float(np.hypot(first["xe"].values[0], first["ye"].values[0]))
    if e0 > 0:  # the exact decay of Control 1 with exact sensing, for comparison
        ax_n.semilogy(t, e0 * np.exp(-gain * t), "k:", lw=1.2, label=f"‖e(0)‖ exp(−kt), k = {gain:g} 1/s")
    ax_x.set_ylabel("world x component, x_e (m)")
    ax_y.set_ylabel("world y component, y_e (m)")
    ax_n.set_ylabel("distance ‖(x_e, y_e)‖ (m)")
    ax_n.set_xlabel("time (s)")
    for ax in (ax_x, ax_y, ax_n):
        ax.grid(alpha=0.3)
    ax_x.legend(fontsize=8)
    ax_n.legend(fontsize=8)
    ax_x.set_title(f"{result.attrs.get('scenario', '')}: error of the follower's reference point")
    fig.tight_layout()
    return fig


def plot_deviation(result: xr.Dataset):  # noqa: ANN201
    """Deviation of each follower from its predecessor's travelled path (Karasalo & Hu (2010), eq. 54, Fig. 16)."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.2))
    t = result["time"].values
    for run, follower, label, style in _lines(result):
        ax.plot(t, result["deviation"].sel(run=run, follower=follower), label=label, **style)
    ax.set_yscale("log")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("distance from the predecessor's path (m)")
    ax.set_title(f"{result.attrs.get('scenario', '')}: how far each follower strays from its predecessor's path")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, ncol=2)
    fig.tight_layout()
    return fig


def plot_references(result: xr.Dataset):  # noqa: ANN201
    """Formation parameters ``d0(t)`` and ``β0(t)`` (Karasalo & Hu (2010), Figs. 17–19)."""
    import matplotlib.pyplot as plt

    fig, (ax_d, ax_b) = plt.subplots(2, 1, figsize=(8, 5.6), sharex=True)
    t = result["time"].values
    for run, follower, label, style in _lines(result):
        s = result.sel(run=run, follower=follower)
        ax_d.plot(t, s["d0"], label=label, **style)
        ax_b.plot(t, s["beta0"], label=label, **style)
    ax_d.set_ylabel("desired distance d0 (m)")
    ax_b.set_ylabel("desired bearing β0 (rad)")
    ax_b.set_xlabel("time (s)")
    for ax in (ax_d, ax_b):
        ax.grid(alpha=0.3)
    ax_d.legend(fontsize=8, ncol=2)
    ax_d.set_title(f"{result.attrs.get('scenario', '')}: formation parameters")
    fig.tight_layout()
    return fig


def plot_active_pairs(result: xr.Dataset):  # noqa: ANN201
    """Switching filter: active sensor pairs over time (shaded), merged sub-filter (dots), estimation error."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap

    rows = [
        (run, f)
        for run in result["run"].values
        if str(result["sensing_mode"].sel(run=run).values) == "ring"
        for f in result["follower"].values
    ]
    fig, axes = plt.subplots(len(rows) + 1, 1, figsize=(8, 1.6 * len(rows) + 2.6), sharex=True, squeeze=False)
    t = result["time"].values
    pairs = result["pair"].values
    for ax, (run, f) in zip(axes[:-1, 0], rows, strict=True):
        s = result.sel(run=run, follower=f)
        ax.pcolormesh(t, pairs, s["active"].values.T, cmap=ListedColormap(["white", "tab:green"]), shading="nearest")
        chosen = s["selected_pair"].values
        ax.plot(t[chosen > 0], chosen[chosen > 0], "k.", ms=1.5, label="merged sub-filter")
        ax.set_yticks(pairs, [f"pair {p}" for p in pairs], fontsize=7)
        ax.set_ylabel(f"{run}\nfollower {int(f)}", fontsize=8)
    axes[0, 0].set_title("active sensor pairs (green) and the sub-filter picked by the merge (dots)")
    err_ax = axes[-1, 0]
    for k, (run, f) in enumerate(rows):
        err_ax.semilogy(t, result["position_error"].sel(run=run, follower=f), lw=_width(k, len(rows)), alpha=0.85,
                        label=f"{run}, follower {int(f)}")  # fmt: skip
    err_ax.set_ylabel("error ‖p̂ − p‖ (m)")
    err_ax.set_xlabel("time (s)")
    err_ax.grid(alpha=0.3, which="both")
    err_ax.legend(fontsize=7, ncol=2)
    err_ax.set_title("predecessor position estimation error")
    fig.tight_layout()
    return fig


def save_figures(result: xr.Dataset, out: Path) -> list[Path]:
    """Write every applicable figure into ``out``; return their paths."""
    figures = {
        "paths.png": plot_paths,
        "formation_errors.png": plot_formation_errors,
        "reference_point_errors.png": plot_reference_point_errors,
        "deviation.png": plot_deviation,
    }
    if any(str(k) != "constant" for k in result["reference_kind"].values):
        figures["references.png"] = plot_references
    if any(str(m) == "ring" for m in result["sensing_mode"].values):
        figures["active_pairs.png"] = plot_active_pairs
    written = []
    for name, plot in figures.items():
        write_figure(out / name, lambda plot=plot: plot(result))
        written.append(out / name)
    return written
