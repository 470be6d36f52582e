"""Why a solution's numbers are not to be trusted as they stand: the warnings of ``summary.json`` and the command.

Each is a sentence for the user, from what a :class:`~mobisense.ocp.solution.Solution` holds: its plan check
(:mod:`mobisense.ocp.direct.plan_check`), its strategy's record, its covariance and its baseline.
"""

from __future__ import annotations

from typing import Any

from .solve_outcome import StartKind

__all__ = ["PLAN_TOLERANCE", "PATH_TOLERANCE", "UNRESOLVED_FIELD", "field_grid_warning", "solution_warnings",
           "unresolved_plan_cost", "plan_warning", "constraint_warning", "strategy_warning",
           "init_warning"]  # fmt: skip

#: relative difference of the optimiser's J from its plan re-integrated (``stats["plan_check"]``) above which the
#: grid is reported as not resolving the plan (the discretisation error of a resolved grid is far smaller:
#: 5e-11 on the default problem at K = 100, 2.2e-7 on coupled_two_sensor at its K = 50)
PLAN_TOLERANCE = 1e-5
#: violation of a path constraint on the re-simulated path (between the nodes), relative to the constraint's size
#: (a disc's radius, a polygon's √area, d_min, v_max, the workspace's shorter side, u_max), beyond which the plan
#: is reported as breaking it: a resolved grid leaves far less (keep_out.yaml at K = 80: 1e-4 of the radius)
PATH_TOLERANCE = 1e-2


def solution_warnings(solution: Any, smallest: float, init: bool = True) -> list[str]:
    """Every warning that applies to ``solution``, whose Σ(t) has smallest eigenvalue ``smallest``.

    ``init=False`` leaves out :func:`init_warning` (a sweep warm-starts its tasks from neighbours itself: no ``init``
    the user gave went unused).
    """
    candidates = (plan_warning(solution), constraint_warning(solution), strategy_warning(solution),
                  init_warning(solution) if init else None, field_grid_warning(solution))  # fmt: skip
    warnings = [w for w in candidates if w]
    if smallest <= 0:  # a covariance that is not one: the grid or the solve did not follow the Riccati flow
        warnings.append(f"Σ(t) is not positive definite (smallest eigenvalue {smallest:.3g}): not a Kalman "
                        "filter's covariance — the grid does not resolve it or the optimum is a poor one; try "
                        "more intervals or --multistart K")  # fmt: skip
    if solution.worse_than_baseline:
        # a grid too coarse for the covariance's decay leaves no plan near coasting in the NLP (stiff_start.py)
        why = solution.stats.get("coarse_grid") or "a poor local optimum; try --multistart K"
        warnings.append(
            f"the optimum found (J = {solution.cost:.6g}) costs more than not moving (no-control baseline "
            f"J = {solution.baseline['cost']:.6g}): {why}"
        )
    return warnings


#: mean kriging residual variance inside a cell (fraction of σ²) beyond which a field's grid is reported as not
#: resolving the field: a spacing of about 1.2 ℓ (Matérn-3/2); field_mapping_5x5.yaml (2ℓ/3) leaves 0.05
UNRESOLVED_FIELD = 0.25


def field_grid_warning(solution: Any) -> str | None:
    """That a field's grid is too coarse for its length scale (:meth:`FieldSpec.unresolved_fraction`), or None.

    The filter's state is the field at the nodes: with ℓ = 0.3 on a spacing of 2 the plan parked a sensor on a node
    and J counted that node as known, while the cell around it kept 95 % of its prior variance (field audit).
    """
    spec = solution.problem.process.field
    if spec is None:
        return None
    fraction = spec.unresolved_fraction()
    if fraction <= UNRESOLVED_FIELD:
        return None
    (nx, ny), ((x0, x1), (y0, y1)) = spec.grid, spec.extent
    spacing = max((x1 - x0) / nx, (y1 - y0) / ny)
    return (f"the field's grid does not resolve it: cells of {spacing:.3g} for a length scale of "
            f"{spec.kernel.length_scale:.3g} leave {100 * fraction:.0f} % of the field's variance unknown between the "
            "nodes whatever the sensors do, and J, the plan and the maps describe the nodes only (docs/theory/field.md "
            "§1); use a finer process.field.grid (a spacing of at most ℓ/3 leaves about 1 %)")


