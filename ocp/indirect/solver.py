"""Solve the mobile-sensor Kalman problem by the indirect method, the PMP boundary-value problem.

Theory: docs/theory/indirect.md.

``solve_indirect(problem)`` does what Hussein (2008) does: start from the classical Kalman filter (ε = 0: sensors
coast, Σ from the Riccati IVP, costates from the adjoint equations integrated backwards), continue in ε with the
schedule of ``solver.homotopy`` (:func:`mobisense.ocp.homotopy.run_continuation`) and the BVP solver of ``solver.bvp``
(:mod:`mobisense.ocp.indirect.bvp_solvers`), and return a :class:`~mobisense.ocp.solution.Solution` whose ``stats``
carry the ``indirect`` block and the optimality residuals. ``refine_from_direct`` solves the BVP at ε = 1 from a direct
solution's states and multiplier costates instead.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline

from ..homotopy import run_continuation
from ..model import Structure
from ..problem import Problem
from ..registries import BVP_SOLVERS
from ..simulate import Trajectory, coast
from ..solution import HomotopyStep, Solution, SolveStatus
from .bvp_solvers import BVPSolution, BVPSolver, Guess
from .hamiltonian import HamiltonianSystem, hamiltonian_system
from .residuals import optimality_residuals

__all__ = [
    "solve_indirect",
    "indirect_continuation",
    "refine_from_direct",
    "kalman_guess",
    "solution_from_bvp",
    "indirect_summary",
    "make_bvp_solver",
    "follow_schedule",
]


def kalman_guess(
    system: HamiltonianSystem, problem: Problem, values: dict[str, Any], samples: int = 401
) -> tuple[Callable[[float], Guess], Trajectory]:
    """The ε → 0 guess: coasting sensors, Σ from the Riccati IVP, μ from the backward adjoint.

    Returns ``guess_at(eps)`` — a function giving y(t) = [x(t); μ(t)] with μ the solution of the adjoint
    equation ``μ' = −∂H̃/∂x`` at u = 0 along the coasting states, ``μ(tf) = ε ∂Φ/∂x`` on the free
    components (0 on fixed ones) — and the coasting trajectory (the no-control baseline).
    """
    t0, tf = problem.horizon.t0, problem.horizon.tf
    P = system.layout.pack(values)
    t = np.linspace(t0, tf, samples)
    # CVODES (BDF, compiled): a long horizon makes the Riccati equation stiff, where DOP853 crawled (tf = 1e12
    # ran for minutes, found by a fuzzer); the same trajectory as integrate() within 2e-10 (ocp/simulate.py)
    coasting = coast(system.model, P, t)
    x_of_t = CubicSpline(t, coasting.x)
    zero = np.zeros(system.structure.nu)
    free = ~system.fixed_terminal
    dPhi = np.asarray(system.terminal_gradient(coasting.x[-1], P)).ravel()
    scale = float(np.abs(dPhi).max())  # > 0: M is positive definite

    def guess_at(eps: float) -> Guess:
        Pe = system.layout.pack({**values, "eps": eps})
        mu_T = eps * dPhi * free
        try:
            adjoint = solve_ivp(
                lambda tt, mu: np.asarray(system.costate_rhs(x_of_t(tt), zero, mu, Pe)).ravel(),
                (tf, t0),
                mu_T,
                dense_output=True,
                method="LSODA",  # switches to BDF where the adjoint is stiff (the Riccati's rates, backwards)
                rtol=1e-10,
                atol=1e-12 * scale,
            )
        except ValueError as exc:  # e.g. steps below the resolution of the times (tf = 1e12: a fuzzer's)
            adjoint = None
            reason = str(exc)
        if adjoint is None or not adjoint.success:
            reason = reason if adjoint is None else adjoint.message
            raise RuntimeError(
                f"the ε = 0 (Kalman) guess: the adjoint equation could not be integrated over [{t0:g}, {tf:g}] "
                f"({reason}); the direct method does not need it"
            )

        def guess(times: np.ndarray) -> np.ndarray:
            return np.vstack([x_of_t(times).T, adjoint.sol(times)])

        return guess

    return guess_at, coasting


def _direct_guess(direct: Solution) -> Guess:
    """y(t) from a direct solution: states on its grid, multiplier costates on its costate grid (linear)."""
    if direct.Lam is None:
        raise ValueError("the direct solution carries no costates (it did not converge at any ε)")
    x, lam = direct.states(), direct.costates()
    mu = direct.eps * lam  # μ = ε λ

    def guess(times: np.ndarray) -> np.ndarray:
        xs = [np.interp(times, direct.t, x[:, k]) for k in range(x.shape[1])]
        mus = [np.interp(times, direct.t_costate, mu[:, k]) for k in range(mu.shape[1])]
        return np.array(xs + mus)

    return guess


def make_bvp_solver(problem: Problem, name: str, guess: Guess) -> BVPSolver:
    """BVP solver ``name`` for ``problem``, with the scales of the unknowns taken from ``guess``.

    Parameters
    ----------
    problem : Problem
    name : str
        Key of :data:`mobisense.ocp.registries.BVP_SOLVERS` (``"collocation"`` or ``"scipy"``).
    guess : callable
        times (T,) -> y = [x; μ] (2 nx, T), sampled at 401 points for
        :meth:`~mobisense.ocp.indirect.hamiltonian.HamiltonianSystem.default_scales`.
    """
    system = hamiltonian_system(Structure.of(problem))
    values = system.layout.values(problem)
    P = system.layout.pack(values)
    times = np.linspace(problem.horizon.t0, problem.horizon.tf, 401)
    scales = system.default_scales(guess(times), P)
    return BVP_SOLVERS[name](problem, values, scales)


def refine_from_direct(direct: Solution, solver: str | None = None, problem: Problem | None = None) -> BVPSolution:
    """Solve the BVP at ε = 1 starting from ``direct`` (states + multiplier costates).

    Parameters
    ----------
    direct : Solution
        A converged solution at ε = 1 with costates (direct, or indirect of a neighbouring problem).
    solver : str, optional
        Name in :data:`mobisense.ocp.registries.BVP_SOLVERS` (default ``solver.bvp.refine_solver``).
    problem : Problem, optional
        The problem to solve (default ``direct.problem``); it must have the same structure.
    """
    problem = problem or direct.problem
    guess = _direct_guess(direct)
    bvp = make_bvp_solver(problem, solver or problem.solver.bvp.refine_solver, guess)
    if bvp.name == "scipy":
        return bvp.solve(1.0, guess, mesh=direct.t)
    return bvp.solve(1.0, guess)


def solution_from_bvp(problem: Problem, bvp: BVPSolution, method: str = "indirect") -> Solution:
    """A :class:`Solution` (states, controls, PMP costates λ = μ/ε on the BVP nodes) from a BVP solution."""
    system = hamiltonian_system(Structure.of(problem))
    nx = system.structure.nx
    P = system.layout.pack({**system.layout.values(problem), "eps": bvp.eps})
    x, mu = bvp.y[:nx].T, bvp.y[nx:].T
    u = np.asarray(system.control.map(bvp.nodes)(x.T, mu.T, P)).T
    return Solution.from_states(
        problem,
        method,
        SolveStatus.SOLVED if bvp.success and bvp.eps == 1.0 else SolveStatus.FAILED,
        bvp.message,
        bvp.eps,
        t=bvp.t,
        x=x,
        t_u=bvp.t,
        u=u,
        costs=(bvp.terminal_cost, bvp.running_cost, bvp.control_energy),
        t_costate=bvp.t,
        lam=mu / bvp.eps if bvp.eps > 0 else None,  # λ = μ/ε (at ε = 0 only μ ≡ 0 is defined)
    )


def indirect_summary(bvp: BVPSolution, solver: str, time_s: float, records: list[dict[str, Any]]) -> dict[str, Any]:
    """The ``indirect`` block of summary.json (costs at ε = 1, status, time, nodes, homotopy record).

    ``curve`` lists ε and Tr Σ(tf) at every accepted point of the arclength continuation (collocation
    solver): plotted against each other they show the folds of the solution curve.
    """
    return {
        "solver": solver,
        "cost": bvp.terminal_cost + bvp.running_cost,
        "terminal_cost": bvp.terminal_cost,
        "control_energy": bvp.control_energy,
        "status": "solved" if bvp.success and bvp.eps == 1.0 else "failed",
        "message": bvp.message,
        "eps_reached": bvp.eps,
        "time_s": time_s,
        "nodes": bvp.nodes,
        "homotopy": [{k: v for k, v in r.items() if k != "curve"} for r in records],
        "folds": _distinct([f for r in records for f in r.get("folds", [])]),
        "newton_iterations": int(sum(r["iterations"] for r in records)),
        "arclength_steps": int(sum(r.get("arclength_steps", 0) for r in records)),
        "curve": {
            key: [v for r in records if r["status"] == "converged" for v in r.get("curve", {}).get(key, [])]
            for key in ("eps", "trace_sigma_tf")
        },
    }


def _distinct(values: list[float], rtol: float = 1e-6) -> list[float]:
    """Sorted (descending) values without near-duplicates (a fold passed again after a retried ε step)."""
    out: list[float] = []
    for value in sorted(values, reverse=True):
        if not out or abs(out[-1] - value) > rtol * abs(value):
            out.append(value)
    return out


def solve_indirect(
    problem: Problem,
    progress: Callable[[HomotopyStep], None] | None = None,
    init: Solution | None = None,
) -> Solution:
    """Solve ``problem`` by the indirect method with ε-continuation from the Kalman solution.

    Parameters
    ----------
    problem : Problem
    progress : callable, optional
        Called with a :class:`HomotopyStep` after every ε step.
    init : Solution, optional
        A converged solution with costates (direct or indirect) of a problem of the same structure: its
        states and costates seed the BVP at ε = 1 directly (with ``solver.bvp.refine_solver``); if that
        does not converge, the continuation from the Kalman solution runs.

    Returns
    -------
    Solution
        ``method="indirect"``; see :func:`indirect_continuation`, which also returns the dense BVP solution.
    """
    if init is not None and init.success and init.Lam is not None:
        seeded = _solve_seeded(problem, init)
        if seeded is not None:
            return seeded
    return indirect_continuation(problem, progress)[0]


def _solve_seeded(problem: Problem, init: Solution) -> Solution | None:
    """The BVP at ε = 1 from ``init``'s states and costates, or None if it did not converge there."""
    if Structure.of(init.problem) != Structure.of(problem):
        return None
    t_start = time.perf_counter()
    bvp = refine_from_direct(init, problem=problem)
    if not (bvp.success and bvp.eps == 1.0):
        return None
    elapsed = time.perf_counter() - t_start
    system = hamiltonian_system(Structure.of(problem))
    P = system.layout.pack(system.layout.values(problem))
    coasting = coast(system.model, P, np.linspace(problem.horizon.t0, problem.horizon.tf, 401))
    solution = solution_from_bvp(problem, bvp)
    solution.message = f"converged at ε = 1 from the states and costates of init ({init.method} method)"
    solution.baseline = {
        "cost": coasting.cost,
        "terminal_cost": coasting.terminal_cost,
        "running_cost": coasting.running_cost,
    }
    solution.stats = {
        "indirect": indirect_summary(bvp, problem.solver.bvp.refine_solver, elapsed, [_record(bvp)]),
        "optimality": {"indirect": optimality_residuals(solution)},
        "total_time_s": elapsed,
        "start": "seeded from init at ε = 1",
    }
    return solution


