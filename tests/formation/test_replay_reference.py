"""``replay`` never flies a stale plan: the solution's problem hash must match the problem file."""

from __future__ import annotations

import json

import pytest
import yaml
from short_runs import small_solution

from mobisense import cli
from mobisense.core.config import ConfigError
from mobisense.formation.replay.reference import load_checked, reference_status

pytestmark = pytest.mark.slow  # every test here solves a problem


@pytest.fixture
def saved(tmp_path):
    solution = small_solution()
    solution.save(tmp_path / "solution")
    problem = tmp_path / "problem.yaml"
    problem.write_text(yaml.safe_dump(solution.problem.normalised()))
    return tmp_path / "solution" / "solution.nc", problem


def test_an_up_to_date_solution_is_loaded(saved):
    solution_path, problem = saved
    solution, note, solved = load_checked(solution_path, problem)
    assert not solved and "matches" in note and solution.success
    assert "matches" in reference_status(solution_path, problem)


def test_a_stale_solution_is_solved_again(saved):
    solution_path, problem = saved
    data = yaml.safe_load(problem.read_text())
    data["cost"]["alpha"] = 0.016
    problem.write_text(yaml.safe_dump(data))
    assert "is stale" in reference_status(solution_path, problem)
    solution, note, solved = load_checked(solution_path, problem)
    assert solved and "is stale" in note and solution.problem.cost.alpha == 0.016


def test_an_unreadable_solution_without_a_problem_is_an_input_error(tmp_path, saved):
    bad = tmp_path / "bad.nc"
    bad.write_text("not netCDF")
    with pytest.raises(ConfigError, match="is not a solution file written by mobisense solve"):
        load_checked(bad, None)
    solution, note, solved = load_checked(bad, saved[1])
    assert solved and "is not a solution file" in note


def test_the_replay_command_says_it_re_solved_and_writes_the_new_solution(saved, tmp_path):
    solution_path, problem = saved
    data = yaml.safe_load(problem.read_text())
    data["cost"]["alpha"] = 0.016
    problem.write_text(yaml.safe_dump(data))
    scenario = tmp_path / "replay.yaml"
    scenario.write_text(yaml.safe_dump({"name": "r", "solution": str(solution_path), "problem": "problem.yaml",
                                        "monte_carlo": {"runs": 20, "time_step": 0.1}}))  # fmt: skip
    out = tmp_path / "out"
    assert cli.main(["replay", str(scenario), "--out", str(out), "--no-plot"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert "is stale" in summary["solution"] and "solution.nc" in summary["files"]
