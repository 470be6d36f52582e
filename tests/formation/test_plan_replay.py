"""Replay of an optimised plan: tracking error bound, Monte Carlo consistency with the optimiser's Σ(t)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from reference_problems import hussein2008
from scipy.integrate import quad_vec

from mobisense.cli import main
from mobisense.core.config import ConfigError, parse_config
from mobisense.estimation.fields.library import QuadraticField
from mobisense.formation.replay.plan import (
    OcpReplayScenario,
    discretise_process,
    measurement_variances,
    monte_carlo_filter,
    predicted_covariance,
    replay_solution,
    simulate_tracking,
)
from mobisense.formation.replay.reference import ReferenceTrajectory, TrackingController, load_or_solve
from mobisense.formation.replay.results import replay_dataset, replay_summary
from mobisense.formation.replay.scenario import FieldReplayScenario
from mobisense.formation.replay.simulation import build_system, simulate
from mobisense.ocp.direct.solver import solve_direct
from mobisense.ocp.direct.transcription import transcription_for
from mobisense.ocp.problem import Problem
from mobisense.ocp.simulate import integrate


@pytest.fixture(scope="module")
def solution():
    """The paper's example on a coarser grid (40 intervals: ~2 s); ε-homotopy as shipped."""
    sol = solve_direct(Problem.from_dict(hussein2008(collocation={"intervals": 40})))
    assert sol.success
    return sol


@pytest.fixture(scope="module")
def saved_solution(solution, tmp_path_factory):
    folder = tmp_path_factory.mktemp("solved")
    solution.save(folder)
    return folder / "solution.nc"


def residual(reference: ReferenceTrajectory, solution) -> np.ndarray:
    """max_t |u_ref − p_ref''| per component: both are piecewise linear, so the max is at the breakpoints."""
    t = np.union1d(solution.t, solution.t_u)
    return np.abs(reference(t)[2] - reference.acceleration(t)).max(axis=0)


@pytest.mark.slow
def test_replay_tracks_the_plan_within_the_feed_forward_residual(solution):
    """e'' + Kd e' + Kp e = u_ref − p_ref'' with Kd² = 4 Kp: the impulse response t e^{−ωt} ≥ 0 has L1 norm
    1/ω² = 1/Kp, so |e(t)| ≤ max|u_ref − p_ref''| / Kp per component (plus integrator error, 1e-8)."""
    reference, controller = ReferenceTrajectory.from_solution(solution), TrackingController(100.0, 20.0)
    times = np.linspace(0.0, 10.0, 1001)
    r, _ = simulate_tracking(reference, controller, times)
    error = np.abs(r - reference(times)[0])
    bound = residual(reference, solution) / controller.stiffness + 1e-8
    assert np.all(error <= bound)
    assert error.max() < 1e-4  # "small": the plan is flown to 1e-4 L on a 15 L path (measured ~1e-5)


def test_replay_from_an_offset_converges_as_the_critically_damped_error(solution):
    reference, controller = ReferenceTrajectory.from_solution(solution), TrackingController(100.0, 20.0)
    times = np.linspace(0.0, 3.0, 301)
    offset = np.array([[0.5, -0.3]])
    r, _ = simulate_tracking(reference, controller, times, initial_offset=offset)
    omega = np.sqrt(controller.stiffness)
    homogeneous = (
        offset[None] * ((1 + omega * times) * np.exp(-omega * times))[:, None, None]
    )  # e0 (1 + ωt) e^{−ωt}
    forced_bound = residual(reference, solution) / controller.stiffness + 1e-8
    assert np.all(np.abs(r - reference(times)[0] - homogeneous) <= forced_bound)


def test_discretisation_against_closed_forms():
    a, q, dt = -0.5, 1.3, 0.2
    F, Qd = discretise_process(np.array([[a]]), np.array([[q]]), dt)
    assert abs(F[0, 0] - np.exp(a * dt)) < 1e-15
    assert abs(Qd[0, 0] - q * (np.exp(2 * a * dt) - 1) / (2 * a)) < 1e-15
    A = np.array([[0.1, 1.0], [-0.7, -0.3]])
    BQB = np.array([[0.5, 0.1], [0.1, 0.2]])
    _, Qd2 = discretise_process(A, BQB, dt)
    from scipy.linalg import expm

    reference, _ = quad_vec(lambda s: expm(A * s) @ BQB @ expm(A * s).T, 0.0, dt, epsabs=1e-14)
    assert np.abs(Qd2 - reference).max() < 1e-13  # quadrature to 1e-14 on O(0.1) entries


