"""Shrinking-horizon re-planning (docs/theory/path_constraints.md §5): closed loop vs plan, open loop, no control."""

from __future__ import annotations

import pytest
import yaml
from reference_problems import PROBLEMS

from mobisense.ocp.problem import Problem
from mobisense.ocp.replan import Disturbance, replan_monte_carlo


def _problem() -> Problem:
    data = yaml.safe_load((PROBLEMS / "hussein2008.yaml").read_text())
    data["solver"]["collocation"]["intervals"] = 30
    return Problem.from_dict(data)


@pytest.mark.slow
def test_without_disturbance_the_closed_loop_reproduces_the_plan() -> None:
    r = replan_monte_carlo(_problem(), Disturbance(), runs=1, every=2.5, time_step=0.005)
    # principle of optimality: the re-solved plans continue the first one; what differs is the collocation
    # error of the re-solves on their shrinking grids and the O(Δt) platform integration: measured 1.3e-6
    assert r["closed_loop"]["cost_mean"] == pytest.approx(r["plan_cost"], rel=1e-4)
    assert r["open_loop"]["cost_mean"] == pytest.approx(r["plan_cost"], rel=2e-3)  # Euler, Δt = 0.005: O(Δt)
    assert r["no_control"]["cost_mean"] > r["plan_cost"]


@pytest.mark.slow
def test_under_a_current_re_planning_beats_the_open_loop_by_more_than_the_standard_errors() -> None:
    r = replan_monte_carlo(_problem(), Disturbance((0.3, -0.2), 0.05), runs=4, every=1.0, time_step=0.01)
    closed, open_ = r["closed_loop"], r["open_loop"]
    assert closed["cost_mean"] + closed["cost_stderr"] < open_["cost_mean"] - open_["cost_stderr"]
    # every warm re-solve is a fraction of the re-plan interval (real-time factor < 1)
    assert r["replan_solve_time_s"]["median"] < 0.5 * r["replan_every_s"]
