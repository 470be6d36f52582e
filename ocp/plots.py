"""Figures of a solution: paths, Σ(t) against the no-control baseline, u(t), the homotopy and the continuation.

``paths.png`` (paths over the noise level, homotopy paths coloured by ε), ``covariance.png``,
``controls.png``, ``homotopy.png`` (J_ε and iterations per ε step of each start) and, when the indirect method ran,
``continuation.png`` (the arclength continuation in ε with its folds).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from ..core.files import write_figure
from .registries import NOISE_MODELS
from .solution import Solution
from .zone_plots import constraint_corners, draw_constraints

__all__ = [
    "FIGURES",
    "effective_noise",
    "coasting_covariance",
    "draw_constraints",
    "plot_paths",
    "plot_covariance",
    "plot_controls",
    "plot_homotopy",
    "plot_continuation",
    "figures_of",
    "figure_names",
    "save_figures",
]


def effective_noise(solution: Solution, sensor: int, points: np.ndarray) -> np.ndarray:
    """Effective variance ``1 / Σ_k 1/r_k(p)`` of one sensor's rows at positions ``points`` (M, 2)."""
    problem = solution.problem
    model = NOISE_MODELS[problem.sensors[sensor].noise.model]
    theta = np.asarray(problem.sensors[sensor].noise.parameters(), float)
    p = ca.SX.sym("p", 2)
    info = 0
    for loc in problem.row_locations(sensor):
        info += 1.0 / model.variance(p, ca.DM(loc), ca.DM(theta))
    f = ca.Function("info", [p], [info]).map(points.shape[0])
    return 1.0 / np.asarray(f(points.T)).ravel()


def _label(solution: Solution, **powers: int) -> str:
    return solution.problem.units.system().label(**powers)


