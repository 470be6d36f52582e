"""The no-control baseline is compared with only when it is feasible (it violates fixed terminal states)."""

from __future__ import annotations

import json

import pytest
import yaml
from reference_problems import PROBLEMS, hussein2008

from mobisense import Problem, cli


def test_coasting_violates_exactly_the_terminal_states_it_does_not_reach():
    data = hussein2008()
    assert Problem.from_dict(data).coasting_violations() == []
    # coasting from p0 = (10, 10) with v0 = (0, -2) for 10 s ends at (10, -10) with velocity (0, -2)
    data["sensors"][0]["terminal"] = {"p": [10.0, -10.0], "v": [0.0, -2.0]}
    assert Problem.from_dict(data).coasting_violations() == []
    data["sensors"][0]["terminal"] = {"p": [2.0, -2.0], "v": [0.0, -2.0]}
    assert Problem.from_dict(data).coasting_violations() == [
        "sensors[0].terminal.p: coasting ends at (10, -10), not (2, -2)"
    ]
    data["sensors"][0]["terminal"] = {"v": [0.0, 0.0]}
    expected = ["sensors[0].terminal.v: coasting ends at (0, -2), not (0, 0)"]
    assert Problem.from_dict(data).coasting_violations() == expected


@pytest.mark.slow
def test_no_improvement_is_quoted_over_an_infeasible_baseline(tmp_path, capsys):
    data = yaml.safe_load((PROBLEMS / "terminal_and_bound.yaml").read_text())
    data["solver"]["collocation"]["intervals"] = 30
    path = tmp_path / "rendezvous.yaml"
    path.write_text(yaml.safe_dump(data))
    assert cli.main(["solve", str(path), "--out", str(tmp_path / "out"), "--no-plot"]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["baseline_feasible"] is False and summary["improvement_percent"] is None
    assert summary["baseline_violations"] == [
        "sensors[0].terminal.p: coasting ends at (10, -10), not (2, -2)",
        "sensors[0].terminal.v: coasting ends at (0, -2), not (0, 0)",
    ]
    out = capsys.readouterr().out
    assert "none quoted: the baseline is infeasible" in out and "%" not in out.split("improvement")[1].split("\n")[0]


def test_the_improvement_is_quoted_from_the_flown_plan_when_the_grid_does_not_resolve_it() -> None:
    # random-problem audit: a plan that coasts (|u| ≤ 7e-5) was quoted 0.167 % better than coasting from the NLP's J,
    # a grid error (its re-integrated J equals the baseline to 1.6e-10); a failed solve quoted one too
    import copy

    import mobisense as ms

    solution = ms.solve(ms.Problem.from_dict(hussein2008(collocation={"intervals": 30})))
    base, check = solution.baseline["cost"], solution.stats["plan_check"]
    assert solution.improvement_percent == pytest.approx(100 * (base - solution.cost) / base, rel=1e-12)
    unresolved = copy.copy(solution)
    unresolved.stats = {**solution.stats, "plan_check": {**check, "cost": base, "relative_difference": -2e-3}}
    assert unresolved.improvement_percent == 0.0  # the flown plan's J: no better than coasting
    resolved = copy.copy(solution)  # within the plan tolerance (1e-5) the optimiser's J is quoted
    resolved.stats = {**solution.stats, "plan_check": {**check, "cost": base, "relative_difference": 5e-6}}
    assert resolved.improvement_percent == solution.improvement_percent
    failed = copy.copy(solution)
    failed.status = ms.SolveStatus.FAILED
    assert failed.improvement_percent is None
