"""Warm starts shifted in time: a solved window's primal–dual point moved onto another window's grid.

Re-planning (docs/theory/path_constraints.md §5.2) re-solves the problem on ``[t, t_e]`` from a solution on
``[t_prev, t_e,prev]``. The primal point is the previous solution's collocation polynomials (the Lagrange
polynomials through each interval's nodes, evaluated from the NLP point itself) at the new grid's interval
starts and nodes, held at their last value past the previous window's end, with zero control there. The multipliers are
moved interval by interval: each new interval takes the
physical multipliers (``μ = ν cost_scale / s_g``, eq. direct.8) of the previous interval containing its
midpoint — the collocation and continuity multipliers approximate costates (eq. direct.6), functions of
time, and the inequality rows' scale with the interval length, which the re-plans keep (their grids
have the problem's spacing). Terminal rows keep their multipliers when both NLPs have them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .transcription import DirectCollocation

__all__ = ["shifted_point"]


def _per_interval_w(tr: DirectCollocation) -> np.ndarray:
    """Indices of ``w`` interval by interval (K, nz + nn) (the eliminated layout stores nothing else)."""
    return np.hstack([tr.maps.z, tr.maps.nxt])


def _polynomials(
    tr: DirectCollocation, w: np.ndarray, P: np.ndarray, window: tuple[float, float], times: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """States (T, nx) and controls (T, nu) of the NLP point ``w`` on ``window`` at ``times`` (clipped to it)."""
    parts = tr.unpack(w, P)
    nodes = np.concatenate([parts["xs"][:-1, None, :], parts["xc"]], axis=1)  # (K, d + 1, nx)
    return tr.colloc.evaluate(np.clip(times, *window), *window, nodes, parts["u"])


def _source_intervals(t_old: tuple[float, float], k_old: int, t_new: tuple[float, float], k_new: int) -> np.ndarray:
    """For each new interval, the old interval containing its midpoint (clipped to the old window)."""
    h_new = (t_new[1] - t_new[0]) / k_new
    mid = t_new[0] + h_new * (np.arange(k_new) + 0.5)
    h_old = (t_old[1] - t_old[0]) / k_old
    return np.clip(np.floor((mid - t_old[0]) / h_old).astype(int), 0, k_old - 1)


def shifted_point(
    previous: Any, tr_old: DirectCollocation, tr_new: DirectCollocation, P_new: np.ndarray, window: tuple[float, float]
) -> dict[str, Any]:
    """The primal–dual point of ``previous`` (a solved direct Solution on ``tr_old``) on ``tr_new``'s grid.

    Parameters
    ----------
    previous : Solution
        Converged (ε = 1) solution of the previous window, with its ``nlp`` point.
    tr_old, tr_new : DirectCollocation
        Its transcription and the new window's (same structure apart from the terminal constraints).
    P_new : ndarray
        Parameters of the new window's NLP (any ``cost_scale``: :func:`solve_direct` re-scales from it).
    window : (float, float)
        The new window ``(t, t_e)`` (T).

    Returns
    -------
    dict
        ``w, lam_w, lam_g, P, signature``, the ``init`` of :func:`~mobisense.ocp.direct.solver.solve_direct`.
    """
    nlp = previous.nlp
    P_old = np.asarray(nlp["P"], float)
    t_old = (float(previous.t[0]), float(previous.t[-1]))
    # primal: the previous polynomials on the new interval starts and collocation nodes
    starts, nodes = tr_new.times(*window)
    times = np.concatenate([starts, nodes.ravel()])
    x, u = _polynomials(tr_old, np.asarray(nlp["w"], float), P_old, t_old, times)
    u[times > t_old[1]] = 0.0  # past the previous window: its end state held (coasting on measured no better)
    K, d = tr_new.intervals, tr_new.colloc.degree
    w = tr_new.pack(x[: K + 1], x[K + 1 :].reshape(K, d, -1), u[K + 1 :].reshape(K, d, -1), P_new)
    # duals: physical multipliers of the old interval under each new interval's midpoint
    src = _source_intervals(t_old, tr_old.intervals, window, K)
    cs_old = float(tr_old.layout.unpack(P_old)["cost_scale"][0])
    cs_new = float(tr_new.layout.unpack(np.asarray(P_new, float))["cost_scale"][0])
    mu = np.asarray(nlp["lam_g"], float) * cs_old / tr_old.constraint_scales(P_old)
    nr_old, nr_new = tr_old.kernels.nr, tr_new.kernels.nr
    if nr_old != nr_new:
        raise ValueError(f"interval rows differ ({nr_old} vs {nr_new}): not the same problem structure")
    rows = mu[: tr_old.intervals * nr_old].reshape(tr_old.intervals, nr_old)[src].ravel()
    terminal_old, terminal_new = mu[tr_old.intervals * nr_old :], tr_new.ng - K * nr_new
    terminal = terminal_old if terminal_old.size == terminal_new else np.zeros(terminal_new)
    lam_g = np.concatenate([rows, terminal]) * tr_new.constraint_scales(P_new) / cs_new
    idx_old, idx_new = _per_interval_w(tr_old), _per_interval_w(tr_new)
    zeta = np.asarray(nlp["lam_w"], float) * cs_old / tr_old.variable_scales(P_old)
    lam_w = np.zeros(tr_new.nw)
    lam_w[idx_new] = zeta[idx_old[src]]
    lam_w *= tr_new.variable_scales(P_new) / cs_new
    return {"w": w, "lam_w": lam_w, "lam_g": lam_g, "P": np.asarray(P_new, float), "signature": repr(tr_new.signature)}
