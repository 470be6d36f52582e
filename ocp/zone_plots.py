"""The path constraints drawn on a plane: keep-out zones hatched, the workspace dashed (path_constraints.md §1).

Shared by the figures of a collocated solution (:mod:`mobisense.ocp.plots`) and of a field's
(:mod:`mobisense.ocp.field_plots`); matplotlib is imported by the caller.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .path_constraints import KeepOutDisc, PathConstraints

__all__ = ["draw_constraints", "constraint_corners"]


def draw_constraints(ax: Any, constraints: PathConstraints | None) -> None:
    """Draw keep-out zones (hatched) and the workspace (dashed) on a matplotlib axis of the plane."""
    if constraints is None:
        return
    from matplotlib.patches import Circle, Polygon, Rectangle

    style = {"facecolor": "0.55", "edgecolor": "k", "alpha": 0.6, "hatch": "//", "zorder": 3}
    for k, zone in enumerate(constraints.keep_out):
        label = "keep-out zones" if k == 0 else None
        if isinstance(zone, KeepOutDisc):
            ax.add_patch(Circle(tuple(zone.center), zone.radius, label=label, **style))
        else:
            ax.add_patch(Polygon(np.asarray(zone.polygon), closed=True, label=label, **style))
    if constraints.workspace is not None:
        w = constraints.workspace
        ax.add_patch(
            Rectangle(
                (w.x[0], w.y[0]), w.x[1] - w.x[0], w.y[1] - w.y[0], fill=False, ls="--", ec="k", label="workspace"
            )
        )


def constraint_corners(problem: Any) -> np.ndarray:
    """Points (M, 2) that the drawn zones and workspace reach: the shaded plane covers them."""
    c = problem.constraints
    if c is None:
        return np.zeros((0, 2))
    points = []
    for zone in c.keep_out:
        if isinstance(zone, KeepOutDisc):
            points += [np.asarray(zone.center) + zone.radius * np.array(d) for d in ((-1, -1), (1, 1))]
        else:
            points += [np.asarray(v, float) for v in zone.polygon]
    if c.workspace is not None:
        points += [np.array([c.workspace.x[0], c.workspace.y[0]]), np.array([c.workspace.x[1], c.workspace.y[1]])]
    return np.array(points, float).reshape(-1, 2)
