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
restores at no risk of crossing.

The detour keeps the coasting guess's course, which may still leave the workspace or, where the zones push
two sensors together, break the separation; a sensor coasting out of a tight workspace or towards another
one is best stopped. :func:`braking_guess` stops every sensor at a constant deceleration within
:data:`BRAKING_FRACTION` of the horizon (or as fast as its ``u_max`` allows) and holds it there, with the
coasting guess's Σ. :func:`cold_start` is the hook of the cold solve (:mod:`mobisense.ocp.direct.strategy`):
the coasting guess (its detour when it enters a zone or brings sensors closer than ``min_separation``),
unless the braking guess breaks the constraints less (:func:`guess_violation`).
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from ..path_constraints import KeepOutDisc, constraint_sizes, margins
from ..problem import Problem

__all__ = [
    "BRAKING_FRACTION",
    "needs_detour",
    "separate_positions",
    "detour_positions",
    "detour_guess",
    "braking_path",
    "braking_guess",
    "guess_violation",
    "cold_start",
]

#: distance kept from a zone, relative to its size (disc radius, polygon √area)
MARGIN = 0.05
#: the braking guess stops each sensor within this fraction of the horizon, unless its u_max needs longer
BRAKING_FRACTION = 0.05


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
                side = (
                    lateral / np.linalg.norm(lateral)
                    if np.linalg.norm(lateral) > 0.01 * zone.radius
                    else _side(heading, target - c)
                )
                out[t, i] = c + along * heading + np.sqrt(max(r * r - along * along, 0.0)) * side  # fmt: skip
            continue
        V = np.asarray(zone.polygon, float)
        grow = margin * np.sqrt(zone.area)
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


def braking_path(problem: Problem, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, velocities and controls (T, N, 2) at times ``t`` (T,) of sensors braking to rest.

    Sensor i decelerates at ``−v0_i / T_i`` for ``T_i = max(BRAKING_FRACTION (tf − t0), |v0_i| / u_max_i)``
    (at most tf − t0), then holds still.
    """
    h = problem.horizon
    p0 = np.array([s.p0 for s in problem.sensors], float)
    v0 = np.array([s.v0 for s in problem.sensors], float)
    fastest = [np.linalg.norm(v0[i]) / s.u_max if s.u_max else 0.0 for i, s in enumerate(problem.sensors)]
    T = np.minimum(np.maximum(BRAKING_FRACTION * (h.tf - h.t0), fastest), h.tf - h.t0)[None, :, None]  # (1, N, 1)
    a = -v0[None] / T
    elapsed = (np.asarray(t, float) - h.t0)[:, None, None]
    tau = np.minimum(elapsed, T)
    p = p0[None] + v0[None] * tau + 0.5 * a * tau**2
    v = v0[None] + a * tau
    u = np.where(elapsed < T, a, 0.0) * np.ones_like(v)
    return p, v, u


def braking_guess(problem: Problem, tr: Any, w0: np.ndarray, P: np.ndarray) -> np.ndarray:
    """The coasting guess ``w0`` (scaled, of ``tr``) with every sensor braking to rest (:func:`braking_path`)."""
    starts = tr.unpack(w0, P)
    layout = tr.structure.state
    xs = starts["xs"].copy()
    t_starts, t_nodes = tr.times(problem.horizon.t0, problem.horizon.tf)
    p, v, _ = braking_path(problem, t_starts)
    xs[:, layout.positions] = p.reshape(len(xs), -1)
    xs[:, layout.velocities] = v.reshape(len(xs), -1)
    _, _, u = braking_path(problem, t_nodes.ravel())
    return tr.pack(xs, starts["xc"], u.reshape(starts["u"].shape), P)


def guess_violation(problem: Problem, p: np.ndarray, v: np.ndarray) -> float:
    """How far positions and velocities (T, N, 2) break the path constraints (0: all held).

    The sum over the groups of each one's largest violation relative to its size.
    """
    c = problem.constraints
    if c is None:
        return 0.0
    sizes = constraint_sizes(c)
    return sum(max(0.0, float(m.max())) / sizes[g] for g, m in margins(c, p, v).items())


def cold_start(ctx: Any) -> np.ndarray:
    """The start of a cold solve of a :class:`~mobisense.ocp.direct.strategy.SolveContext` (scaled, (nw,)).

    The coasting guess, or its detour when that enters a keep-out zone or brings sensors closer than
    ``min_separation``; the braking guess instead when it breaks the constraints less (see module notes).
    """
    problem, tr = ctx.problem, ctx.tr
    c = problem.constraints
    if c is None or not (c.keep_out or c.min_separation is not None or c.workspace is not None):
        return ctx.w0
    P = ctx.parameters(1.0)
    layout = tr.structure.state
    _, p, v = layout.split(tr.unpack(ctx.w0, P)["xs"])
    guess = ctx.w0
    if needs_detour(problem, p):
        guess = detour_guess(problem, tr, ctx.w0, P)
        _, p, v = layout.split(tr.unpack(guess, P)["xs"])
    coasting = guess_violation(problem, p, v)
    if coasting == 0.0:
        return guess
    braking = braking_guess(problem, tr, ctx.w0, P)
    _, p, v = layout.split(tr.unpack(braking, P)["xs"])
    return braking if guess_violation(problem, p, v) < coasting else guess