def plot_paths(solution: Solution):  # noqa: ANN201  (matplotlib Figure)
    """Sensor paths over contours of the first sensor's noise level; the homotopy paths coloured by ε."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import Normalize

    problem = solution.problem
    length = _label(solution, length=1)
    locs = problem.matrices()["locations"]
    pts = np.concatenate([solution.p.reshape(-1, 2), locs, constraint_corners(problem)])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.15 * max(float((hi - lo).max()), 1.0)
    xs = np.linspace(lo[0] - pad, hi[0] + pad, 160)
    ys = np.linspace(lo[1] - pad, hi[1] + pad, 160)
    X, Y = np.meshgrid(xs, ys)
    R = effective_noise(solution, 0, np.column_stack([X.ravel(), Y.ravel()])).reshape(X.shape)
    fig, ax = plt.subplots(figsize=(6.8, 6.4))
    cs = ax.contourf(X, Y, np.log10(R), levels=20, cmap="Blues_r", alpha=0.8)
    fig.colorbar(cs, ax=ax, label=f"log10 of the noise variance of sensor {problem.sensors[0].name}")
    # the process locations go under everything, so that a sensor ending on one stays visible
    ax.plot(*locs.T, "*", color="red", mec="darkred", ms=10, label="process locations", zorder=2)
    if solution.path_p is not None and len(solution.path_eps) > 1:
        cmap, norm = plt.get_cmap("autumn"), Normalize(0.0, 1.0)
        for k, eps in enumerate(solution.path_eps[:-1]):
            for i in range(problem.N):
                ax.plot(*solution.path_p[k, :, i].T, color=cmap(norm(float(eps))), lw=0.8, alpha=0.8, zorder=3)
        key = fig.colorbar(plt.cm.ScalarMappable(norm, cmap), ax=ax, orientation="horizontal", pad=0.12,
                           fraction=0.05, aspect=40)  # fmt: skip
        key.set_label("ε of the homotopy paths (thin lines; the thick line is ε = 1)")
    for i, sensor in enumerate(problem.sensors):
        line = ax.plot(*solution.p[:, i].T, lw=2.2, label=f"{sensor.name} (ε = {solution.eps:g})", zorder=4)[0]
        colour = line.get_color()
        ax.plot(*solution.p[0, i], "o", color=colour, mec="k", ms=8, zorder=5, label="start" if i == 0 else None)
        ax.plot(*solution.p[-1, i], "s", mfc="none", mec=colour, mew=2.2, ms=13, zorder=6,
                label="end" if i == 0 else None)  # hollow: a process location under it stays visible  # fmt: skip
    draw_constraints(ax, problem.constraints)
    ax.set_xlabel(f"x ({length})")
    ax.set_ylabel(f"y ({length})")
    ax.set_aspect("equal")
    ax.set_title(f"{problem.name}: optimal sensor paths")
    ax.legend(loc="best", fontsize=8)
    return fig


def coasting_covariance(solution: Solution) -> np.ndarray:
    """Σ(t) of the no-control baseline (sensors coasting, u ≡ 0: the classical Kalman filter) on ``solution.t``."""
    from .model import SensorKalmanModel, Structure
    from .simulate import coast

    model = SensorKalmanModel(Structure.of(solution.problem))
    P = model.layout.pack(model.layout.values(solution.problem))
    x = coast(model, P, solution.t).x
    return solution.layout.split(x)[0]


def plot_covariance(solution: Solution):  # noqa: ANN201
    """Tr Σ(t) of the optimum and of the no-control baseline; the entries of Σ(t) when n > 1."""
    import matplotlib.pyplot as plt

    n = solution.problem.n
    time, variance = _label(solution, time=1), _label(solution, state=2)
    baseline = coasting_covariance(solution)
    feasible = solution.baseline_feasible
    fig, axes = plt.subplots(1, 2 if n > 1 else 1, figsize=(11, 4.2) if n > 1 else (6.4, 4.2), squeeze=False)
    ax1 = axes[0, 0]
    ax1.semilogy(solution.t, np.trace(baseline, axis1=1, axis2=2), "--", color="0.35", lw=1.6,
                 label="no control (u ≡ 0)" + ("" if feasible else ", violates the terminal constraints"))  # fmt: skip
    ax1.semilogy(solution.t, np.trace(solution.Sigma, axis1=1, axis2=2), lw=2, label=f"optimal (ε = {solution.eps:g})")
    ax1.set_xlabel(f"time ({time})")
    ax1.set_ylabel(f"trace of Σ(t) ({variance})" if n > 1 else f"Σ(t) ({variance})")
    ax1.set_title("estimation error covariance" + (": trace" if n > 1 else ""))
    ax1.legend(fontsize=8)
    if n > 1:
        ax2 = axes[0, 1]
        for i in range(n):
            for j in range(i, n):
                ax2.plot(solution.t, solution.Sigma[:, i, j], label=f"Σ[{i},{j}]")
        ax2.set_yscale("symlog", linthresh=1e-2)
        ax2.set_xlabel(f"time ({time})")
        ax2.set_ylabel(f"entry of Σ(t) ({variance})")
        ax2.set_title("entries of Σ(t), optimal")
        ax2.legend(fontsize=8, ncol=max(1, n // 2))
    fig.tight_layout()
    return fig


def plot_controls(solution: Solution):  # noqa: ANN201
    """Control components and norm of each sensor vs time."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for i, sensor in enumerate(solution.problem.sensors):
        line = ax.plot(solution.t_u, np.linalg.norm(solution.u[:, i], axis=1), lw=2, label=f"|u| {sensor.name}")[0]
        ax.plot(solution.t_u, solution.u[:, i, 0], ":", color=line.get_color(), label=f"u_x {sensor.name}")
        ax.plot(solution.t_u, solution.u[:, i, 1], "--", color=line.get_color(), label=f"u_y {sensor.name}")
        if sensor.u_max is not None:
            ax.axhline(sensor.u_max, color=line.get_color(), lw=0.8, alpha=0.6, label=f"bound on |u| {sensor.name}")
    ax.set_xlabel(f"time ({_label(solution, time=1)})")
    ax.set_ylabel(f"acceleration u ({_label(solution, length=1, time=-2)})")
    ax.set_title("sensor controls (accelerations)")
    ax.legend(fontsize=8, ncol=2)
    return fig


