"""Figures of a field problem: the error-variance maps diag Σ at t0 and tf with the paths, and Tr Σ(t).

``variance_maps.png``: diag Σ on the grid at t0 (the stationary prior), at tf under the optimal paths
(drawn on top: start ○, end △), and at tf without control; ``trace.png``: Tr Σ(t) against the
no-control baseline. The baseline comes from the solution (``baseline["sigma_diag_tf"]`` and
``baseline["trace_Sigma"]``, computed by the solver on the same grid).
"""

from __future__ import annotations

import numpy as np

from .solution import Solution
from .zone_plots import constraint_corners, draw_constraints

__all__ = ["FIELD_FIGURES", "plot_variance_maps", "plot_trace"]


def _label(solution: Solution, **powers: int) -> str:
    return solution.problem.units.system().label(**powers)


def plot_variance_maps(solution: Solution):  # noqa: ANN201  (matplotlib Figure)
    """Diag Σ on the grid at t0, at tf with the optimal paths, and at tf without control (one colour scale)."""
    import matplotlib.pyplot as plt

    spec = solution.problem.process.field
    field = spec.process()
    (x0, x1), (y0, y1) = spec.extent
    nx, ny = spec.grid
    xe, ye = np.linspace(x0, x1, nx + 1), np.linspace(y0, y1, ny + 1)
    diag = solution.variances()
    t, p = solution.t, solution.p
    panels = [(f"t = {t[0]:g}: prior", diag[0], False), (f"t = {t[-1]:g}: optimal paths", diag[-1], True)]
    if "sigma_diag_tf" in solution.baseline:
        panels.append((f"t = {t[-1]:g}: no control", np.asarray(solution.baseline["sigma_diag_tf"]), False))
    vmax = float(diag.max())
    # one frame for every panel: the field, the paths (which may leave it) and the constraints' zones, so the
    # panels are drawn alike
    corners = constraint_corners(solution.problem)
    xs, ys = np.r_[x0, x1, p[..., 0].ravel(), corners[:, 0]], np.r_[y0, y1, p[..., 1].ravel(), corners[:, 1]]
    pad = 0.02 * max(np.ptp(xs), np.ptp(ys))
    xlim, ylim = (xs.min() - pad, xs.max() + pad), (ys.min() - pad, ys.max() + pad)
    height = float(np.clip(4.0 * np.ptp(ylim) / np.ptp(xlim), 2.0, 6.0)) + 1.0  # titles and x label: 1 inch
    fig, axes = plt.subplots(1, len(panels), figsize=(4.6 * len(panels), height), layout="constrained",
                             squeeze=False, sharex=True, sharey=True)  # fmt: skip
    length, variance = _label(solution, length=1), _label(solution, state=2)
    from matplotlib import patheffects

    outline = [patheffects.withStroke(linewidth=3.2, foreground="k")]  # white paths stay visible off the grid too
    for ax, (title, values, paths) in zip(axes[0], panels, strict=True):
        ax.set_facecolor("0.85")  # outside the grid: no map there
        mesh = ax.pcolormesh(xe, ye, field.to_grid(values), vmin=0.0, vmax=vmax, cmap="viridis", shading="flat")
        ax.plot(*field.locations.T, "k.", ms=2, alpha=0.5)
        draw_constraints(ax, solution.problem.constraints)
        for i, sensor in enumerate(solution.problem.sensors):
            ax.plot(p[0, i, 0], p[0, i, 1], "wo", ms=5, mec="k", zorder=3)
            if paths:
                ax.plot(p[:, i, 0], p[:, i, 1], "w-", lw=1.6, zorder=2, path_effects=outline)
                ax.plot(p[-1, i, 0], p[-1, i, 1], "w^", ms=7, mec="k", zorder=3)
                ax.annotate(sensor.name, p[-1, i], color="w", fontsize=8, xytext=(4, 4), textcoords="offset points",
                            path_effects=outline)  # fmt: skip
        ax.set(title=f"{title}\nTr Σ = {values.sum():.4g} {variance}", xlabel=f"x ({length})",
               ylabel=f"y ({length})", xlim=xlim, ylim=ylim, aspect="equal")  # fmt: skip
    fig.colorbar(mesh, ax=axes[0].tolist(), label=f"error variance diag Σ ({variance})")
    return fig


def plot_trace(solution: Solution):  # noqa: ANN201
    """Tr Σ(t) of the optimum and of the no-control baseline."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    if "trace_Sigma" in solution.baseline:
        ax.plot(solution.t, solution.baseline["trace_Sigma"], "--", color="0.35", label="no control (u ≡ 0)")
    ax.plot(solution.t, solution.variances().sum(axis=1), lw=2, label="optimal paths")
    ax.set(xlabel=f"time ({_label(solution, time=1)})", ylabel=f"Tr Σ(t) ({_label(solution, state=2)})",
           title="total error variance of the field", ylim=(0, None))  # fmt: skip
    ax.legend()
    return fig


FIELD_FIGURES = {"variance_maps.png": plot_variance_maps, "trace.png": plot_trace}
