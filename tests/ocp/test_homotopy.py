"""ε-continuation schedules and the bookkeeping of a failure in the middle of the homotopy."""

from __future__ import annotations

import numpy as np
import pytest
from reference_problems import hussein2008

from mobisense.ocp.direct.solver import solve_direct
from mobisense.ocp.direct.transcription import transcription_for
from mobisense.ocp.homotopy import run_continuation
from mobisense.ocp.problem import HomotopyOptions, Problem


def record(fail_above=None, fail_once_at=None):
    tried = []
    failed_once = set()

    def attempt(eps):
        tried.append(eps)
        if fail_above is not None and eps > fail_above:
            return False
        if fail_once_at is not None and eps == fail_once_at and eps not in failed_once:
            failed_once.add(eps)
            return False
        return True

    return tried, attempt


def test_fixed_schedule_is_the_papers():
    tried, attempt = record()
    assert run_continuation(attempt, HomotopyOptions(mode="fixed", step=0.05)) == 1.0
    np.testing.assert_allclose(tried, 0.05 * np.arange(1, 21), rtol=0, atol=1e-12)


def test_fixed_schedule_ends_exactly_at_one():
    tried, attempt = record()
    run_continuation(attempt, HomotopyOptions(mode="fixed", step=0.3))
    assert tried == [0.3, 0.6, 0.9, 1.0]


def test_fixed_stops_at_first_failure():
    tried, attempt = record(fail_above=0.5)
    assert run_continuation(attempt, HomotopyOptions(mode="fixed", step=0.25)) == 0.5
    assert tried == [0.25, 0.5, 0.75]


def test_adaptive_grows_and_cuts():
    tried, attempt = record(fail_once_at=0.35)
    assert run_continuation(attempt, HomotopyOptions(mode="adaptive", step=0.05, growth=2.0)) == 1.0
    # 0.05, +0.1 -> 0.15, +0.2 -> 0.35 fails, +0.1 -> 0.25, +0.2 -> 0.45, +0.4 -> 0.85, +0.8 -> 1
    assert tried == [0.05, 0.15, 0.35, 0.25, 0.45, 0.85, 1.0]


def test_adaptive_gives_up_below_min_step():
    tried, attempt = record(fail_above=0.3)
    reached = run_continuation(attempt, HomotopyOptions(mode="adaptive", step=0.1, min_step=0.01))
    assert reached == pytest.approx(0.3)
    assert all(eps > 0.3 for eps in tried[-3:])


@pytest.mark.slow
def test_failure_mid_homotopy_keeps_last_solved_step(monkeypatch):
    # the continuation alone (strategy homotopy, no budget: no cold solve to fall back on), docs/theory/direct.md §5.3
    problem = Problem.from_dict(
        hussein2008(collocation={"intervals": 40}, homotopy={"step": 0.25, "budget": None}, strategy="homotopy")
    )
    tr = transcription_for(problem)
    real_solve = type(tr).solve
    eps_offset = tr.layout.offsets["eps"][0]

    def failing_solve(self, P, *args, **kwargs):
        result = real_solve(self, P, *args, **kwargs)
        if P[eps_offset] > 0.6:  # pretend Ipopt failed from ε = 0.75 on
            result.success, result.status = False, "Restoration_Failed"
        return result

    monkeypatch.setattr(type(tr), "solve", failing_solve)
    solution = solve_direct(problem, transcription=tr)
    assert solution.status == "failed" and solution.eps == 0.5
    assert "Restoration_Failed at ε = 0.75" in solution.message and "last ε solved = 0.5" in solution.message
    assert [s.eps for s in solution.homotopy] == [0.25, 0.5, 0.75]
    assert solution.path_eps.tolist() == [0.25, 0.5]
    assert solution.Lam is not None  # costates of the last solved step are kept
    worst = solution.stats["worst_violation"]
    assert isinstance(worst["constraint"], str) and 0.0 <= worst["time"] <= 10.0
