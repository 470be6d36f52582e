"""Initial guesses of the direct method: the coasting (Kalman-filter) trajectory and random feasible ones.

Every guess is a scaled decision vector of :class:`~mobisense.ocp.direct.transcription.DirectCollocation`:
a trajectory sampled on the state grid (every interval start and collocation node) and controls at the
collocation nodes. :func:`random_guess` is a smooth random control ``u(t) = Σ_m a_m sin(mπ τ + φ_m)``
(τ the normalised time, amplitudes of the order of the problem's control scale) with the states it
produces (integrated with CVODES, :func:`~mobisense.ocp.simulate.sine_controlled`), so it satisfies the
dynamics and only the optimality differs (multi-start).
"""

from __future__ import annotations

import numpy as np

from ..problem import Problem
from ..simulate import Trajectory, coast, sine_controlled
from .transcription import DirectCollocation, transcription_for

__all__ = ["state_grid", "initial_guess", "coasting_baseline", "cost_scale", "coasting_start", "random_guess"]


def state_grid(tr: DirectCollocation, t0: float, tf: float) -> tuple[np.ndarray, np.ndarray]:
    """Merged state time grid (interval starts and collocation nodes, no duplicates) and its sort order."""
    starts, nodes = tr.times(t0, tf)
    t_all = np.concatenate([starts, nodes.ravel()])
    order = np.argsort(t_all, kind="stable")
    # equal up to rounding (an interval's end node and the next start): relative to the horizon, not absolute
    tol = 1e-9 * (tf - t0) / tr.intervals + 8 * np.finfo(float).eps * max(abs(t0), abs(tf))
    keep = np.concatenate([[True], np.diff(t_all[order]) > tol])
    return t_all[order][keep], order[keep]


def coasting_baseline(problem: Problem, t_eval: np.ndarray, tr: DirectCollocation | None = None) -> Trajectory:
    """The ε → 0 solution: sensors coast (u ≡ 0), Σ from the Riccati IVP — the classical Kalman filter."""
    tr = tr or transcription_for(problem)
    P = tr.layout.pack(tr.layout.values(problem))
    return coast(tr.model, P, t_eval)


def cost_scale(coasting_cost: float) -> float:
    """The cost scale c_s of the NLP objective J / c_s: the coasting cost (docs/theory/direct.md §1.3).

    It follows the cost however small (M SPD makes it > 0): an absolute floor would make tiny-cost problems
    (M = 1e-40) optimise the control energy alone; 1e-300 only keeps the division finite.
    """
    return max(abs(float(coasting_cost)), 1e-300)


def coasting_start(problem: Problem, tr: DirectCollocation, eps: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(P at ``eps``, coasting guess w0): the parameters and start of a cold solve, as :func:`solve_direct` makes them.

    The cost scale is the coasting cost (docs/theory/direct.md §1.3).
    """
    values = tr.layout.values(problem)
    t_grid, _ = state_grid(tr, problem.horizon.t0, problem.horizon.tf)
    coasting = coast(tr.model, tr.layout.pack(values), t_grid)
    values["cost_scale"] = cost_scale(coasting.cost)
    P = tr.layout.pack({**values, "eps": eps})
    return P, initial_guess(tr, coasting, P)


def initial_guess(
    tr: DirectCollocation, trajectory: Trajectory, P: np.ndarray, u: np.ndarray | None = None
) -> np.ndarray:
    """Decision vector of a trajectory sampled on the state grid (every start and node) and controls ``u``.

    ``u`` has shape (K, d, nu) (controls at the collocation nodes); ``None`` means coasting (u = 0).
    """
    K, d = tr.intervals, tr.colloc.degree
    starts, nodes = tr.times(trajectory.t[0], trajectory.t[-1])
    t_all = np.concatenate([starts, nodes.ravel()])
    tol = 1e-9 * max(1.0, abs(trajectory.t[-1] - trajectory.t[0]))
    x_all = trajectory.x[np.clip(np.searchsorted(trajectory.t, t_all - tol), 0, len(trajectory.t) - 1)]
    u = np.zeros((K, d, tr.structure.nu)) if u is None else u
    return tr.pack(x_all[: K + 1], x_all[K + 1 :].reshape(K, d, -1), u, P)


def random_guess(
    problem: Problem, seed: int, amplitude: float = 3.0, modes: int = 3, tr: DirectCollocation | None = None
) -> np.ndarray:
    """A scaled decision vector of a random smooth control and its trajectory (see module docstring).

    ``tr`` is the transcription to pack it for (default: :func:`transcription_for` of ``problem``).
    """
    tr = tr or transcription_for(problem)
    values = tr.layout.values(problem)
    P = tr.layout.pack(values)
    rng = np.random.default_rng(seed)
    u_scale = float(values["control_scale"])
    nu = tr.structure.nu
    t0, tf = problem.horizon.t0, problem.horizon.tf
    a = amplitude * u_scale * rng.standard_normal((modes, nu))
    phase = rng.uniform(0, 2 * np.pi, (modes, nu))
    m = np.arange(1, modes + 1)[:, None]
    _, nodes = tr.times(t0, tf)
    t_grid, _ = state_grid(tr, t0, tf)
    trajectory = sine_controlled(tr.model, P, t_grid, a, phase)
    tau = (nodes.ravel() - t0) / (tf - t0)
    u = (a[None] * np.sin(m[None] * np.pi * tau[:, None, None] + phase[None])).sum(axis=1)
    u = u.reshape(tr.intervals, tr.colloc.degree, nu)
    # the scaling of w does not depend on cost_scale (set inside solve_direct), so this P packs it correctly
    return initial_guess(tr, trajectory, P, u)
