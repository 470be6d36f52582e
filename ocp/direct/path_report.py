"""Activity and violation of the path constraints of a direct solution (docs/theory/path_constraints.md §3).

The NLP enforces the constraints at the collocation nodes only. :func:`resimulate_sensors` re-integrates
the sensors' double integrators exactly under the optimised control (the Lagrange polynomial through each
interval's d control nodes, integrated in closed form from the interval start of the *re-simulated*
path, so the errors of the collocation do not hide), and :func:`constraint_report` gives, for each
constraint group, whether it is active at the optimum, its largest multiplier and the largest violation
on the re-simulated path between the nodes.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.polynomial import polynomial as npoly

from ..collocation import CollocationScheme
from ..path_constraints import group_names, margins
from ..problem import Problem

__all__ = ["ACTIVE_TOLERANCE", "resimulate_sensors", "constraint_report"]

#: a group is active when a scaled row is within this of its bound at a node (Ipopt's tol is 1e-9)
ACTIVE_TOLERANCE = 1e-6


def resimulate_sensors(
    problem: Problem, u: np.ndarray, scheme: str, degree: int, per_interval: int = 20
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions and velocities of the sensors flown under the collocation control, on a fine grid.

    Parameters
    ----------
    problem : Problem
    u : ndarray, shape (K, d, N, 2)
        Controls at the collocation nodes (L/T²).
    scheme, degree : str, int
        The collocation scheme of ``u``.
    per_interval : int
        Sample times per interval (uniform in τ ∈ (0, 1]).

    Returns
    -------
    t : ndarray, shape (K·per_interval + 1,)
    p, v : ndarray, shape (T, N, 2)
    """
    K = u.shape[0]
    colloc = CollocationScheme(scheme, degree)
    tau = colloc.tau[1:]
    basis = np.linalg.inv(np.vander(tau, degree, increasing=True)).T  # row j: coefficients of ℓ_j
    I1 = [npoly.polyint(c) for c in basis]  # ∫_0^τ ℓ_j
    I2 = [npoly.polyint(c) for c in I1]  # ∫_0^τ ∫_0^s ℓ_j
    s = np.linspace(0.0, 1.0, per_interval + 1)[1:]
    W1 = np.array([npoly.polyval(s, c) for c in I1])  # (d, S)
    W2 = np.array([npoly.polyval(s, c) for c in I2])
    t0, tf = problem.horizon.t0, problem.horizon.tf
    h = (tf - t0) / K
    p = [np.asarray([sensor.p0 for sensor in problem.sensors], float)]
    v = [np.asarray([sensor.v0 for sensor in problem.sensors], float)]
    for k in range(K):
        pk, vk = p[-1], v[-1]
        v_int = vk[None] + h * np.einsum("js,jnc->snc", W1, u[k])
        p_int = pk[None] + h * s[:, None, None] * vk[None] + h**2 * np.einsum("js,jnc->snc", W2, u[k])
        p.extend(p_int)
        v.extend(v_int)
    t = t0 + h * np.concatenate([[0.0], (np.arange(K)[:, None] + s[None, :]).ravel()])
    return t, np.array(p), np.array(v)


def constraint_report(problem: Problem, tr: Any, result: Any, P: np.ndarray, u: np.ndarray) -> dict[str, Any]:
    """``{group: {active, max_violation, max_violation_at_nodes, max_multiplier, units}}`` of a direct solution.

    Parameters
    ----------
    problem : Problem
    tr : DirectCollocation
    result : NLPResult
        The converged NLP point.
    P : ndarray
        Its parameters.
    u : ndarray, shape (K, d, N, 2)
        Controls at the nodes.

    Notes
    -----
    ``max_violation`` is the largest physical violation (penetration depth (L), separation deficit (L),
    speed excess (L/T), distance outside the workspace (L); ≤ 0 means satisfied with that margin) on the
    re-simulated path; ``max_multiplier`` the largest multiplier of the group's rows in cost units per unit
    of the row's physical value (zero when inactive); ``units`` the unit of ``max_violation``, the problem's
    length (or speed) unit in UDUNITS, as in ``solution.nc``.
    """
    k, K, d = tr.kernels, tr.intervals, tr.colloc.degree
    if not k.n_cons:
        return {}
    constraints = problem.constraints
    rows = result.g[: K * k.nr].reshape(K, k.nr)[:, k.nr - k.n_cons :].reshape(K * d, -1)
    scales = tr.constraint_scales(P)[: K * k.nr].reshape(K, k.nr)[:, k.nr - k.n_cons :].reshape(K * d, -1)
    cost_scale = float(tr.layout.unpack(np.asarray(P, float))["cost_scale"][0])
    lam = result.lam_g[: K * k.nr].reshape(K, k.nr)[:, k.nr - k.n_cons :].reshape(K * d, -1)
    lam = lam * cost_scale / scales
    groups = np.array([g for g, _ in tr.model.path_labels])
    t, p, v = resimulate_sensors(problem, u, tr.colloc.scheme, d)
    violation = margins(constraints, p, v)
    _, p_nodes, v_nodes = _node_states(tr, result, P)
    at_nodes = margins(constraints, p_nodes, v_nodes)
    system = problem.units.system()  # the problem's declared units, as in solution.nc (UDUNITS)
    length, speed = system.of(length=1), system.of(length=1, time=-1)
    out: dict[str, Any] = {}
    for name in group_names(tr.structure.path):
        mask = groups == name
        worst = int(np.argmax(violation[name]))
        out[name] = {
            "active": bool(rows[:, mask].max() >= -ACTIVE_TOLERANCE),
            "max_violation": float(violation[name].max()),
            "max_violation_time": float(t[worst]),
            "max_violation_at_nodes": float(at_nodes[name].max()),
            "max_multiplier": float(np.abs(lam[:, mask]).max()),
            "units": speed if name == "max_speed" else length,
        }
    return out


def _node_states(tr: Any, result: Any, P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """States at the collocation nodes: Σ entries, p (K·d, N, 2), v (K·d, N, 2)."""
    xc = tr.unpack(result.w, P)["xc"].reshape(-1, tr.structure.nx)
    layout = tr.structure.state
    Sigma, p, v = layout.split(xc)
    return Sigma, p, v