def test_measurement_variances_use_the_noise_model(solution):
    problem = solution.problem
    positions = np.random.default_rng(0).normal(size=(7, 1, 2)) * 5
    r = measurement_variances(problem, positions)
    # β ρ² + γ (docs/theory/ocp.md, eq. ocp.4)
    expected = 5.0 * np.sum((positions[:, 0] - [0.0, 0.0]) ** 2, axis=-1) + 3.0
    assert r.shape == (7, 1) and np.allclose(r[:, 0], expected, rtol=1e-14, atol=0)


def riccati_along_plan(solution, times):
    """Σ(t) re-integrated by solve_ivp under the optimised control: independent of the optimiser.

    DOP853 with rtol 1e-8, far below the O(Δt) ≈ 1e-2 differences compared.
    """
    tr = transcription_for(solution.problem)
    reference = ReferenceTrajectory.from_solution(solution)
    P = tr.layout.pack(tr.layout.values(solution.problem))
    trajectory = integrate(tr.model, P, times, control=lambda t: reference(t)[2].ravel(), rtol=1e-8)
    return trajectory.x[:, :1, None]


@pytest.mark.slow
def test_sampled_filter_covariance_converges_to_the_riccati_solution_at_first_order(solution):
    reference = ReferenceTrajectory.from_solution(solution)
    errors = []
    for dt in (0.04, 0.02):
        times = np.linspace(0.0, 10.0, int(round(10 / dt)) + 1)
        Sigma = riccati_along_plan(solution, times)
        result = monte_carlo_filter(
            solution.problem, times, reference(times)[0], Sigma, 20, np.random.default_rng(0)
        )
        errors.append(np.abs(result.filter_covariance / Sigma - 1).max())
    # discrete filter with R/Δt sampling vs the Kalman-Bucy Riccati ODE: O(Δt) — halving Δt halves the error
    assert 1.8 < errors[0] / errors[1] < 2.2
    assert errors[1] < 0.01


@pytest.mark.slow
def test_monte_carlo_errors_are_consistent_with_the_optimiser_prediction(solution):
    scenario = OcpReplayScenario(
        name="t", solution="s.nc", monte_carlo={"runs": 2000, "time_step": 0.02}, seed=5
    )
    ds, summary = replay_solution(scenario, solution)
    mc = summary["monte_carlo"]
    # n = 1, B = 2000: each step's average NEES has std √(2/B) = 0.032; the time average over ~10 s with an
    # error correlation time ≳ 1 s has std ≈ 0.01: 0.05 is 5σ
    assert abs(mc["nees_filter_mean"] - 1.0) < 0.05
    assert abs(mc["nees_predicted_mean"] - 1.0) < 0.05
    # the fraction of steps inside the 95% band fluctuates with the slow error correlation: ≥ 80%
    assert mc["fraction_inside_band_predicted"] > 0.8 and mc["fraction_inside_band_filter"] > 0.8
    # delivered Tr[M E(tf)] vs promised: relative std of a variance estimate from B runs √(2/B) = 3.2%: 4σ
    assert abs(mc["terminal_cost_delivered"] / mc["terminal_cost_promised"] - 1) < 0.13
    assert ds["Sigma_predicted"].values.min() > 0
    assert np.allclose(
        ds["Sigma_predicted"].values[[0, -1]].ravel(), predicted_covariance(solution, [0.0, 10.0]).ravel()
    )


def test_load_or_solve(tmp_path):
    with pytest.raises(ConfigError, match="file not found"):
        load_or_solve(tmp_path / "missing.nc", None)
    problem = tmp_path / "p.yaml"
    problem.write_text(yaml.safe_dump(hussein2008(collocation={"intervals": 20})))
    solved, note = load_or_solve(tmp_path / "missing.nc", problem)
    assert solved.success and "solved" in note


