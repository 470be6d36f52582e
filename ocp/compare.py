"""Solve a problem both ways — direct collocation and the indirect (PMP) method — and measure the agreement.

``solve_both(problem)`` runs :func:`mobisense.ocp.direct.solver.solve_direct`, the indirect ε-continuation from the
Kalman solution (:func:`mobisense.ocp.indirect.solver.indirect_continuation`), and the direct-seeded refinement (the
BVP at ε = 1 started from the direct states and multiplier costates,
:func:`mobisense.ocp.indirect.solver.refine_from_direct`). It returns the direct solution as a
:class:`ComparedSolution` whose ``stats`` carry

- ``indirect``: cost pieces, status, time, nodes and homotopy record of the continuation;
- ``seeded``: the same for the direct-seeded refinement, with its own ``agreement``;
- ``agreement``: direct vs indirect continuation (see :func:`agreement`);
- ``optimality``: residuals of the necessary conditions of every solution (:mod:`mobisense.ocp.indirect.residuals`);

and whose ``indirect`` attribute (saved as ``indirect_*`` variables of solution.nc) is the indirect solution.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..core.netcdf_writer import DatasetContent
from .direct.solver import solve_direct
from .indirect.bvp_solvers import BVPSolution
from .indirect.hamiltonian import hamiltonian_system
from .indirect.residuals import optimality_residuals
from .indirect.solver import indirect_continuation, refine_from_direct, solution_from_bvp
from .model import Structure
from .problem import Problem
from .solution import HomotopyStep, Solution

__all__ = ["ComparedSolution", "agreement", "solve_both"]


def _group_difference(reference: np.ndarray, other: np.ndarray, groups: dict[str, slice]) -> dict[str, float]:
    """Largest |other − reference| / max |reference| per group of columns (0/0 -> absolute difference)."""
    out = {}
    for name, cols in groups.items():
        peak = float(np.abs(reference[:, cols]).max())
        diff = float(np.abs(other[:, cols] - reference[:, cols]).max())
        out[name] = diff / peak if peak > 0 else diff
    return out


def agreement(direct: Solution, indirect: BVPSolution) -> dict[str, Any]:
    """How well a BVP solution reproduces a direct solution, on the direct solution's grids.

    Parameters
    ----------
    direct : Solution
        Reference (states on ``t``, controls on ``t_u``, multiplier costates on ``t_costate``).
    indirect : BVPSolution
        Evaluated densely at those times.

    Returns
    -------
    dict
        ``cost_rel_diff`` = |J_ind − J_dir| / |J_dir|; ``max_state_diff``, ``max_control_diff``,
        ``max_costate_diff``: the largest difference relative to the peak of its group (Σ, p, v; u;
        Λ (matrix costate), λ_p, λ_v), each group given in ``details``.
    """
    problem = direct.problem
    system = hamiltonian_system(Structure.of(problem))
    layout = system.structure.state
    nx = layout.nx
    P = system.layout.pack({**system.layout.values(problem), "eps": indirect.eps})
    x_dir, lam_dir = direct.states(), direct.costates()
    x_ind = indirect.evaluate(direct.t)[:nx].T
    y_u = indirect.evaluate(direct.t_u)
    u_ind = np.asarray(system.control.map(direct.t_u.size)(y_u[:nx], y_u[nx:], P)).T
    lam_ind = indirect.evaluate(direct.t_costate)[nx:].T / indirect.eps

    def with_matrix_costate(lam: np.ndarray) -> np.ndarray:
        """Columns [Λ (n·n), λ_p (2N), λ_v (2N)] so the Σ costate is compared as the matrix Λ."""
        Lam, lam_p, lam_v = layout.split_costate(lam)
        return np.column_stack([Lam.reshape(len(lam), -1), lam_p.reshape(len(lam), -1), lam_v.reshape(len(lam), -1)])

    n2, N2 = layout.n**2, layout.nu
    state_groups = layout.groups
    costate_groups = {"Lam": slice(0, n2), "lam_p": slice(n2, n2 + N2), "lam_v": slice(n2 + N2, None)}
    states = _group_difference(x_dir, x_ind, state_groups)
    controls = _group_difference(direct.u.reshape(len(direct.t_u), -1), u_ind, {"u": slice(None)})
    costates = _group_difference(with_matrix_costate(lam_dir), with_matrix_costate(lam_ind), costate_groups)
    cost_ind = indirect.terminal_cost + indirect.running_cost
    return {
        "cost_rel_diff": abs(cost_ind - direct.cost) / abs(direct.cost),
        "max_state_diff": max(states.values()),
        "max_control_diff": controls["u"],
        "max_costate_diff": max(costates.values()),
        "details": {**states, **controls, **costates},
    }


@dataclass
class ComparedSolution(Solution):
    """The direct solution of a ``both`` solve, carrying the indirect solution alongside."""

    indirect: Solution | None = None

    def to_content(self) -> DatasetContent:
        """The direct solution's content plus ``indirect_*`` variables on their own ``time_indirect`` axis."""
        content = super().to_content()
        other = self.indirect
        if other is None:
            return content
        from .solution_dataset import DIMENSIONS, variable_attrs

        content.add_coord("time_indirect", ("time_indirect",), other.t, variable_attrs(self, "time_indirect"))
        for name in ("Sigma", "p", "v", "u", "Lam", "lam_p", "lam_v"):  # on the BVP's nodes, the controls too
            if getattr(other, name) is None:  # an indirect solve that failed before its first BVP has no costates
                continue
            dim = ("time_indirect", *DIMENSIONS[name][1:])
            attrs = variable_attrs(self, name, " (indirect solution)")
            content.add_variable(f"indirect_{name}", dim, getattr(other, name), attrs)
        return content


