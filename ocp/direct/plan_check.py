"""The check of a direct solution: its controls re-integrated independently of the collocation, and J compared.

The NLP's J is a quadrature of the collocation polynomials; when the grid resolves Σ it differs from the J of
the same controls integrated accurately by the discretisation error (order 2d − 1: ≈ 5e-11 relative on the
default problem at K = 100). When it does not — a covariance that falls within a fraction of an interval, a
control that swings between two nodes — the NLP's J can be several per cent off the J of the plan it returns,
and comparing starts by it keeps the wrong one. :func:`check_plan` integrates the returned controls (the
Lagrange polynomials through each interval's collocation points: what ``Solution.sample`` returns and a replay
flies) with :func:`mobisense.ocp.simulate.resimulate_plan`; ``mobisense solve`` and :func:`mobisense.solve` store
the result as ``plan_check`` in the solution's statistics (``summary.json``) and warn above
:data:`mobisense.ocp.solution_warnings.PLAN_TOLERANCE`.
"""

from __future__ import annotations

import time
from typing import Any

from ..simulate import resimulate_plan
from ..solution import Solution
from .transcription import transcription_for

__all__ = ["check_plan", "record_plan_check"]


def check_plan(solution: Solution) -> dict[str, Any]:
    """Re-integrate a direct solution's controls; return ``{cost, relative_difference, integrator, time_s}``.

    ``relative_difference`` = (NLP J − re-integrated J) / |re-integrated J|; ``cost`` None (and ``integrator``
    the reason) when the integration failed. The transcription is the cached one of the solution's problem.
    """
    problem = solution.problem
    if solution.collocation is None:
        raise ValueError("check_plan: not a direct-collocation solution (no collocation grid)")
    tr = transcription_for(problem)
    P = tr.layout.pack(tr.layout.values(problem))
    u = solution.u.reshape(tr.intervals, tr.colloc.degree, -1)
    t0 = time.perf_counter()
    try:
        check = resimulate_plan(tr.model, P, u, tr.colloc.tau[1:], problem.horizon.t0, problem.horizon.tf)
    except RuntimeError as exc:
        return {"cost": None, "relative_difference": None, "integrator": str(exc), "time_s": time.perf_counter() - t0}
    cost = check.trajectory.cost
    difference = (solution.cost - cost) / abs(cost) if cost else None
    return {"cost": cost, "relative_difference": difference, "integrator": check.integrator,
            "time_s": time.perf_counter() - t0}  # fmt: skip


def record_plan_check(solution: Solution) -> None:
    """Store the plan check as ``solution.stats["plan_check"]`` for a solved solution (else nothing).

    :func:`check_plan` for a direct solution, :func:`mobisense.ocp.field_plan_check.check_field_plan` for a
    field's shooting solution; the indirect method's J is not a plan's.
    """
    if not solution.success:
        return
    if solution.collocation is not None:
        solution.stats["plan_check"] = check_plan(solution)
    elif solution.method == "shooting":
        from ..field_plan_check import check_field_plan

        solution.stats["plan_check"] = check_field_plan(solution)
