"""Figures of a solution: paths over noise contours, Σ(t), u(t), and the homotopy path (cost vs ε)."""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np

from ..core.files import write_figure
from .path_constraints import draw_constraints
from .registries import NOISE_MODELS
from .solution import Solution

__all__ = ["effective_noise", "plot_paths", "plot_covariance", "plot_controls", "plot_homotopy", "save_figures"]


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


def plot_paths(solution: Solution):  # noqa: ANN201  (matplotlib Figure)
    """Sensor paths in the plane over contours of sensor 1's noise level; homotopy paths in grey."""
    import matplotlib.pyplot as plt

    problem = solution.problem
    locs = np.asarray(problem.process.locations)
    pts = np.concatenate([solution.p.reshape(-1, 2), locs])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.15 * max(float((hi - lo).max()), 1.0)
    xs = np.linspace(lo[0] - pad, hi[0] + pad, 160)
    ys = np.linspace(lo[1] - pad, hi[1] + pad, 160)
    X, Y = np.meshgrid(xs, ys)
    R = effective_noise(solution, 0, np.column_stack([X.ravel(), Y.ravel()])).reshape(X.shape)
    fig, ax = plt.subplots(figsize=(6.4, 5.6))
    cs = ax.contourf(X, Y, np.log10(R), levels=20, cmap="Blues_r", alpha=0.8)
    fig.colorbar(cs, ax=ax, label=f"log10 noise variance of sensor {problem.sensors[0].name}")
    if solution.path_p is not None and len(solution.path_eps) > 1:
        cmap = plt.get_cmap("autumn")
        for k, eps in enumerate(solution.path_eps[:-1]):
            for i in range(problem.N):
                ax.plot(*solution.path_p[k, :, i].T, color=cmap(float(eps)), lw=0.8, alpha=0.7)
        ax.plot([], [], color=cmap(0.0), lw=0.8, label="homotopy paths (ε < 1)")
    for i, sensor in enumerate(problem.sensors):
        line = ax.plot(*solution.p[:, i].T, lw=2.2, label=f"{sensor.name} (ε = {solution.eps:g})")[0]
        ax.plot(*solution.p[0, i], "o", color=line.get_color(), ms=7)
        ax.plot(*solution.p[-1, i], "s", color=line.get_color(), ms=7)
    ax.plot(*locs.T, "r*", ms=14, label="process locations")
    draw_constraints(ax, problem.constraints)
    ax.set_xlabel("x (L)")
    ax.set_ylabel("y (L)")
    ax.set_aspect("equal")
    ax.set_title(f"{problem.name}: sensor paths (o start, □ end)")
    ax.legend(loc="best", fontsize=8)
    return fig


def plot_covariance(solution: Solution):  # noqa: ANN201
    """Tr Σ(t) and the entries of Σ(t), with the coasting (classical Kalman) baseline when available."""
    import matplotlib.pyplot as plt

    n = solution.problem.n
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    ax1.semilogy(solution.t, np.trace(solution.Sigma, axis1=1, axis2=2), lw=2, label=f"optimal (ε = {solution.eps:g})")
    if solution.path_Sigma is not None and len(solution.path_eps) > 0:
        ax1.semilogy(
            solution.t,
            np.trace(solution.path_Sigma[0], axis1=1, axis2=2),
            "--",
            label=f"first homotopy step (ε = {solution.path_eps[0]:g})",
        )
    ax1.set_xlabel("t (T)")
    ax1.set_ylabel("Tr Σ(t)")
    ax1.set_title("trace of the error covariance")
    ax1.legend()
    for i in range(n):
        for j in range(i, n):
            ax2.plot(solution.t, solution.Sigma[:, i, j], label=f"Σ[{i},{j}]")
    ax2.set_yscale("symlog", linthresh=1e-2)
    ax2.set_xlabel("t (T)")
    ax2.set_title("entries of Σ(t)")
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
            ax.axhline(sensor.u_max, color=line.get_color(), lw=0.8, alpha=0.6)
    ax.set_xlabel("t (T)")
    ax.set_ylabel("u (L/T²)")
    ax.set_title("sensor controls")
    ax.legend(fontsize=8, ncol=2)
    return fig


def plot_homotopy(solution: Solution):  # noqa: ANN201
    """J_ε and Ipopt iterations along the ε continuation."""
    import matplotlib.pyplot as plt

    steps = solution.homotopy
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    ok = [s for s in steps if s.success]
    bad = [s for s in steps if not s.success]
    ax.plot([s.eps for s in ok], [s.cost for s in ok], "o-", label="J_ε (converged)")
    if bad:
        ax.plot([s.eps for s in bad], [s.cost for s in bad], "rx", ms=9, label="failed steps")
    ax.set_xlabel("ε")
    ax.set_ylabel("J_ε")
    ax.set_title("homotopy path")
    ax2 = ax.twinx()
    ax2.bar([s.eps for s in steps], [s.iterations for s in steps], width=0.02, alpha=0.3, color="grey")
    ax2.set_ylabel("Newton iterations (BVP)" if solution.method == "indirect" else "Ipopt iterations")
    ax.legend(loc="upper right")
    return fig


def save_figures(solution: Solution, folder: str | Path) -> list[Path]:
    """Write paths.png, covariance.png, controls.png and homotopy.png into ``folder``."""
    folder = Path(folder)
    figures = {
        "paths.png": plot_paths,
        "covariance.png": plot_covariance,
        "controls.png": plot_controls,
        "homotopy.png": plot_homotopy,
    }
    written = []
    for name, draw in figures.items():
        write_figure(folder / name, lambda draw=draw: draw(solution))
        written.append(folder / name)
    return written