def constraint_warning(solution: Any) -> str | None:
    """Which path constraints the flown plan breaks beyond :data:`PATH_TOLERANCE` of their size, or None.

    The NLP holds the constraints at the collocation nodes; the re-simulated path between them
    (``stats["constraints"]``, :func:`mobisense.ocp.direct.path_report.constraint_report`) may cross them when
    the grid is too coarse near the constraint, or when no path can keep them (a start on a zone's edge,
    heading in at the speed limit) and the optimiser has found the discretisation's way through instead.
    """
    report = solution.stats.get("constraints")
    if not report:
        return None
    from .path_constraints import constraint_sizes

    problem = solution.problem
    sizes = constraint_sizes(problem.constraints) if problem.constraints is not None else {}
    bounds = [s.u_max for s in problem.sensors if s.u_max is not None]
    if bounds:
        sizes["u_max"] = float(min(bounds))
    broken = []
    for group, entry in report.items():
        size = sizes.get(group)
        violation = entry.get("max_violation")
        if size and violation is not None and violation > PATH_TOLERANCE * size:
            broken.append(f"{group} by {violation:.3g} {entry.get('units', '')} ({100 * violation / size:.2g} % of its "
                          f"size) at t = {entry['max_violation_time']:.4g} (at the nodes "
                          f"{entry['max_violation_at_nodes']:.2g})")  # fmt: skip
    if not broken:
        return None
    return (
        f"the plan's controls, flown, break {'; '.join(broken)}: the constraints hold at the collocation nodes "
        f"only; solve on more than K = {_intervals(solution)} intervals (--intervals), and if the violation does "
        "not shrink, no path keeps the constraint from this start"
    )


def _intervals(solution: Any) -> Any:
    """The solution's number of intervals K (of its collocation, else of its shooting grid)."""
    return solution.collocation[2] if solution.collocation is not None else solution.stats.get("intervals")


def unresolved_plan_cost(solution: Any) -> float | None:
    """J of the plan re-integrated when it differs from the optimiser's by more than :data:`PLAN_TOLERANCE`, else None.

    The grid does not resolve such a plan (:func:`plan_warning`); its quoted improvement uses this J.
    """
    check = solution.stats.get("plan_check") or {}
    difference = check.get("relative_difference")
    if check.get("cost") is None or difference is None or abs(difference) <= PLAN_TOLERANCE:
        return None
    return float(check["cost"])


def plan_warning(solution: Any) -> str | None:
    """Why J is not to be trusted when the plan check (``stats["plan_check"]``) exceeds :data:`PLAN_TOLERANCE`.

    The check (:func:`mobisense.ocp.direct.plan_check.check_plan`) re-integrates the controls independently of
    the collocation; None when it is within the tolerance or was not run.
    """
    check = solution.stats.get("plan_check")
    if not check:
        return None
    if check.get("cost") is None:
        return f"the plan check could not re-integrate this plan ({check.get('integrator')}): J is unchecked"
    if unresolved_plan_cost(solution) is None:
        return None
    difference = check["relative_difference"]
    return (
        f"the grid does not resolve this plan: its controls re-integrated give J = {check['cost']:.8g}, "
        f"{100 * abs(difference):.3g} % {'below' if difference > 0 else 'above'} the optimiser's (relative "
        f"difference {difference:+.2g}, beyond ±{PLAN_TOLERANCE:g}); solve on more than K = {_intervals(solution)} "
        "intervals (--intervals) before trusting J or the choice between starts"
    )


def strategy_warning(solution: Any) -> str | None:
    """Why the plan is not the continuation's when ``solver.strategy: homotopy`` asked for it (else None).

    With a budget the strategy falls back to the cold solve when the continuation would cost more than
    ``budget`` × the cold solve's iterations or fails (docs/theory/direct.md §5.6): documented, but a user who
    asked for the paper's method is told which plan they got and how to get the other.
    """
    strategy = solution.stats.get("strategy") or {}
    if strategy.get("strategy") != "homotopy" or strategy.get("kept") in (None, "homotopy"):
        return None
    run = next((s for s in strategy.get("starts", []) if s.get("start") == "homotopy"), None)
    if run is None:
        return None
    why = (f"spent its budget of {strategy.get('homotopy_budget')} iterations (solver.homotopy.budget × the cold "
           "solve's; null lets it finish)" if run.get("status") == "budget spent" else
           f"ended with {run.get('status')}")  # fmt: skip
    reached = run.get("eps_reached") or 0.0  # the last ε solved: 0 is the coasting start, before any step
    where = f"after solving ε = {reached:g}" if reached > 0 else "within its first ε step"
    return (f"strategy homotopy: the continuation stopped {where} when it {why}; the {strategy.get('kept')} solve's "
            "plan is kept")  # fmt: skip


def init_warning(solution: Any) -> str | None:
    """Why the ``init`` a solve was given did not start it (another grid or structure, no converged point)."""
    start = solution.stats.get("start")
    if solution.stats.get("init_unused"):  # a field's shooting says why itself
        return str(solution.stats["init_unused"])
    if start == StartKind.INIT_OTHER_LAYOUT:
        return ("init was not used: its NLP has another structure (sensors, states, constraints, collocation scheme "
                "or degree, or horizon; another number of intervals is moved onto the grid); solved from coasting "
                "(solver.strategy) as without it")  # fmt: skip
    if start == StartKind.INIT_OTHER_METHOD:
        return ("init was not used: it was solved by another method (a field's shooting or the indirect method), "
                "which has no collocation point to start from; solved from coasting (solver.strategy) as without it")
    if start == StartKind.INIT_WITHOUT_POINT:
        return ("init was not used: it carries no converged ε = 1 NLP point (a failed solve, or one read from a "
                "file); solved from coasting (solver.strategy) as without it")  # fmt: skip
    return None