@pytest.mark.slow
def test_cli_replays_a_solution_and_rejects_a_bad_offset(saved_solution, tmp_path, capsys):
    scenario = tmp_path / "replay.yaml"
    scenario.write_text(yaml.safe_dump({"name": "r", "solution": str(saved_solution),
                                        "monte_carlo": {"runs": 200, "time_step": 0.05}}))  # fmt: skip
    out = tmp_path / "out"
    assert main(["replay", str(scenario), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["kind"] == "ocp" and summary["tracking_error_max"] < 1e-4
    for name in ("result.nc", "paths.png", "covariance.png", "nees.png"):
        assert (out / name).stat().st_size > 0
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        yaml.safe_dump({"name": "r", "solution": str(saved_solution), "initial_offset": [[0, 0], [1, 1]]})
    )
    assert main(["replay", str(bad), "--out", str(tmp_path / "bad_out")]) == 2
    assert "initial_offset: expected 1 offsets" in capsys.readouterr().err
    assert not (tmp_path / "bad_out").exists()
    # gains whose loop no integration resolves over the plan (a fuzzer's damping 1e12 ran for minutes): refused by
    # validate and replay, nothing written; 1e4 over the 10-T plan is 1e5 time constants, the most accepted
    for damping, code in ((1e12, 2), (1.0001e4, 2)):
        bad.write_text(yaml.safe_dump({"name": "r", "solution": str(saved_solution), "tracking": {"damping": damping}}))
        for argv in (["validate", str(bad)], ["replay", str(bad), "--out", str(tmp_path / "bad_out")]):
            assert main(argv) == code
            err = capsys.readouterr().err
            assert err.count("\n") == 1 and f"{bad}: tracking.damping: the closed loop's fastest rate" in err
        assert not (tmp_path / "bad_out").exists()
    bad.write_text(yaml.safe_dump({"name": "r", "solution": str(saved_solution), "tracking": {"damping": 1e4}}))
    assert main(["validate", str(bad)]) == 0


@pytest.mark.slow
def test_formation_centre_tracks_the_optimised_path(saved_solution, solution, tmp_path):
    """OCP → control → estimation: a cross whose centre follows the plan over a quadratic field."""
    p0, v0 = solution.p[0, 0], solution.v[0, 0]
    data = {
        "name": "centre",
        "field": {"kind": "quadratic", "hessian": [[0.2, 0.05], [0.05, -0.1]], "gradient": [1, 0.5]},
        "platforms": {"count": 4, "initial": {"center": p0.tolist(), "velocity": v0.tolist()}},
        "formation": {"kind": "cross", "shape": {"a": 1.0, "b": 1.5},
                      "gains": {"stiffness": 25, "damping": 10}},
        "motion": {"kind": "reference", "solution": str(saved_solution), "stiffness": 100.0, "damping": 20.0},
        "filter": {"noise": {"sigma_process": 0.01, "sigma_measurement": 0.05}, "hessian": "fixed"},
        "duration": 10.0, "time_step": 0.05,
    }  # fmt: skip
    scenario = parse_config(data, FieldReplayScenario)
    system = build_system(scenario, tmp_path / "s.yaml")
    record = simulate(system)
    ds = replay_dataset(record, system, 0)
    summary = replay_summary(ds, record, system)
    reference = ReferenceTrajectory.from_solution(solution)
    # the centre is exactly a particle (decoupled, no limits): the same bound as for a single sensor, with
    # the integrator's error of the replay loop (rtol 1e-7 on O(10) positions) instead of 1e-8
    assert summary["reference_tracking_max"] <= np.hypot(*residual(reference, solution)[0]) / 100.0 + 1e-5
    # the filter on the exact quadratic model (known Ĥ) estimates z within 4σ of its own covariance
    assert np.all(np.abs(ds["z_est"] - ds["z_true"]) < 4 * ds["z_std"] + 1e-12)
    assert QuadraticField  # the field kind used above


def test_a_shipped_example_run_by_name_finds_the_solution_solve_wrote_by_default(tmp_path, monkeypatch):
    # after pip install the example lives in site-packages, where its ../out/hussein2008/solution.nc never is;
    # `mobisense solve hussein2008` writes out/hussein2008/solution.nc under the current folder: that one is used
    import mobisense.core.examples as examples
    from mobisense.formation.replay.plan import resolve

    installed = tmp_path / "site-packages" / "mobisense" / "problems"
    installed.mkdir(parents=True)
    scenario = installed / "replay_hussein2008.yaml"
    scenario.write_text("name: x\n")
    monkeypatch.setattr(examples, "examples_folder", lambda: installed)
    user = tmp_path / "user"
    user.mkdir()
    monkeypatch.chdir(user)
    relative = "../out/hussein2008/solution.nc"
    assert resolve(scenario, relative) == installed / relative  # nothing solved yet: the file's own path
    (user / "out" / "hussein2008").mkdir(parents=True)
    (user / "out" / "hussein2008" / "solution.nc").write_bytes(b"")
    assert resolve(scenario, relative) == Path("out/hussein2008/solution.nc")
    copied = user / "mine" / "replay_hussein2008.yaml"  # a file of the user's own keeps its own relative path
    copied.parent.mkdir()
    assert resolve(copied, relative) == copied.parent / relative


@pytest.mark.slow
def test_a_point_sensor_of_a_field_measures_where_it_flies_in_the_sampled_filter():
    # the filter froze each point sensor's kriging row at p0: replaying the shipped 5 × 5 plan it "delivered"
    # 0.797 (the no-control baseline) where the plan promised 0.278; an independent filter along the flown path
    # gave 0.2774 with the rows following the sensors (field audit)
    from short_runs import field_solution

    from mobisense.formation.replay.plan import measurement_matrices, predicted_covariance

    solution = field_solution()
    problem = solution.problem
    times = np.linspace(0.0, 5.0, 501)
    positions = ReferenceTrajectory.from_solution(solution)(times)[0]
    C = measurement_matrices(problem, positions)
    np.testing.assert_allclose(C[:, 0], problem.process.field.process().weights(positions[:, 0]), rtol=1e-14)
    assert np.linalg.norm(C[-1] - C[0]) > 0.1  # the sensor moves: its row changes
    predicted = predicted_covariance(solution, times)
    result = monte_carlo_filter(problem, times, positions, predicted, 20, np.random.default_rng(0))
    # the filter's own covariance along the flown path against the optimiser's Σ: the O(Δt) of the R/Δt
    # sampling (measured on the default problem below 1 % at Δt = 0.02) plus PCHIP between the plan's nodes
    M = problem.matrices()["M"]
    promised, delivered = np.trace(M @ predicted[-1]), np.trace(M @ result.filter_covariance[-1])
    assert abs(delivered / promised - 1) < 0.01
    frozen = monte_carlo_filter(problem, times, np.broadcast_to(positions[:1], positions.shape), predicted, 20,
                                np.random.default_rng(0))  # fmt: skip
    assert np.trace(M @ frozen.filter_covariance[-1]) > promised * (1 + 10 * abs(delivered / promised - 1))


def test_a_field_plan_saved_with_diag_sigma_only_replays_against_its_reintegrated_sigma(tmp_path):
    # a field of more than 25 states keeps diag Σ only (the shipped 10 × 10 example): its replay was refused
    # ("expected the full error covariance Σ(t), got a file written without it"). Σ(t) is re-integrated from the
    # plan by DOP853 (rtol 1e-10). The independent reference is the shooting's own Σ (Möbius-RK4, order 4): with
    # 2 substeps per interval they differ by 1.4e-6, with 8 by 5.3e-9 (= 1.4e-6 / 4⁴, the RK4 error), so 1e-8.
    from short_runs import field_solution

    from mobisense.ocp.field_plan_check import plan_covariances

    solution = field_solution(shooting={"full_sigma": False, "substeps": 8})
    np.testing.assert_allclose(plan_covariances(solution), solution.Sigma, atol=1e-8, rtol=0)
    import h5py

    solution.save(tmp_path / "diag")
    solution.stats["full_sigma"] = True  # the same plan written with its Σ, for the same replay
    solution.save(tmp_path / "full")
    for name, stored in (("diag", False), ("full", True)):
        with h5py.File(tmp_path / name / "solution.nc", "r") as f:
            assert ("Sigma" in f) is stored
    summaries = {}
    for name in ("diag", "full"):
        scenario = tmp_path / f"{name}.yaml"
        scenario.write_text(yaml.safe_dump({"name": name, "solution": f"{name}/solution.nc", "seed": 3,
                                            "monte_carlo": {"runs": 20, "time_step": 0.05}}))  # fmt: skip
        assert main(["replay", str(scenario), "--out", str(tmp_path / f"out_{name}"), "--no-plot"]) == 0
        summaries[name] = json.loads((tmp_path / f"out_{name}" / "summary.json").read_text())
    assert "Σ(t) re-integrated from its plan (the file keeps diag Σ only)" in summaries["diag"]["solution"]
    assert "re-integrated" not in summaries["full"]["solution"]
    diag, full = summaries["diag"]["monte_carlo"], summaries["full"]["monte_carlo"]
    assert diag["terminal_cost_promised"] == pytest.approx(solution.terminal_cost, rel=1e-7)
    for key, value in full.items():  # the same runs (seed 3) against Σ re-integrated or stored: the same numbers
        assert diag[key] == pytest.approx(value, rel=1e-6), key


@pytest.mark.slow
def test_a_field_plan_missing_its_solution_is_solved_by_shooting_not_direct_collocation(tmp_path, capsys):
    # replay with 'problem:' and no solution file estimated and ran a direct collocation of the field: the
    # shipped 5 × 5 was refused as needing 330 GiB; a field is solved by its own method
    from short_runs import field_problem

    (tmp_path / "field.yaml").write_text(yaml.safe_dump(field_problem(shooting={"intervals": 20,
                                                                                "coarse_intervals": 10})))  # fmt: skip
    scenario = tmp_path / "replay.yaml"
    scenario.write_text(yaml.safe_dump({"name": "r", "solution": "missing/solution.nc", "problem": "field.yaml",
                                        "monte_carlo": {"runs": 10, "time_step": 0.1}}))  # fmt: skip
    assert main(["replay", str(scenario), "--out", str(tmp_path / "out"), "--no-plot"]) == 0
    assert "solved" in capsys.readouterr().out and "by shooting" in (tmp_path / "out" / "summary.json").read_text()