def plot_homotopy(solution: Solution):  # noqa: ANN201
    """J_ε and the solver iterations of every step, one series per start (cold, random starts, the continuation).

    When no start stepped in ε (strategy ``auto`` whose starts agreed at ε = 1), the starts side by side: each
    one's J at ε = 1 and its iterations, the kept one marked. A continuation stopped by its iteration budget
    (``solver.homotopy.budget``) ends in a square, not a cross: it did not fail, it was not allowed to go on.
    """
    import matplotlib.pyplot as plt

    steps = solution.homotopy
    by_start: dict[str, list[Any]] = {}  # in the order the starts ran
    for step in steps:  # an indirect or shooting continuation has no start label: the method names it
        by_start.setdefault(step.start or solution.method, []).append(step)
    starts = list(by_start)
    kept = (solution.stats.get("strategy") or {}).get("kept")
    iterations = "Newton iterations (BVP)" if solution.method == "indirect" else "Ipopt iterations"
    fig, ax = plt.subplots(figsize=(6.8, 4.2))
    ax2 = ax.twinx()
    ax.set_zorder(ax2.get_zorder() + 1)
    ax.patch.set_visible(False)
    ax.ticklabel_format(axis="y", useOffset=False)
    if not any(s.eps < 1.0 for s in steps):  # no continuation: the starts at ε = 1 side by side
        x = np.arange(len(starts))
        ax2.bar(x, [sum(s.iterations for s in by_start[n]) for n in starts], width=0.5, alpha=0.3, color="grey")
        for i, name in enumerate(starts):
            ok = [s.cost for s in by_start[name] if s.success]
            if ok:
                ax.plot(i, ok[-1], "*" if name == kept else "o", ms=14 if name == kept else 8, color="tab:blue")
            else:
                ax.plot(i, by_start[name][-1].cost, "rx", ms=9)
        title = "starts of the solve at ε = 1 (no continuation ran)"
        costs = np.array([s.cost for s in steps if np.isfinite(s.cost)])
        if costs.size:  # starts that agree to round-off would fill the axis with their last digits
            middle, half = 0.5 * (costs.max() + costs.min()), 0.5 * np.ptp(costs)
            half = max(1.2 * half, 1e-6 * abs(middle), 1e-300)
            ax.set_ylim(middle - half, middle + half)
            title += f"\ntheir J {np.ptp(costs) / max(abs(middle), 1e-300):.1e} relative apart"
        ax.set_xticks(x, [f"{n}{' (kept)' if n == kept else ''}" for n in starts], rotation=20, fontsize=8)
        ax.set_xlabel("start (solver.strategy)")
        ax.set_ylabel("J at ε = 1 (blue; red ×: not converged)")
        ax2.set_ylabel(f"{iterations} of the start (grey bars)")
        ax.set_title(title, fontsize=10)
        return fig
    width = 0.8 * min([0.02, *np.diff(sorted({s.eps for s in steps}))]) / max(len(starts), 1)
    for k, name in enumerate(starts):
        run = by_start[name]
        ax2.bar([s.eps + (k - (len(starts) - 1) / 2) * width for s in run], [s.iterations for s in run],
                width=width, alpha=0.3, color=f"C{k}")  # fmt: skip
        ok = [s for s in run if s.success]
        tag = f"{name}{' (kept)' if name == kept else ''}"
        if ok:
            ax.plot([s.eps for s in ok], [s.cost for s in ok], "o-" if len(ok) > 1 else "o", color=f"C{k}",
                    label=f"{tag}: J_ε of its converged steps")  # fmt: skip
        stopped = [s for s in run if not s.success and s.status == "User_Requested_Stop"]
        failed = [s for s in run if not s.success and s.status != "User_Requested_Stop"]
        if stopped:
            ax.plot([s.eps for s in stopped], [s.cost for s in stopped], "s", mfc="none", mec=f"C{k}", ms=9,
                    label=f"{name}: stopped, iteration budget spent")  # fmt: skip
        if failed:
            ax.plot([s.eps for s in failed], [s.cost for s in failed], "x", color="red", ms=9,
                    label=f"{name}: failed steps")  # fmt: skip
    ax2.set_ylabel(f"{iterations} of the step (bars)")
    ax.set_xlabel("ε (homotopy parameter; 1: the original problem)")
    ax.set_ylabel("cost J_ε")
    ax.set_title("homotopy path" + (" of each start" if len(starts) > 1 else f" ({starts[0]})"))
    ax.legend(loc="upper right", fontsize=8)
    return fig


