"""Parametric sensitivities of the direct optimum (eq. path.6) against central differences of re-solved optima."""

from __future__ import annotations

import json
import re

import pytest
import yaml
from reference_problems import PROBLEMS

from mobisense import cli
from mobisense.ocp.direct.sensitivities import solution_sensitivities
from mobisense.ocp.direct.solver import solve_direct
from mobisense.ocp.direct.transcription import transcription_for
from mobisense.ocp.problem import Problem


def _path(key: str) -> list:
    return [int(t[1:-1]) if t.startswith("[") else t for t in re.findall(r"[A-Za-z_0-9]+|\[\d+\]", key)]


def _get(data: dict, key: str) -> float:
    for k in _path(key):
        data = data[k]
    return data


def _with(data: dict, key: str, value: float) -> dict:
    copy = yaml.safe_load(yaml.safe_dump(data))
    *head, last = _path(key)
    target = copy
    for k in head:
        target = target[k]
    target[last] = value
    return copy


def _problem(name: str) -> Problem:
    data = yaml.safe_load((PROBLEMS / name).read_text())
    data["solver"]["collocation"]["intervals"] = 30
    data["solver"]["tolerance"] = 1e-11
    return Problem.from_dict(data)


@pytest.mark.slow
@pytest.mark.parametrize(
    "name, keys, step",
    [
        (
            "hussein2008.yaml",
            ["cost.alpha", "horizon.tf", "sensors[0].p0[0]", "sensors[0].noise.beta", "process.A[0][0]",
             "process.B[0][0]", "process.locations[0][1]", "cost.M[0][0]"],
            1e-4,
        ),
        # an active disc touches the path near a node: a step of 1e-4 r already changes which nodes are
        # active (a second-order kink of J*, 1e-4 relative error measured), so the step is 1e-6
        # s2 measures x1 + x2: the row moves C_2 and the location the row refers to (eq. path.8)
        ("coupled_two_sensor.yaml", ["sensors[1].measures[0][0]", "sensors[1].measures[0][1]", "cost.alpha"], 1e-4),
        ("keep_out.yaml", ["constraints.keep_out[0].radius", "constraints.keep_out[0].center[1]", "cost.alpha"], 1e-6),
    ],
)  # fmt: skip
def test_envelope_sensitivities_match_central_differences_of_re_solved_optima(name, keys, step) -> None:
    problem = _problem(name)
    solution = solve_direct(problem)
    assert solution.success
    sens = solution_sensitivities(transcription_for(problem), solution)
    base = problem.normalised()
    for key in keys:
        x = _get(base, key)
        h = step * (abs(x) or 1.0)
        costs = [solve_direct(Problem.from_dict(_with(base, key, x + s * h)), init=solution).cost for s in (1, -1)]
        fd = (costs[0] - costs[1]) / (2 * h)
        # central difference: truncation O(h² J''') ≤ 1e-7 relative at these steps; the warm-started re-solves
        # (tol 1e-11) agree to ~1e-12 J, i.e. ≤ 1e-6 relative after division by 2h: measured ≤ 1e-6 on every key,
        # so 1e-5 is a tenfold margin
        assert sens[key] == pytest.approx(fd, rel=1e-5, abs=1e-9), key


@pytest.mark.slow
def test_solve_sensitivities_flag_writes_every_leaf(tmp_path, capsys) -> None:
    out = tmp_path / "out"
    code = cli.main(["solve", str(PROBLEMS / "hussein2008.yaml"), "--intervals", "20", "--out", str(out),
                     "--sensitivities", "--no-plot", "--quiet"])  # fmt: skip
    assert code == 0
    sens = json.loads((out / "summary.json").read_text())["sensitivities"]
    expected = {"horizon.t0", "horizon.tf", "process.A[0][0]", "process.B[0][0]", "process.Q[0][0]",
                "process.Sigma0[0][0]", "process.locations[0][0]", "process.locations[0][1]", "sensors[0].p0[0]",
                "sensors[0].p0[1]", "sensors[0].v0[0]", "sensors[0].v0[1]", "sensors[0].noise.beta",
                "sensors[0].noise.gamma", "cost.M[0][0]", "cost.K[0][0]", "cost.alpha"}  # fmt: skip
    assert set(sens) == expected
    # the horizon can be shifted without changing anything: dJ/dt0 = −dJ/dtf (time invariance, A constant)
    assert sens["horizon.t0"] == pytest.approx(-sens["horizon.tf"], rel=1e-6)


def test_sensitivities_need_the_direct_method(tmp_path, capsys) -> None:
    out = tmp_path / "out"
    code = cli.main(["solve", str(PROBLEMS / "hussein2008.yaml"), "--method", "indirect", "--out", str(out),
                     "--sensitivities"])  # fmt: skip
    assert code == 2 and "--sensitivities" in capsys.readouterr().err and not out.exists()


@pytest.mark.slow
def test_a_symmetric_matrix_gives_each_of_its_two_off_diagonal_entries_half_the_derivative() -> None:
    # random-problem audit: Σ0[0][1] read −0.0648 with Σ0[1][0] 0.0, M and K halves, Q an uneven split depending on
    # B; only the pair's sum matched a central difference. Each entry is now half the derivative of changing both
    problem = _problem("coupled_two_sensor.yaml")
    solution = solve_direct(problem)
    sens = solution_sensitivities(transcription_for(problem), solution)
    base = problem.normalised()
    for key in ("process.Sigma0", "process.Q", "cost.M"):
        upper, lower = sens[f"{key}[0][1]"], sens[f"{key}[1][0]"]
        assert upper == lower
        x = _get(base, f"{key}[0][1]")
        h = 1e-4 * (abs(x) or 1.0)
        costs = []
        for s in (1, -1):
            both = _with(_with(base, f"{key}[0][1]", x + s * h), f"{key}[1][0]", x + s * h)
            costs.append(solve_direct(Problem.from_dict(both), init=solution).cost)
        # the symmetric change moves both entries: dJ = (upper + lower) h; central difference as in the test above
        assert upper + lower == pytest.approx((costs[0] - costs[1]) / (2 * h), rel=1e-5, abs=1e-9), key


def test_a_field_solved_directly_lists_no_derived_matrices_and_no_named_weights() -> None:
    # A, B, Q, Σ0 and the locations of a field are derived from it; M: mean names no numbers (they were listed)
    from short_runs import field_problem

    problem = Problem.from_dict(field_problem(method="direct", collocation={"intervals": 10}))
    solution = solve_direct(problem)
    sens = solution_sensitivities(transcription_for(problem), solution)
    assert not [key for key in sens if key.startswith(("process.", "cost.M", "cost.K"))]
    assert {"cost.alpha", "horizon.tf", "sensors[0].p0[0]", "sensors[0].noise.variance_value"} <= set(sens)
