"""Residuals of the necessary conditions (docs/theory/indirect.md §5) along any solution, direct or indirect.

For a solution at ε = 1 with states, controls and costates λ, evaluated where all three are known
(the control times that are also state and costate times):

``dH_du``
    ``max_t |∂H/∂u| / max_t |λ_v|`` with ``H = L + λ'f``: stationarity of the Hamiltonian in u
    (at the optimum α u = −λ_v, so both terms have the size of λ_v).
``transversality``
    ``max_k |λ_k(tf) − ∂Φ/∂x_k(tf)| / max_k |∂Φ/∂x_k|`` over the free terminal components (docs/theory/indirect.md,
    eq. indirect.6: Λ(tf) = M, λ(tf) = 0), at the last costate time.
``hamiltonian_variation``
    ``(max_t H − min_t H) / (J / T)``: H is constant along an extremal of a time-invariant problem;
    J/T (cost per unit time) is its natural size.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..model import Structure
from ..solution import Solution
from .hamiltonian import hamiltonian_system

__all__ = ["optimality_residuals", "common_times"]


def common_times(solution: Solution) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Control times also present in the state and costate grids, and their indices in t_u, t, t_costate."""
    tol = 1e-9 * max(1.0, float(solution.t[-1] - solution.t[0]))

    def index_in(grid: np.ndarray, times: np.ndarray) -> np.ndarray:
        k = np.clip(np.searchsorted(grid, times - tol), 0, len(grid) - 1)
        return np.where(np.abs(grid[k] - times) <= tol, k, -1)

    i_t = index_in(solution.t, solution.t_u)
    i_c = index_in(solution.t_costate, solution.t_u)
    keep = (i_t >= 0) & (i_c >= 0)
    i_u = np.flatnonzero(keep)
    return solution.t_u[keep], i_u, i_t[keep], i_c[keep]


def optimality_residuals(solution: Solution) -> dict[str, Any]:
    """∂H/∂u, transversality and H-variation residuals of ``solution`` (see module docstring).

    Only for ε = 1 (problem II.1); an empty dict for a solution that stopped earlier, whose conditions
    depend on the method's homotopy family.
    """
    if solution.Lam is None or solution.eps != 1.0:
        return {}
    problem = solution.problem
    system = hamiltonian_system(Structure.of(problem))
    nx = system.structure.nx
    P = system.layout.pack(system.layout.values(problem, eps=1.0))
    x, lam = solution.states(), solution.costates()
    times, i_u, i_t, i_c = common_times(solution)
    xs, us, lams = x[i_t], solution.u.reshape(len(solution.t_u), -1)[i_u], lam[i_c]
    m = len(times)
    # docs/theory/indirect.md, eq. indirect.14 at ε = 1: H = L + λ'f
    # (and H̃ = H, μ = λ in mobisense.ocp.indirect.hamiltonian)
    dHdu = np.asarray(system.dHdu.map(m)(xs.T, us.T, lams.T, P)).T
    L = np.asarray(system.model.running.map(m)(xs.T, us.T, P))[0]
    f = np.asarray(system.model.f.map(m)(xs.T, us.T, P)).T
    H = L + np.sum(lams * f, axis=1)
    lam_v = lam[:, nx - system.structure.nu :]
    free = ~system.fixed_terminal
    dPhi = np.asarray(system.terminal_gradient(x[-1], P)).ravel()
    transversality = np.abs(lam[-1, free] - dPhi[free]).max() / max(np.abs(dPhi).max(), 1e-300)
    horizon = problem.horizon.tf - problem.horizon.t0
    return {
        "dH_du": float(np.abs(dHdu).max() / max(np.abs(lam_v).max(), 1e-300)),
        "transversality": float(transversality),
        "transversality_time": float(solution.t_costate[-1]),
        "hamiltonian_variation": float((H.max() - H.min()) / (abs(solution.cost) / horizon)),
        "hamiltonian_mean": float(H.mean()),
        "points": m,
    }
