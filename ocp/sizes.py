"""Memory estimates of solving a problem from its sizes alone, for the pre-flight budget (:mod:`mobisense.core.budget`).

The direct method's peak is CasADi's expanded NLP with its Jacobian and Hessian functions (≈ 140–260 bytes
per SX node, measured for n = 1…10 states and N = 1…64 sensors, K = 10…1600 intervals, d = 1…9) plus Ipopt's
KKT matrices and MUMPS factors (counted per structural non-zero); a continuation builds a second, warm-started
solver (measured 1.6× the memory of one). Against the peak RSS measured for 20 sizes the estimate is
0.8–1.6×. The counts come from :func:`mobisense.ocp.direct.nlp_size.transcription_size`.
The indirect method's collocation BVP has the same symbolic functions on its own mesh, and a sparse LU
whose fill stays within each interval's block.
"""

from __future__ import annotations

from ..core.budget import PROCESS_BYTES, Estimate
from .direct.nlp_size import path_rows_size, transcription_size
from .homotopy import fixed_schedule
from .model import Structure
from .problem import Problem

__all__ = ["BYTES_PER_NODE", "BYTES_PER_NONZERO", "direct_estimate", "indirect_estimate", "solution_bytes",
           "problem_estimates"]  # fmt: skip

#: resident memory per SX node of the expanded NLP and its derivative functions (upper end of 137–260 measured)
BYTES_PER_NODE = 200
#: Ipopt + MUMPS memory per structural non-zero of the constraint Jacobian and Lagrangian Hessian
BYTES_PER_NONZERO = 600
#: lower estimates of the time: building per SX node (5 µs measured on a loaded core), and one Ipopt iteration
#: per non-zero (a continuation step takes ≥ 15 iterations cold, fewer warm)
SECONDS_PER_NODE = 1e-6
SECONDS_PER_NONZERO_ITERATION = 5e-8
_SMALLER = "use fewer intervals (--intervals), a lower degree (--degree), or fewer states or sensors"


def _steps(problem: Problem) -> int:
    h = problem.solver.homotopy
    return 1 if h.mode == "none" else len(fixed_schedule(h.step)) if h.mode == "fixed" else int(4 / h.step) + 1


def solution_bytes(problem: Problem) -> float:
    """Bytes of a :class:`~mobisense.ocp.solution.Solution` (states, costates, homotopy path) and its dataset."""
    c = problem.solver.collocation
    s = Structure.of(problem)
    times = c.intervals * (c.degree + 1) + 1
    path = min(_steps(problem), 1000)
    return 2 * 8.0 * times * s.nx * (3 + path)


def direct_estimate(problem: Problem, intervals: int | None = None) -> Estimate:
    """Peak memory of :func:`mobisense.ocp.direct.solver.solve_direct` on ``problem``."""
    c = problem.solver.collocation
    K = intervals or c.intervals
    size = transcription_size(Structure.of(problem), c.degree, K, c.scheme)
    solvers = 1.0 if problem.solver.homotopy.mode == "none" else 1.7  # the warm solver: 1.6× measured
    nonzeros = size.jacobian_nnz + size.hessian_nnz
    need = solvers * (BYTES_PER_NODE * size.expression_nodes + BYTES_PER_NONZERO * nonzeros)
    iterations = 5 * _steps(problem)
    seconds = solvers * SECONDS_PER_NODE * size.expression_nodes + iterations * nonzeros * SECONDS_PER_NONZERO_ITERATION
    structure = Structure.of(problem)
    rows = path_rows_size(structure.path, problem.N, 4 + 2 * c.degree)[0]
    paths = f", {rows} path-constraint rows per node" if rows else ""
    what = (
        f"the direct-collocation NLP ({size.variables:.3g} variables, {size.jacobian_nnz + size.hessian_nnz:.3g} "
        f"Jacobian and Hessian non-zeros: n = {problem.n} states, N = {problem.N} sensors, K = {K} intervals, "
        f"d = {c.degree}{paths})"
    )
    hint = _SMALLER + (", or fewer keep-out zones or polygon vertices (constraints)" if rows else "")
    return Estimate(what, need + solution_bytes(problem), hint, seconds)