def plot_continuation(solution: Solution):  # noqa: ANN201
    """The indirect method's arclength continuation: Tr Σ(tf) against ε on the solution curve, with its folds.

    Plain stepping in ε stops at a fold (dε/ds changes sign); the arclength continuation follows the curve
    around it. ``None`` when the solution has no indirect continuation record.
    """
    import matplotlib.pyplot as plt

    indirect = solution.stats.get("indirect") or {}
    curve = indirect.get("curve") or {}
    eps, trace = np.asarray(curve.get("eps", []), float), np.asarray(curve.get("trace_sigma_tf", []), float)
    if eps.size < 2:
        return None
    fig, ax = plt.subplots(figsize=(6.8, 4.4))
    ax.plot(eps, trace, "-", color="tab:blue", lw=1.4, label="solution curve (arclength steps)")
    ax.plot(eps, trace, ".", color="tab:blue", ms=4)
    turns = np.flatnonzero(np.diff(np.sign(np.diff(eps))) != 0) + 1
    if turns.size:
        ax.plot(eps[turns], trace[turns], "o", mfc="none", mec="tab:red", mew=1.8, ms=10, zorder=5,
                label="folds: " + ", ".join(f"ε ≈ {f:.3g}" for f in indirect.get("folds", eps[turns])))  # fmt: skip
    ax.set_xscale("log")
    ax.set_xlabel("ε (log scale)")
    ax.set_ylabel(f"trace of Σ(tf) ({_label(solution, state=2)})")
    ax.set_title(f"{solution.problem.name}: continuation of the PMP boundary-value problem in ε")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    return fig


#: file name -> figure of a solution (``None`` when it does not apply)
FIGURES = {
    "paths.png": plot_paths,
    "covariance.png": plot_covariance,
    "controls.png": plot_controls,
    "homotopy.png": plot_homotopy,
    "continuation.png": plot_continuation,
}


def figures_of(solution: Solution) -> dict[str, Any]:
    """File name -> drawing function of every figure of a solution (field problems have their own)."""
    if solution.problem.process.field is not None:  # maps of diag Σ instead of Σ's n² entries
        from .field_plots import FIELD_FIGURES

        return {**FIELD_FIGURES, "controls.png": plot_controls, "homotopy.png": plot_homotopy}
    return FIGURES


def figure_names(field: bool) -> list[str]:
    """The names ``--plot`` accepts (file names without ``.png``) for a field problem or another one."""
    from .field_plots import FIELD_FIGURES

    names = [*FIELD_FIGURES, "controls.png", "homotopy.png"] if field else list(FIGURES)
    return [name.removesuffix(".png") for name in names]


def save_figures(solution: Solution, folder: str | Path, names: Sequence[str] | None = None) -> list[Path]:
    """Write paths.png, covariance.png, controls.png, homotopy.png (and continuation.png) into ``folder``.

    For a field problem: variance_maps.png and trace.png (:mod:`mobisense.ocp.field_plots`), controls.png,
    homotopy.png. ``names`` (file names without ``.png``, see :func:`figure_names`) selects some of them;
    a figure that does not apply (continuation.png without an indirect continuation) is not written.
    """
    folder = Path(folder)
    written = []
    figures = figures_of(solution)
    if names is not None:
        unknown = sorted(set(names) - {name.removesuffix(".png") for name in figures})
        if unknown:
            raise ValueError(f"no figure named {', '.join(unknown)} (expected some of {', '.join(figures)})")
        figures = {name: draw for name, draw in figures.items() if name.removesuffix(".png") in names}
    for name, draw in figures.items():
        figure = draw(solution)
        if figure is not None:
            write_figure(folder / name, lambda figure=figure: figure)  # saves and closes it
            written.append(folder / name)
    return written
