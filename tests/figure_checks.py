"""Checks that a rendered matplotlib figure tells its reader what it shows.

:func:`figure_problems` lists, for a drawn figure:

* axes without an x (y) label on themselves or on an axes sharing their x (y) axis;
* colour bars without a label;
* legend entries whose artist shows nothing: a line or marker with data but no finite point inside the
  axes limits (an empty line is a legend proxy for a contour or collection), or one entirely covered by
  an artist drawn over it (a later solid, mostly opaque line at least as wide passing within half its
  width of every point, or a later filled marker at least half as large at the same place).

Distances are measured in display pixels after drawing, so a curve hidden under another curve of the
same data is found whatever the data's scale.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def _points(line: Any) -> np.ndarray:
    xy = np.column_stack([np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)])
    xy = xy[np.all(np.isfinite(xy), axis=1)]
    return line.axes.transData.transform(xy) if len(xy) else xy


def _inside(ax: Any, pixels: np.ndarray) -> np.ndarray:
    box = ax.get_window_extent()
    return (pixels[:, 0] >= box.x0 - 1) & (pixels[:, 0] <= box.x1 + 1) & (pixels[:, 1] >= box.y0 - 1) & (
        pixels[:, 1] <= box.y1 + 1
    )


def _distance_to_polyline(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """Distance of each point to the nearest segment of ``polyline`` (pixels)."""
    if len(polyline) == 1:
        return np.linalg.norm(points - polyline[0], axis=1)
    a, b = polyline[:-1][None], polyline[1:][None]
    ab = b - a
    t = np.clip(np.sum((points[:, None] - a) * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-12), 0, 1)
    nearest = a + t[..., None] * ab
    return np.linalg.norm(points[:, None] - nearest, axis=-1).min(axis=1)


def _covered(line: Any, others: list[Any], dpi: float) -> bool:
    pixels = _points(line)
    if not len(pixels):
        return False
    has_line = line.get_linestyle() not in ("None", "", " ") and line.get_linewidth() > 0
    marker = line.get_marker() not in (None, "None", "", " ")
    for other in others:
        if not other.get_visible():
            continue
        theirs = _points(other)
        if not len(theirs):
            continue
        if has_line:
            solid = other.get_linestyle() in ("-", "solid")  # dashes and dots leave gaps: they hide nothing
            opaque = other.get_alpha() is None or other.get_alpha() >= 0.5
            width = other.get_linewidth() * dpi / 72 if solid and opaque else 0.0
            if width >= line.get_linewidth() * dpi / 72 and np.all(_distance_to_polyline(pixels, theirs) <= width / 2):
                return True
        elif marker:
            filled = other.get_markerfacecolor() not in ("none", "None") and other.get_marker() not in ("None", "")
            if filled and other.get_markersize() >= 0.5 * line.get_markersize():  # its centre is gone
                gap = np.linalg.norm(pixels[:, None] - theirs[None], axis=-1).min(axis=1)
                if np.all(gap <= 0.5 * line.get_markersize() * dpi / 72 * 0.5):
                    return True
    return False


def _drawn_after(ax: Any, artist: Any) -> list[Any]:
    lines = list(ax.get_lines())
    index = lines.index(artist)
    z = artist.get_zorder()
    later = [o.get_zorder() > z or (o.get_zorder() == z and i > index) for i, o in enumerate(lines)]
    return [o for o, after in zip(lines, later, strict=True) if o is not artist and after]


def _legend_artists(ax: Any) -> list[tuple[str, Any]]:
    legend = ax.get_legend()
    if legend is None:
        return []
    labelled = {}
    for artist in ax.get_lines():
        labelled.setdefault(artist.get_label(), artist)
    return [(text.get_text(), labelled.get(text.get_text())) for text in legend.get_texts()]


def figure_problems(fig: Any) -> list[str]:
    """Everything :mod:`figure_checks` finds wrong with ``fig`` (empty when it is fine); draws the figure."""
    fig.canvas.draw()
    dpi = fig.dpi
    problems = []
    colorbar_axes = {id(ax) for ax in fig.axes if getattr(ax, "_colorbar", None) is not None}
    for number, ax in enumerate(fig.axes):
        name = f"axes {number} ({ax.get_title() or 'untitled'})"
        if not ax.get_visible() or not ax.axison:
            continue
        if id(ax) in colorbar_axes:
            if not (ax.get_ylabel() or ax.get_xlabel()):
                problems.append(f"{name}: colour bar without a label")
            continue
        if not any(s.get_ylabel() for s in ax.get_shared_y_axes().get_siblings(ax)):
            problems.append(f"{name}: no y label")
        siblings = ax.get_shared_x_axes().get_siblings(ax)
        if not any(s.get_xlabel() for s in siblings):
            problems.append(f"{name}: no x label")
        for label, artist in _legend_artists(ax):
            if artist is None or len(artist.get_xdata()) == 0:
                continue  # a patch, a collection (band, bar) or an empty proxy line standing for a contour
            pixels = _points(artist)
            if not len(pixels) or not _inside(ax, pixels).any():
                problems.append(f"{name}: legend entry {label!r} has no point inside the axes")
            elif _covered(artist, _drawn_after(ax, artist), dpi):
                problems.append(f"{name}: legend entry {label!r} is hidden under another artist")
    return problems