def indirect_continuation(
    problem: Problem, progress: Callable[[HomotopyStep], None] | None = None
) -> tuple[Solution, BVPSolution]:
    """Solve ``problem`` by the indirect method; return the Solution and the final BVP solution.

    Parameters
    ----------
    problem : Problem
        Its ``solver.homotopy`` gives the ε schedule, ``solver.bvp`` the BVP solver and tolerances.
    progress : callable, optional
        Called with a :class:`HomotopyStep` after every ε step (``iterations`` = Newton iterations of
        the collocation solver, or ``solve_bvp`` iterations).

    Returns
    -------
    solution : Solution
        ``method="indirect"``; ``status="solved"`` when ε = 1 was reached, else ``"failed"`` with the
        last ε solved. ``stats["indirect"]`` holds the homotopy record (ε, status, nodes, time, folds
        passed) and ``stats["optimality"]["indirect"]`` the residuals of the necessary conditions.
    bvp : BVPSolution
        The last accepted BVP solution (dense ``evaluate``).
    """
    t_start = time.perf_counter()
    system = hamiltonian_system(Structure.of(problem))
    values = system.layout.values(problem)
    guess_at, coasting = kalman_guess(system, problem, values)
    name = problem.solver.bvp.solver
    bvp = make_bvp_solver(problem, name, guess_at(1.0))
    start = bvp.solve(0.0, guess_at(0.0))
    steps: list[HomotopyStep] = []
    records: list[dict[str, Any]] = [_record(start)]
    accepted: list[BVPSolution] = []
    state = {"current": start}

    def attempt(eps: float) -> bool:
        current = state["current"]
        if current.eps == 0.0 and bvp.natural_parameter:
            # Hussein's (2008) first step: seeded by the Kalman filter and its adjoint costates (μ = ε λ_K)
            result = bvp.solve(eps, guess_at(eps))
        else:
            result = bvp.follow(current, eps)
        status = "converged" if result.success else result.message
        step = HomotopyStep(eps, result.cost_eps, result.iterations, status, result.time_s, result.success)
        steps.append(step)
        records.append({**_record(result), "eps": eps})
        if progress is not None:
            progress(step)
        if result.success:
            state["current"] = result
            accepted.append(result)
        return result.success

    if start.success:
        run_continuation(attempt, problem.solver.homotopy)
    final = state["current"]
    polish = None
    if final.eps == 1.0 and bvp.name != "scipy" and problem.solver.bvp.polish:
        final, polish = _polish(problem, bvp, final)
    elapsed = time.perf_counter() - t_start
    solution = solution_from_bvp(problem, final)
    solution.homotopy = steps
    if not start.success:
        solution.message = f"the ε = 0 (Kalman) BVP did not converge: {start.message}"
    elif final.eps < 1.0:
        solution.message = f"continuation stopped at ε = {final.eps:g}: {steps[-1].status}"
    solution.baseline = {
        "cost": coasting.cost,
        "terminal_cost": coasting.terminal_cost,
        "running_cost": coasting.running_cost,
    }
    if accepted:
        nx = system.structure.nx
        solution.path_eps = np.array([r.eps for r in accepted])
        path_x = np.stack([r.evaluate(final.t)[:nx].T for r in accepted])
        solution.path_Sigma, solution.path_p, _ = solution.layout.split(path_x)
    summary = indirect_summary(final, name, elapsed, records)
    if polish is not None:
        summary["polish"] = polish
    solution.stats = {
        "indirect": summary,
        "optimality": {"indirect": optimality_residuals(solution)},
        "total_time_s": elapsed,
    }
    return solution, final