def _direct_only(direct: Solution, exc: BaseException) -> ComparedSolution:
    """The ``both`` result when the indirect method failed before its first BVP: the direct solution, failed."""
    reason = " ".join(str(exc).split())[:300] or type(exc).__name__
    stats: dict[str, Any] = dict(direct.stats)
    stats["direct_time_s"] = direct.stats.get("total_time_s")
    stats["optimality"] = {"direct": optimality_residuals(direct)}
    fields = {name: getattr(direct, name) for name in Solution.__dataclass_fields__}
    message = f"direct: {direct.message}; indirect: {reason}"
    fields.update(method="both", status="failed", message=message, stats=stats)
    return ComparedSolution(**fields, indirect=None)


def _bvp_block(bvp: BVPSolution, solver: str, time_s: float) -> dict[str, Any]:
    return {
        "solver": solver,
        "cost": bvp.terminal_cost + bvp.running_cost,
        "terminal_cost": bvp.terminal_cost,
        "control_energy": bvp.control_energy,
        "status": "solved" if bvp.success else "failed",
        "message": bvp.message,
        "time_s": time_s,
        "nodes": bvp.nodes,
        "iterations": bvp.iterations,
    }


def solve_both(
    problem: Problem, progress: Callable[[HomotopyStep], None] | None = None, init: Solution | None = None
) -> ComparedSolution:
    """Solve ``problem`` directly and indirectly; return the direct solution with the comparison in ``stats``.

    Parameters
    ----------
    problem : Problem
    progress : callable, optional
        Called with every :class:`HomotopyStep` of the direct, then of the indirect continuation.
    init : Solution, optional
        Warm start of the direct method (see :func:`~mobisense.ocp.direct.solver.solve_direct`).

    Returns
    -------
    ComparedSolution
        ``method="both"``; ``status="solved"`` only if both methods reached ε = 1.
    """
    direct = solve_direct(problem, progress=progress, init=init)
    try:
        indirect, bvp = indirect_continuation(problem, progress=progress)
    except (ArithmeticError, RuntimeError, ValueError) as exc:  # before any BVP: the direct solution is kept
        return _direct_only(direct, exc)
    stats: dict[str, Any] = dict(direct.stats)
    stats["direct_time_s"] = direct.stats.get("total_time_s")
    stats["indirect"] = indirect.stats["indirect"]
    optimality = {"direct": optimality_residuals(direct), "indirect": indirect.stats["optimality"]["indirect"]}
    stats["agreement"] = agreement(direct, bvp) if direct.success and indirect.success else None
    if direct.success:
        t_start = time.perf_counter()
        seeded = refine_from_direct(direct)
        elapsed = time.perf_counter() - t_start
        solver = problem.solver.bvp.refine_solver
        stats["seeded"] = {**_bvp_block(seeded, solver, elapsed), "agreement": agreement(direct, seeded)}
        optimality["seeded"] = optimality_residuals(solution_from_bvp(problem, seeded))
    stats["optimality"] = optimality
    both_solved = direct.success and indirect.success
    message = direct.message if both_solved else f"direct: {direct.message}; indirect: {indirect.message}"
    fields = {name: getattr(direct, name) for name in Solution.__dataclass_fields__}
    fields.update(method="both", status="solved" if both_solved else "failed", message=message, stats=stats)
    return ComparedSolution(**fields, indirect=indirect)
