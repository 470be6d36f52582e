"""Figures and animation of a field replay (:mod:`mobisense.formation.replay.results` dataset).

``paths.png`` (field contours, the tracked level, platform and centre paths, formation snapshots),
``z_estimate.png`` (estimate ± 2σ vs truth vs time), ``shape.png`` (a(t), and b(t) for four platforms, against
their desired values),
``heading.png`` (θ(t)) and, with a reference, ``tracking.png``. :func:`save_animation` writes
``replay.mp4`` (ffmpeg) or ``replay.gif`` (Pillow), or skips with a message when neither encoder exists.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from .results import units_of

__all__ = ["save_figures", "save_animation", "plot_paths"]


def _extent(ds: Any, extent: list[list[float]] | None) -> tuple[np.ndarray, np.ndarray]:
    if extent is not None:
        return np.asarray(extent[0], float), np.asarray(extent[1], float)
    r = ds["r"].values.reshape(-1, 2)
    lo, hi = r.min(axis=0), r.max(axis=0)
    margin = 0.15 * max(hi - lo) + 1e-9
    return np.array([lo[0] - margin, hi[0] + margin]), np.array([lo[1] - margin, hi[1] + margin])


def _field_background(ax: Any, field: Any, xr_: np.ndarray, yr: np.ndarray, level: float, units: Any) -> Any:
    x, y = np.linspace(*xr_, 200), np.linspace(*yr, 160)
    X, Y = np.meshgrid(x, y)
    Z = field.value(np.stack([X, Y], axis=-1))
    finite = Z[np.isfinite(Z)]
    lo, hi = np.quantile(finite, [0.01, 0.99])
    cs = ax.contourf(X, Y, np.clip(Z, lo, hi), levels=30, cmap="RdYlBu_r", alpha=0.85)
    if np.isfinite(level) and lo <= level <= hi:
        ax.contour(X, Y, Z, levels=[level], colors="k", linewidths=2.2)
        ax.plot([], [], "k-", lw=2.2, label=f"tracked level z = {level:g} {units.label(field=1)}")
    return cs


def _snapshot(ax: Any, r: np.ndarray, color: Any) -> None:
    if len(r) == 4:  # the cross: axes 1-2 and 3-4
        for i, j in ((0, 1), (2, 3)):
            ax.plot(r[[i, j], 0], r[[i, j], 1], "-", color=color, lw=1.2)
    else:
        closed = np.vstack([r, r[:1]]) if len(r) > 2 else r
        ax.plot(closed[:, 0], closed[:, 1], "-", color=color, lw=1.2)
    ax.plot(r[:, 0], r[:, 1], "o", color=color, ms=4, mec="k", mew=0.4)


def plot_paths(ds: Any, field: Any, scenario: Any) -> Any:
    """Paths over field contours with formation snapshots (a matplotlib Figure)."""
    import matplotlib.pyplot as plt

    u = units_of(scenario)
    xr_, yr = _extent(ds, scenario.plot.extent)
    fig, ax = plt.subplots(figsize=(7.2, 6.0))
    cs = _field_background(ax, field, xr_, yr, ds.attrs["C"], u)
    fig.colorbar(cs, ax=ax, label=f"field value z ({u.label(field=1)})", shrink=0.85)
    r = ds["r"].values
    for i in range(r.shape[1]):
        ax.plot(
            r[:, i, 0], r[:, i, 1], lw=0.6, color="0.35", alpha=0.6, label="platforms" if i == 0 else None
        )
    center = ds["center"].values
    ax.plot(center[:, 0], center[:, 1], "-", color="tab:purple", lw=1.6, label="formation centre")
    if "reference" in ds:
        ref = ds["reference"].values
        ax.plot(ref[:, 0], ref[:, 1], "--", color="w", lw=1.4, label="reference")
    n = scenario.plot.snapshots
    colors = plt.cm.viridis(np.linspace(0, 1, max(n, 1)))
    for color, k in zip(colors, np.linspace(0, len(r) - 1, n).astype(int), strict=False):
        _snapshot(ax, r[k], color)
        ax.annotate(f"t = {ds['time'].values[k]:.3g} {u.label(time=1)}", r[k].mean(axis=0), fontsize=7, xytext=(4, 4),
                    textcoords="offset points")  # fmt: skip
    ax.plot(*center[0], "s", color="tab:green", ms=7, label="start")
    length = u.label(length=1)
    ax.set(xlim=xr_, ylim=yr, xlabel=f"x ({length})", ylabel=f"y ({length})", aspect="equal",
           title=f"{scenario.name}: {r.shape[1]} platforms, {ds.attrs['formation']} formation,\n"
           f"{ds.attrs['motion'].replace('_', ' ')} motion, snapshots every "
           f"{(ds['time'].values[-1] - ds['time'].values[0]) / max(n - 1, 1):.3g} {u.label(time=1)}")  # fmt: skip
    ax.legend(fontsize=8, loc="best", framealpha=0.8)
    return fig


def _z_estimate(ds: Any, units: Any) -> Any:
    import matplotlib.pyplot as plt

    t, z, zh, sd = (ds[k].values for k in ("time", "z_true", "z_est", "z_std"))
    fig, ax = plt.subplots(figsize=(7.0, 4.0))
    ax.fill_between(t, zh - 2 * sd, zh + 2 * sd, color="tab:blue", alpha=0.2, label="estimate ± 2σ (filter)")
    ax.plot(t, zh, color="tab:blue", lw=1.2, label="estimate ẑ at the centre")
    ax.plot(t, z, color="k", lw=1.2, label="true z at the centre")
    if np.isfinite(ds.attrs["C"]):
        ax.axhline(ds.attrs["C"], color="tab:red", ls="--", lw=1, label=f"level C = {ds.attrs['C']:g}")
    rms = float(np.sqrt(np.mean((zh - z) ** 2)))
    field_unit = units.label(field=1)
    ax.set(xlabel=f"time ({units.label(time=1)})", ylabel=f"field value z ({field_unit})",
           title=f"Field at the centre: estimate vs truth (RMS error {rms:.3g} {field_unit})")  # fmt: skip
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    return fig


def _shape(ds: Any, units: Any) -> Any:
    """Half distances a(t) (and b(t) for four platforms) against their desired values.

    A shape held by the controller to rounding error would fill any axis autoscaled to it with noise: the
    axis spans at least ±5 % of the values, and the title says how far the shape strayed.
    """
    import matplotlib.pyplot as plt

    t = ds["time"].values
    length = units.label(length=1)
    has_b = bool(np.isfinite(ds["b"].values).any())
    fig, ax = plt.subplots(figsize=(7.0, 3.8))
    ax.plot(t, ds["a_desired"].values, "--", color="tab:blue", lw=2.4, label="a desired")
    ax.plot(t, ds["a"].values, color="tab:blue", lw=1.2, label="a: half distance of platforms 1-2")
    names = ["a"]
    if has_b:
        ax.plot(t, ds["b_desired"].values, "--", color="tab:orange", lw=2.4, label="b desired")
        ax.plot(t, ds["b"].values, color="tab:orange", lw=1.2, label="b: half distance of platforms 3-4")
        names.append("b")
    values = np.concatenate([ds[k].values for k in (*names, *(f"{n}_desired" for n in names))])
    values = values[np.isfinite(values)]
    centre, span = 0.5 * (values.max() + values.min()), values.max() - values.min()
    half = max(0.5 * span * 1.1, 0.05 * max(abs(values).max(), 1e-12))
    ax.set_ylim(centre - half, centre + half)
    ax.ticklabel_format(axis="y", useOffset=False)
    stray = max(float(np.nanmax(np.abs(ds[n].values - ds[f"{n}_desired"].values))) for n in names)
    shown = " and ".join(f"{n}(t)" for n in names)
    ax.set(xlabel=f"time ({units.label(time=1)})", ylabel=f"half distance ({length})",
           title=f"Formation shape {shown}: at most {stray:.2g} {length} from the desired value")  # fmt: skip
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    return fig


def _heading(ds: Any, units: Any) -> Any:
    import matplotlib.pyplot as plt

    t = ds["time"].values
    fig, ax = plt.subplots(figsize=(7.0, 3.8))
    ax.plot(t, ds["theta"].values, color="k", lw=1.2, label="θ w.r.t. the true level curve")
    ax.plot(t, ds["theta_est"].values, color="tab:blue", lw=0.8, alpha=0.7, label="θ seen by the controller")
    ax.axhline(0.0, color="0.5", lw=0.8)
    ax.set(xlabel=f"time ({units.label(time=1)})", ylabel="heading error θ (rad)",
           title="Heading error of the formation centre, θ(t)")  # fmt: skip
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    return fig


def _tracking(ds: Any, units: Any) -> Any:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.0, 3.8))
    ax.semilogy(ds["time"].values, np.maximum(ds["reference_error"].values, 1e-16), color="tab:purple")
    ax.set(xlabel=f"time ({units.label(time=1)})",
           ylabel=f"distance of the centre from its reference ({units.label(length=1)})",
           title="Tracking error of the formation centre")  # fmt: skip
    ax.grid(alpha=0.3, which="both")
    return fig


def save_figures(ds: Any, field: Any, scenario: Any, out: Path) -> list[Path]:
    """Write the figures into ``out``; return their paths."""
    from ...core.files import write_figure

    u = units_of(scenario)
    figures = {
        "paths.png": lambda: plot_paths(ds, field, scenario),
        "z_estimate.png": lambda: _z_estimate(ds, u),
        "shape.png": lambda: _shape(ds, u),
        "heading.png": lambda: _heading(ds, u),
    }
    if "reference_error" in ds:
        figures["tracking.png"] = lambda: _tracking(ds, u)
    for name, draw in figures.items():
        write_figure(out / name, draw)
    return [out / name for name in figures]


def save_animation(ds: Any, field: Any, scenario: Any, out: Path, max_frames: int = 150) -> Path | None:
    """Animate the platforms over the field: ``replay.mp4`` (ffmpeg) or ``replay.gif`` (Pillow).

    Returns the file written, or ``None`` (with a message on stdout) when no encoder is available.
    """
    import matplotlib.pyplot as plt
    from matplotlib import animation

    if animation.writers.is_available("ffmpeg"):
        name, writer = "replay.mp4", animation.FFMpegWriter(fps=15)
    elif animation.writers.is_available("pillow"):
        name, writer = "replay.gif", animation.PillowWriter(fps=12)
    else:
        print("animation skipped: neither ffmpeg nor Pillow is available")
        return None
    u = units_of(scenario)
    xr_, yr = _extent(ds, scenario.plot.extent)
    r, center, t = ds["r"].values, ds["center"].values, ds["time"].values
    frames = np.unique(np.linspace(0, len(t) - 1, min(max_frames, len(t))).astype(int))
    fig, ax = plt.subplots(figsize=(6.4, 5.2))
    _field_background(ax, field, xr_, yr, ds.attrs["C"], u)
    (trail,) = ax.plot([], [], "-", color="tab:purple", lw=1.5)
    (dots,) = ax.plot([], [], "o", color="w", mec="k", ms=6)
    title = ax.set_title("")
    ax.set(xlim=xr_, ylim=yr, xlabel=f"x ({u.label(length=1)})", ylabel=f"y ({u.label(length=1)})", aspect="equal")

    def draw(k: int) -> tuple[Any, ...]:
        trail.set_data(center[: k + 1, 0], center[: k + 1, 1])
        dots.set_data(r[k, :, 0], r[k, :, 1])
        title.set_text(f"{scenario.name}: t = {t[k]:.3g} {u.label(time=1)}")
        return trail, dots, title

    anim = animation.FuncAnimation(fig, draw, frames=frames, blit=False)
    tmp = out / f".partial-{name}"  # the encoders pick the container from the extension: keep it
    try:
        anim.save(tmp, writer=writer, dpi=90)
        os.replace(tmp, out / name)  # atomic, as mobisense.core.files
    finally:
        plt.close(fig)
        tmp.unlink(missing_ok=True)
    return out / name
