"""Warm starts shifted in time (docs/theory/path_constraints.md §5.2): the identity shift, and a real shift."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from reference_problems import PROBLEMS

from mobisense.ocp.direct.solver import solve_direct
from mobisense.ocp.direct.transcription import transcription_for
from mobisense.ocp.direct.warm_shift import shifted_point
from mobisense.ocp.problem import Problem
from mobisense.ocp.solution import StartKind


def _problem(intervals: int, t0: float = 0.0) -> Problem:
    data = yaml.safe_load((PROBLEMS / "hussein2008.yaml").read_text())
    data["solver"]["collocation"]["intervals"] = intervals
    data["horizon"]["t0"] = t0
    return Problem.from_dict(data)


@pytest.mark.slow
def test_shifting_onto_the_same_window_and_grid_returns_the_point() -> None:
    problem = _problem(20)
    solution = solve_direct(problem)
    tr = transcription_for(problem)
    nlp = solution.nlp
    point = shifted_point(solution, tr, tr, nlp["P"], (0.0, 10.0))
    # the polynomials at their own nodes are the nodes; the multipliers map back to themselves (same scales)
    assert np.allclose(point["w"], nlp["w"], rtol=1e-12, atol=1e-12)
    assert np.allclose(point["lam_g"], nlp["lam_g"], rtol=1e-12, atol=1e-15)
    assert np.allclose(point["lam_w"], nlp["lam_w"], rtol=1e-12, atol=1e-15)


@pytest.mark.slow
def test_a_point_shifted_onto_a_later_shorter_window_converges_in_a_few_iterations() -> None:
    problem = _problem(20)
    solution = solve_direct(problem)
    # the remaining problem from the plan's own state at t = 2.5, on the problem's spacing (15 intervals)
    state = solution.sample(2.5)
    data = problem.normalised()
    data["horizon"]["t0"] = 2.5
    data["process"]["Sigma0"] = state.Sigma[0].tolist()
    data["sensors"][0]["p0"], data["sensors"][0]["v0"] = state.p[0, 0].tolist(), state.v[0, 0].tolist()
    data["solver"]["collocation"]["intervals"] = 15
    later = Problem.from_dict(data)
    tr = transcription_for(later)
    P = tr.layout.pack(tr.layout.values(later))
    point = shifted_point(solution, transcription_for(problem), tr, P, (2.5, 10.0))
    warm = solve_direct(later, transcription=tr, init=point)
    cold = solve_direct(later.with_solver(strategy="cold"), transcription=tr)
    assert warm.success and warm.stats["start"] is StartKind.WARM
    # principle of optimality: the tail of the plan is (nearly) the optimum of the remaining problem, so the
    # shifted point is close to it: measured 0 iterations against 21 cold; same optimum to Ipopt's tolerance
    assert sum(s.iterations for s in warm.homotopy) <= 5 < sum(s.iterations for s in cold.homotopy)
    assert abs(warm.cost - cold.cost) <= 1e-7 * cold.cost


def test_an_init_on_another_number_of_intervals_is_moved_onto_the_grid() -> None:
    # first-hour audit: refining the mesh (K = 100 → 150) with init= started from coasting (387 iterations); the
    # optimum on the coarser grid now starts the finer one through the shifted point, and ends where a cold
    # solve ends (the same local optimum: the discretisations differ by ~1e-7, the optima to solver tolerance)
    data = yaml.safe_load((PROBLEMS / "coupled_two_sensor.yaml").read_text())
    coarse = solve_direct(Problem.from_dict(data))
    for K in (150, 30):
        data["solver"]["collocation"]["intervals"] = K
        problem = Problem.from_dict(data)
        cold = solve_direct(problem)
        warm = solve_direct(problem, init=coarse)
        assert warm.stats["start"] == StartKind.WARM and warm.success
        assert sum(step.iterations for step in warm.homotopy) <= 10  # measured 3 and 2; cold 294 and 251
        assert warm.cost == pytest.approx(cold.cost, rel=1e-9)
    data["solver"]["collocation"]["degree"] = 2  # another polynomial: the rows differ, nothing to move
    assert solve_direct(Problem.from_dict(data), init=coarse).stats["start"] == StartKind.INIT_OTHER_LAYOUT