def follow_schedule(solver: BVPSolver, start: BVPSolution, schedule: list[float]) -> list[BVPSolution]:
    """Continue ``start`` through the ε values of ``schedule`` above ``start.eps`` with ``solver.follow``.

    With a natural-parameter solver (``solve_bvp``) and ``schedule = fixed_schedule(δ)`` this is the
    continuation of Hussein (2008, §IV) from any solution, e.g. one on the far branch of the ε-family
    (docs/theory/indirect.md §3.4).

    Returns
    -------
    list of BVPSolution
        One per attempted ε, in order; the last is the first failure, if any.
    """
    steps: list[BVPSolution] = []
    current = start
    for eps in schedule:
        if eps <= start.eps:
            continue
        current = solver.follow(current, eps)
        steps.append(current)
        if not current.success:
            break
    return steps


def _polish(problem: Problem, solver: BVPSolver, solution: BVPSolution) -> tuple[BVPSolution, dict[str, Any]]:
    """Re-solve at ε = 1 with ``solve_bvp`` (residual control, adaptive mesh) from a collocation solution.

    Returns the polished solution if it converged (else ``solution``) and a report whose ``cost_change``
    (relative) estimates the discretisation error of the uniform collocation mesh.
    """
    scipy_solver = BVP_SOLVERS["scipy"](problem, solver.values, solver.D)
    polished = scipy_solver.solve(1.0, solution)
    cost = solution.terminal_cost + solution.running_cost
    report = {
        "solver": "scipy",
        "status": "converged" if polished.success else polished.message,
        "nodes": polished.nodes,
        "time_s": polished.time_s,
        "cost_change": abs(polished.terminal_cost + polished.running_cost - cost) / abs(cost),
        "collocation_cost": cost,
    }
    if not polished.success:
        return solution, report
    polished.message = f"{solution.message}; polished by solve_bvp ({polished.nodes} nodes)"
    return polished, report


def _record(result: BVPSolution) -> dict[str, Any]:
    """One homotopy record of the summary: ε, status, nodes, time, iterations (+ arclength details)."""
    return {
        "eps": result.eps,
        "status": "converged" if result.success else result.message,
        "nodes": result.nodes,
        "time_s": result.time_s,
        "iterations": result.iterations,
        **{k: v for k, v in result.report.items() if k in ("arclength_steps", "rejected_steps", "folds", "curve")},
    }
