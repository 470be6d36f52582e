"""Initial guesses of the direct method: the coasting (Kalman-filter) trajectory and random feasible ones.

Every guess is a scaled decision vector of :class:`~mobisense.ocp.direct.transcription.DirectCollocation`:
a trajectory sampled on the state grid (every interval start and collocation node) and controls at the
collocation nodes. :func:`random_guess` is a smooth random control ``u(t) = Σ_m a_m sin(mπ τ + φ_m)``
(τ the normalised time, amplitudes of the order of the problem's control scale) with the states it
produces (integrated with ``solve_ivp``), so it satisfies the dynamics and only the optimality differs
(multi-start).
"""

from __future__ import annotations

import numpy as np

from ..problem import Problem
from ..simulate import Trajectory, coast, integrate
from .transcription import DirectCollocation, transcription_for

__all__ = ["state_grid", "initial_guess", "coasting_baseline", "random_guess"]


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


def random_guess(problem: Problem, seed: int, amplitude: float = 3.0, modes: int = 3) -> np.ndarray:
    """A scaled decision vector of a random smooth control and its trajectory (see module docstring)."""
    tr = transcription_for(problem)
    values = tr.layout.values(problem)
    P = tr.layout.pack(values)
    rng = np.random.default_rng(seed)
    u_scale = float(values["control_scale"])
    nu = tr.structure.nu
    t0, tf = problem.horizon.t0, problem.horizon.tf
    a = amplitude * u_scale * rng.standard_normal((modes, nu))
    phase = rng.uniform(0, 2 * np.pi, (modes, nu))
    m = np.arange(1, modes + 1)[:, None]

    def control(t: float) -> np.ndarray:
        tau = (t - t0) / (tf - t0)
        return (a * np.sin(m * np.pi * tau + phase)).sum(axis=0)

    _, nodes = tr.times(t0, tf)
    t_grid, _ = state_grid(tr, t0, tf)
    trajectory = integrate(tr.model, P, t_grid, control=control, rtol=1e-8)
    u = np.array([control(t) for t in nodes.ravel()]).reshape(tr.intervals, tr.colloc.degree, nu)
    # the scaling of w does not depend on cost_scale (set inside solve_direct), so this P packs it correctly
    return initial_guess(tr, trajectory, P, u)


