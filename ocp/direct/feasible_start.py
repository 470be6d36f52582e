"""A start outside the keep-out zones and apart by min_separation (docs/theory/path_constraints.md §2.1).

The coasting guess of a cold solve may run through a zone; a path that crosses a disc head-on is the worst
case: at the disc's centre the constraint's gradient vanishes, and Ipopt's restoration phase picks a side
by accident. :func:`detour_guess` moves every position of the coasting guess that lies in a zone (or
within ``margin`` × its size of it) onto the zone's grown boundary: for a disc sideways from the sensor's
heading onto the arc on the side the path passes the centre (an arc around the disc; a path within 1 %
of the radius from the centre takes the side of the process locations' mean — where the sensor heads for
anyway — or the left side when that is straight ahead), for a polygon along the nearest edge's outward
normal. Σ, the velocities and the controls
stay those of the coasting guess, so the start satisfies the zones but not the dynamics, which Ipopt
restores at no risk of crossing. :func:`cold_start` is the hook of the cold solve
(:mod:`mobisense.ocp.direct.strategy`): the detour when the coasting guess enters a zone, else the coasting
guess itself.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from ..path_constraints import KeepOutDisc, margins
from ..problem import Problem

__all__ = ["needs_detour", "separate_positions", "detour_positions", "detour_guess", "cold_start"]

#: distance kept from a zone, relative to its size (disc radius, polygon √area)
MARGIN = 0.05


def needs_detour(problem: Problem, p: np.ndarray) -> bool:
    """True when positions ``p`` (T, N, 2) enter a keep-out zone or come closer than ``min_separation``."""
    c = problem.constraints
    if c is None or not (c.keep_out or c.min_separation is not None):
        return False
    zero = np.zeros_like(p)
    moved = ("keep_out", "min_separation")
    return any(np.max(v) > 0 for k, v in margins(c, p, zero).items() if k.startswith(moved))


def separate_positions(problem: Problem, p: np.ndarray, v: np.ndarray, margin: float = MARGIN) -> np.ndarray:
    """Positions ``p`` (T, N, 2) of sensors closer than ``min_separation`` × (1 + margin) pushed apart.

    Each such pair is moved apart symmetrically along the line joining it, by half the deficit each; a pair
    at the same point (the separation's gradient vanishes there, as a disc's at its centre) is split across
    the mean heading of the two, ``v`` (T, N, 2). A few sweeps over the pairs settle three or more sensors.
    """
    out = np.array(p, float)
    c = problem.constraints
    if c is None or c.min_separation is None or out.shape[1] < 2:
        return out
    d = c.min_separation * (1 + margin)
    pairs = list(itertools.combinations(range(out.shape[1]), 2))
    for _ in range(8):
        moved = False
        for i, j in pairs:  # every time of one pair at once: the times do not interact
            gap = out[:, i] - out[:, j]
            dist = np.linalg.norm(gap, axis=1)
            close = dist < d
            if not close.any():
                continue
            heading = v[:, i] + v[:, j]
            heading[np.linalg.norm(heading, axis=1) == 0] = [1.0, 0.0]
            across = np.stack([-heading[:, 1], heading[:, 0]], axis=1) / np.linalg.norm(heading, axis=1)[:, None]
            apart = dist > 1e-9 * d
            unit = np.where(apart[:, None], gap / np.where(apart, dist, 1.0)[:, None], across)
            push = 0.5 * (d - dist[close])[:, None] * unit[close]
            out[close, i] += push
            out[close, j] -= push
            moved = True
        if not moved:
            break
    return out


def _side(heading: np.ndarray, towards: np.ndarray) -> np.ndarray:
    """The unit normal of ``heading`` on the side of ``towards`` (left when straight ahead or behind)."""
    left = np.array([-heading[1], heading[0]]) / max(np.linalg.norm(heading), 1e-300)
    return left if float(left @ towards) >= 0 else -left


def detour_positions(problem: Problem, p: np.ndarray, v: np.ndarray, margin: float = MARGIN) -> np.ndarray:
    """Positions ``p`` (T, N, 2) apart and out of every keep-out zone (see module docstring); ``v`` the velocities.

    Sensors closer than ``min_separation`` are pushed apart first (:func:`separate_positions`); the zones
    have the last word.
    """
    out = separate_positions(problem, p, v, margin)  # first: the zones have the last word
    target = np.mean(np.asarray(problem.process.locations, float), axis=0)
    for zone in problem.constraints.keep_out if problem.constraints is not None else []:
        if isinstance(zone, KeepOutDisc):
            c, r = np.asarray(zone.center, float), zone.radius * (1 + margin)
            d = out - c
            for t, i in zip(*np.nonzero(np.linalg.norm(d, axis=-1) < r), strict=True):
                speed = np.linalg.norm(v[t, i])
                heading = v[t, i] / speed if speed > 0 else (target - c) / max(np.linalg.norm(target - c), 1e-300)
                along = float(d[t, i] @ heading)
                lateral = d[t, i] - along * heading
                side = lateral / np.linalg.norm(lateral) if np.linalg.norm(lateral) > 0.01 * zone.radius else \
                    _side(heading, target - c)
                out[t, i] = c + along * heading + np.sqrt(max(r * r - along * along, 0.0)) * side  # fmt: skip
            continue
        V = np.asarray(zone.polygon, float)
        a, b = V[1:-1] - V[0], V[2:] - V[0]
        grow = margin * np.sqrt(0.5 * abs(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])))  # √area
        closed = np.vstack([V, V[:1]])
        edges = closed[1:] - closed[:-1]
        normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1) * zone.orientation
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        depth = np.einsum("tnex,ex->tne", out[..., None, :] - V[None, None], normals)  # (T, N, edges)
        nearest = np.argmax(depth, axis=-1)
        inside = np.take_along_axis(depth, nearest[..., None], -1)[..., 0] < grow
        for t, i in zip(*np.nonzero(inside), strict=True):
            e = nearest[t, i]
            out[t, i] += (grow - depth[t, i, e]) * normals[e]
    return out


def detour_guess(problem: Problem, tr: Any, w0: np.ndarray, P: np.ndarray) -> np.ndarray:
    """The coasting guess ``w0`` (scaled, of ``tr``) with its positions moved out of the zones."""
    starts = tr.unpack(w0, P)
    layout = tr.structure.state
    xs, xc = starts["xs"].copy(), starts["xc"].copy()
    for x in (xs, xc):
        flat = x.reshape(-1, x.shape[-1])
        _, p, v = layout.split(flat)
        flat[:, layout.positions] = detour_positions(problem, p, v).reshape(len(flat), -1)
    return tr.pack(xs, xc, starts["u"], P)


def cold_start(ctx: Any) -> np.ndarray:
    """The start of a cold solve of a :class:`~mobisense.ocp.direct.strategy.SolveContext` (scaled, (nw,)).

    The coasting guess, or its detour when that enters a keep-out zone or brings sensors closer than
    ``min_separation``.
    """
    problem, tr = ctx.problem, ctx.tr
    c = problem.constraints
    if c is None or not (c.keep_out or c.min_separation is not None):
        return ctx.w0
    P = ctx.parameters(1.0)
    _, p, _ = tr.structure.state.split(tr.unpack(ctx.w0, P)["xs"])
    return detour_guess(problem, tr, ctx.w0, P) if needs_detour(problem, p) else ctx.w0