def indirect_estimate(problem: Problem) -> Estimate:
    """Peak memory of the indirect method: the collocation BVP (Newton, sparse LU) and ``solve_bvp``."""
    c, bvp = problem.solver.collocation, problem.solver.bvp
    K = bvp.intervals or c.intervals
    s = Structure.of(problem)
    ny = 2 * s.nx
    direct = direct_estimate(problem, intervals=K)
    symbolic = direct.bytes
    lu = 16.0 * K * (ny * (c.degree + 1)) ** 2
    nodes = min(bvp.max_nodes, 10 * (K * c.degree + 1))
    scipy_bvp = 3 * 8.0 * nodes * ny * ny
    what = (
        f"the indirect method's BVP ({ny} unknowns per node: n = {problem.n} states, N = {problem.N} sensors, "
        f"{K} intervals, up to {nodes} solve_bvp nodes)"
    )
    return Estimate(what, symbolic + lu + scipy_bvp, _SMALLER + ", or solver.bvp.max_nodes", direct.seconds)


def shooting_estimate(problem: Problem) -> Estimate:
    """Peak memory and least time of the reduced-space shooting method (:mod:`mobisense.ocp.field`)."""
    from .field import (
        COARSE_H_LAMBDA,
        CONSTRAINED_FACTOR,
        START_ITERATIONS,
        STEP_ITERATIONS,
        shooting_memory_bytes,
        shooting_seconds,
        substeps_for,
    )

    o, n = problem.solver.shooting, problem.n
    m = o.substeps or substeps_for(problem, o.intervals)  # as the solver takes them (FieldShooting)
    what = (f"the shooting NLP (n = {n} field states, N = {problem.N} sensors, K = {o.intervals} intervals of m = {m} "
            "RK4 substeps)")  # fmt: skip
    if m == 1:  # one substep per interval: K itself sets K·m
        hint = "use fewer intervals (solver.shooting.intervals, --intervals) or a coarser grid (process.field.grid)"
    else:
        hint = (
            "use a coarser grid (process.field.grid), fewer sensors or a shorter horizon; memory grows with "
            "(n² + N²) K·m, and K·m with the horizon times the field's fastest rate (docs/theory/field.md §3.3), "
            "not with K"
        )
    N = problem.N
    # the coarse phase first: each ε step of the schedule and each random start, on the coarse grid
    m_coarse = substeps_for(problem, o.coarse_intervals, COARSE_H_LAMBDA)
    coarse_iterations = STEP_ITERATIONS * len(o.homotopy) + START_ITERATIONS * o.starts
    seconds = shooting_seconds(n, o.intervals, m, N) + shooting_seconds(n, o.coarse_intervals, m_coarse, N,
                                                                         coarse_iterations)  # fmt: skip
    if problem.constraints is not None:
        seconds *= CONSTRAINED_FACTOR
    if o.starts:
        hint += "; fewer random starts (solver.shooting.starts)"
    return Estimate(what, shooting_memory_bytes(n, o.intervals, m, N), hint, seconds)


def problem_estimates(
    problem: Problem, method: str | None = None, starts: int = 1, local_workers: int = 0
) -> list[Estimate]:
    """What solving ``problem`` needs: by ``method`` (default the problem's), ``starts`` multi-start solutions.

    Parameters
    ----------
    problem : Problem
    method : str, optional
        ``direct``, ``indirect`` or ``both``.
    starts : int
        Solutions held at once (multi-start keeps every start's solution).
    local_workers : int
        Local dask worker processes, each solving one start at a time (0: the solve runs in this process).
    """
    method = method or problem.solver.method
    parts = []
    if method == "shooting":
        parts.append(shooting_estimate(problem))
    if method in ("direct", "both"):
        parts.append(direct_estimate(problem))
    if method in ("indirect", "both"):
        parts.append(indirect_estimate(problem))
    if local_workers:
        worker = parts[0]
        parts = [
            Estimate(f"{local_workers} worker processes, each solving {worker.what}",
                     local_workers * (PROCESS_BYTES + worker.bytes), worker.hint + "; or fewer --workers",
                     worker.seconds * starts / local_workers),
        ]  # fmt: skip
    if starts > 1:
        parts.append(Estimate(f"{starts} multi-start solutions", starts * solution_bytes(problem), "fewer starts"))
    return parts
