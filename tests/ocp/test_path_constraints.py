"""Path constraints (docs/theory/path_constraints.md): schema, exact re-simulation, and the direct optimum."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from reference_problems import PROBLEMS

from mobisense import cli
from mobisense.core.errors import ConfigError
from mobisense.ocp.direct.path_report import FlownPath, refine_maximum, resimulate_sensors
from mobisense.ocp.direct.solver import solve_direct
from mobisense.ocp.path_constraints import PathConstraints, margins
from mobisense.ocp.problem import Problem


def base(intervals: int = 30, **extra) -> dict:
    data = yaml.safe_load((PROBLEMS / "hussein2008.yaml").read_text())
    data["solver"]["collocation"]["intervals"] = intervals
    data.update(extra)
    return data


def test_margins_are_the_exact_distances() -> None:
    c = PathConstraints(
        keep_out=[{"center": [0.0, 0.0], "radius": 2.0}, {"polygon": [[3, -1], [5, -1], [5, 1], [3, 1]]}],
        max_speed=1.0,
        workspace={"x": [-10, 10], "y": [-10, 10]},
    )
    p = np.array([[[1.0, 0.0]], [[4.5, 0.0]], [[12.0, 0.0]]])
    v = np.array([[[3.0, 4.0]], [[0.0, 0.0]], [[0.0, 0.5]]])
    m = margins(c, p, v)
    np.testing.assert_allclose(m["keep_out[0]"], [1.0, -2.5, -10.0])
    np.testing.assert_allclose(m["keep_out[1]"], [-2.0, 0.5, -7.0])  # depth inside the square: 0.5 to the x = 5 edge
    np.testing.assert_allclose(m["max_speed"], [4.0, -1.0, -0.5])
    np.testing.assert_allclose(m["workspace"], [-9.0, -5.5, 2.0])


def test_the_separation_margin_is_the_closest_pair_at_each_time() -> None:
    # independent: scipy's pdist over every pair at each time; sizes that need one chunk of times and several
    from scipy.spatial.distance import pdist

    rng = np.random.default_rng(3)
    c = PathConstraints(min_separation=0.25)
    for T, N in ((7, 2), (5, 9), (40, 300)):  # 40 × 44 850 pair distances: two chunks of 2^20
        p = rng.uniform(-10, 10, (T, N, 2))
        expected = [0.25 - pdist(p[t]).min() for t in range(T)]
        np.testing.assert_allclose(margins(c, p, np.zeros_like(p))["min_separation"], expected, rtol=1e-14)


def test_resimulation_is_exact_for_a_constant_control() -> None:
    problem = Problem.from_dict(base())
    K, d = 7, 3
    u = np.tile(np.array([0.3, -0.2]), (K, d, 1, 1))
    t, p, v = resimulate_sensors(problem, u, "radau", d, per_interval=5)
    p0, v0 = np.array([10.0, 10.0]), np.array([0.0, -2.0])
    # double integrator under a constant control: p = p0 + v0 t + u t²/2 (rounding only)
    np.testing.assert_allclose(p[:, 0], p0 + np.outer(t, v0) + 0.5 * np.outer(t**2, [0.3, -0.2]), atol=1e-12)
    np.testing.assert_allclose(v[:, 0], v0 + np.outer(t, [0.3, -0.2]), atol=1e-12)


def test_the_flown_path_at_any_time_is_scipys_integration_of_the_control_polynomials() -> None:
    # independent: the Lagrange polynomial through each interval's 3 Radau control nodes, flown by DOP853
    from scipy.integrate import solve_ivp

    from mobisense.ocp.collocation import CollocationScheme

    problem = Problem.from_dict(base())
    K, d = 5, 3
    u = np.random.default_rng(2).normal(size=(K, d, 1, 2))
    tau = CollocationScheme("radau", d).tau[1:]

    def control(t: float) -> np.ndarray:
        k = min(int(t // 2.0), K - 1)
        s = t / 2.0 - k
        weights = [np.prod([(s - tau[m]) / (tau[j] - tau[m]) for m in range(d) if m != j]) for j in range(d)]
        return np.einsum("j,jc->c", weights, u[k, :, 0])

    times = np.sort(np.random.default_rng(3).uniform(0.0, 10.0, 50))
    flown = solve_ivp(lambda t, y: np.r_[y[2:], control(t)], (0.0, 10.0), [10.0, 10.0, 0.0, -2.0], method="DOP853",
                      t_eval=times, rtol=1e-12, atol=1e-12, max_step=0.5)  # fmt: skip
    p, v = FlownPath(problem, u, "radau", d).at(times)
    np.testing.assert_allclose(p[:, 0], flown.y[:2].T, atol=1e-9)  # DOP853 at 1e-12 over 10 time units
    np.testing.assert_allclose(v[:, 0], flown.y[2:].T, atol=1e-9)


def test_the_largest_violation_is_refined_between_the_samples_to_a_kink() -> None:
    # a tent peaking between two samples (a path grazing a corner): the samples miss it by 0.4 of a step
    peak_at, step = 0.123456789, 0.05
    t = np.arange(0.0, 1.0 + step / 2, step)

    def tent(x: np.ndarray) -> np.ndarray:
        return 1.0 - np.abs(np.asarray(x) - peak_at)

    value, when = refine_maximum(tent, t, tent(t))
    assert tent(t).max() < 1.0 - 0.02
    assert value == pytest.approx(1.0, abs=1e-9) and when == pytest.approx(peak_at, abs=1e-9)
    # two peaks, the lower sample belonging to the higher one: the candidates are searched, not only the largest sample
    def two(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x)
        return np.maximum(0.9 - 5 * np.abs(x - 0.30), 1.0 - 40 * np.abs(x - 0.7243))

    assert two(t).argmax() == 6 and refine_maximum(two, t, two(t))[0] == pytest.approx(1.0, abs=1e-8)



@pytest.mark.parametrize(
    "edit, key",
    [
        # a zone is told by its keys: a bad polygon is reported as a polygon, not as a disc missing its centre
        ({"constraints": {"keep_out": [{"polygon": [[0, 0], [2, 0], [0.5, 0.5], [0, 2]]}]}},
         "constraints.keep_out[0].polygon: expected the vertices of a strictly convex polygon"),
        ({"constraints": {"keep_out": [{"polygon": [[0, 0], [2, 0]]}]}},
         "constraints.keep_out[0].polygon: expected at least 3 vertices, got 2"),
        ({"constraints": {"keep_out": [{"center": [1.0, 1.0]}]}}, "constraints.keep_out[0].radius: required key"),
        ({"constraints": {"keep_out": ["disc"]}}, "constraints.keep_out[0]: expected a disc {center: [x, y], radius: "
                                                  "r} or a convex polygon {polygon: [[x, y], …]}, got 'disc'"),
        ({"constraints": {"keep_out": [{"polygon": [[0, 0], [2, 0], [0, 2]], "radius": 1.0}]}},
         "constraints.keep_out[0]: expected a disc {center: [x, y], radius: r} or a convex polygon"),
        ({"constraints": {"keep_out": [{"center": [10.0, 10.0], "radius": 1.0}]}}, "sensors[0].p0"),
        ({"constraints": {"max_speed": 1.0}}, "sensors[0].v0"),
        ({"constraints": {"min_separation": 1.0}}, "constraints.min_separation: expected at least two sensors"),
        # fixed end states no path can reach: refused when read (Ipopt blamed a continuity row, exit 1)
        ({"constraints": {"keep_out": [{"center": [2.0, -2.0], "radius": 1.0}]}, "terminal": {"p": [2.0, -2.0]}},
         "sensors[0].terminal.p: expected a terminal position satisfying constraints.keep_out[0]"),
        ({"constraints": {"workspace": {"x": [-5, 15], "y": [-5, 15]}}, "terminal": {"p": [20.0, 0.0]}},
         "sensors[0].terminal.p: expected a terminal position satisfying constraints.workspace (violated by 5)"),
        ({"constraints": {"max_speed": 2.5}, "terminal": {"v": [3.0, 0.0]}},
         "sensors[0].terminal.v: expected a terminal speed within constraints.max_speed 2.5, got 3"),
        ({"constraints": {"workspace": {"x": [1, 0], "y": [0, 1]}}}, "constraints.workspace.x"),
        ({"constraints": {"workspace": {"x": [-2, 5, 6], "y": [0, 1]}}},
         "constraints.workspace.x: expected at most 2 items, not 3 (got [-2, 5, 6]"),  # was pydantic's own words
        ({"constraints": {"workspace": {"x": [-2, 12], "y": [0]}}}, "constraints.workspace.y: expected at least 2 "
                                                                   "items, not 1"),
        ({"constraints": {"max_speed": 3.0}, "solver": {"method": "indirect"}}, "constraints"),
        # hostile sizes and repeats (a fuzzer's: 2000 copies of a disc through a YAML anchor ran for minutes)
        ({"constraints": {"keep_out": [{"center": [50.0 + k, 50.0], "radius": 0.1} for k in range(101)]}},
         "constraints.keep_out: expected at most 100 zones"),
        ({"constraints": {"keep_out": [{"polygon": [[50 + float(np.cos(a)), 50 + float(np.sin(a))]
                                                    for a in np.linspace(0, 6.2, 65)]}]}},
         "constraints.keep_out[0].polygon: expected at most 64 vertices, got 65"),
        ({"constraints": {"keep_out": [{"center": [6.5, 4.5], "radius": 2.0}] * 2}},
         "constraints.keep_out[1]: repeats keep_out[0]"),
        ({"constraints": {"keep_out": [{"center": [6.5, 4.5], "radius": 2.0}, {"center": [6.5, 4.5], "radius": 2}]}},
         "constraints.keep_out[1]: repeats keep_out[0]"),  # 2 and 2.0 are one radius (was reported as keep_out[1])
    ],
)
def test_bad_constraints_exit_2_with_the_key_path(tmp_path, capsys, edit, key) -> None:
    data = base()
    solver = edit.pop("solver", None)
    if "terminal" in edit:
        data["sensors"][0]["terminal"] = edit.pop("terminal")
    data.update(edit)
    if solver:
        data["solver"].update(solver)
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump(data))
    out = tmp_path / "out"
    assert cli.main(["solve", str(path), "--out", str(out)]) == 2
    assert key in capsys.readouterr().err
    assert not out.exists()


def test_sensors_too_close_at_the_start_are_named_as_the_closest_pair() -> None:
    data = base(constraints={"min_separation": 1.0})
    sensor = data["sensors"][0]
    data["sensors"] = [{**sensor, "name": name, "p0": p0} for name, p0 in
                       (("a", [10.0, 10.0]), ("b", [-1.0, 11.0]), ("c", [-1.0, 10.5]))]  # fmt: skip
    with pytest.raises(ConfigError, match=r"sensors\[2\]\.p0: expected an initial position at least "
                       r"constraints\.min_separation 1 from sensor 1's, got 0\.5$"):  # fmt: skip
        Problem.from_dict(data, source="p.yaml")


@pytest.mark.slow
def test_a_disc_across_the_path_is_skirted_tangentially_and_costs_more() -> None:
    free = solve_direct(Problem.from_dict(base()))
    mid = free.p[len(free.t) // 2, 0]
    radius = 1.0
    data = base(constraints={"keep_out": [{"center": mid.tolist(), "radius": radius}]})
    solution = solve_direct(Problem.from_dict(data))
    assert solution.success
    report = solution.stats["constraints"]["keep_out[0]"]
    assert report["active"] and report["max_multiplier"] > 0
    assert report["units"] == solution.problem.units.system().of(length=1)  # as solution.nc's p (UDUNITS)
    dist = np.linalg.norm(solution.p[:, 0] - mid, axis=1)
    # at the nodes the constraint holds to Ipopt's tolerance (1e-9 on scaled rows of size L²·1e-9)
    assert dist.min() >= radius - 1e-6
    # tangent where active: at the closest node the velocity is perpendicular to the radius (|cos| ≤ 0.05:
    # the node spacing h = 1/3 T lets the contact point sit between nodes)
    j = int(np.argmin(dist))
    radial = (solution.p[j, 0] - mid) / dist[j]
    assert abs(radial @ solution.v[j, 0]) / np.linalg.norm(solution.v[j, 0]) < 0.05
    assert solution.cost >= free.cost * (1 - 1e-9)  # a subset of the feasible set cannot cost less
    # between the nodes the re-simulated path may cut the arc by O(h² |v|²/r): a few mm here
    assert report["max_violation"] < 0.02 * radius


@pytest.mark.slow
def test_separation_holds_for_two_sensors_converging_and_inactive_multipliers_vanish() -> None:
    data = yaml.safe_load((PROBLEMS / "separation.yaml").read_text())
    data["solver"]["collocation"]["intervals"] = 30
    free_data = {**data, "constraints": None}
    free = solve_direct(Problem.from_dict(free_data))
    gap_free = np.linalg.norm(free.p[:, 0] - free.p[:, 1], axis=1).min()
    assert gap_free < 1.0  # unconstrained, the two sensors close in on the process
    solution = solve_direct(Problem.from_dict(data))
    assert solution.success
    gap = np.linalg.norm(solution.p[:, 0] - solution.p[:, 1], axis=1)
    assert gap.min() >= 1.5 - 1e-6
    assert solution.cost >= free.cost
    nlp = solution.nlp
    from mobisense.ocp.direct.transcription import transcription_for

    tr = transcription_for(solution.problem)
    k = tr.kernels
    _, p_nodes, v_nodes = tr.structure.state.split(tr.unpack(nlp["w"], nlp["P"])["xc"].reshape(-1, tr.structure.nx))
    rows = margins(solution.problem.constraints, p_nodes, v_nodes)["min_separation"]  # one row per node
    lam = nlp["lam_g"][: tr.intervals * k.nr].reshape(tr.intervals, k.nr)[:, k.nr - k.n_cons :].ravel()
    inactive = rows < -0.1  # at least 0.1 L from the bound
    assert inactive.any() and (~inactive).any()
    # complementarity λ|g| ≈ μ ≤ 1e-9 at Ipopt's tol: 0.1 L away (|g| ≳ 0.1 scaled) λ ≤ 1e-8, ≤ 1e-6 of the active
    assert np.abs(lam[inactive]).max() <= 1e-6 * np.abs(lam).max()
    assert (lam[~inactive] >= -1e-12).all()


def test_u_max_holds_between_the_nodes_where_the_control_polynomial_swings() -> None:
    # the shipped rendezvous on a coarse grid: bounding |u| at the nodes alone let the Radau control polynomial
    # reach |u| = 1.92 against u_max = 1.0 between them (K = 50); the bound on its Bernstein coefficients holds it
    # on the whole interval (the polynomial is their convex combination)
    data = yaml.safe_load((PROBLEMS / "terminal_and_bound.yaml").read_text())
    data["sensors"][0]["u_max"] = 1.0
    data["solver"]["collocation"]["intervals"] = 50
    solution = solve_direct(Problem.from_dict(data))
    assert solution.success, solution.message
    scheme, d, K = solution.collocation
    import casadi as ca

    nodes = np.asarray(ca.collocation_points(d, scheme))
    s = np.linspace(0.0, 1.0, 401)  # each interval's polynomial, evaluated here from the node values
    basis = np.array([np.prod([(s - nodes[r]) / (nodes[j] - nodes[r]) for r in range(d) if r != j], axis=0)
                      for j in range(d)])  # fmt: skip
    u = np.einsum("js,kjc->ksc", basis, solution.u.reshape(K, d, 2))
    # Ipopt's tolerance: the scaled row (|c|² − u_max²)/u_scale² ≥ −1e-9·… leaves |u| within 1e-6 of the bound
    assert np.linalg.norm(u, axis=-1).max() <= 1.0 + 1e-6
    report = solution.stats["constraints"]["u_max"]
    assert report["active"] and report["max_violation"] <= 1e-6 and report["units"] == "m s-2"


def test_a_binding_speed_limit_is_reported_active() -> None:
    # an interior-point optimum keeps a slack of 2e-6…9e-6 on a binding row with a small multiplier: the
    # multiplier, not the slack alone, says it binds (J rises from 15.84777 to 15.86493 with it)
    data = yaml.safe_load((PROBLEMS / "hussein2008.yaml").read_text())
    data["solver"]["collocation"]["intervals"] = 40
    free = solve_direct(Problem.from_dict(data))
    for limit, binding in ((2.2, True), (10.0, False)):
        data["constraints"] = {"max_speed": limit}
        solution = solve_direct(Problem.from_dict(data))
        report = solution.stats["constraints"]["max_speed"]
        assert report["active"] is binding, (limit, report)
        assert (solution.cost > free.cost * (1 + 1e-4)) is binding


def test_a_baseline_that_crosses_a_zone_or_leaves_the_workspace_is_infeasible() -> None:
    # coasting is a straight line p0 + v0 t: keep_out.yaml's sensor (p0 = (10, 10), v0 = (0, -2)) ends at
    # y = -10 at t = 10, 8 L below the workspace's y_min = -2; no improvement may be quoted against it
    data = yaml.safe_load((PROBLEMS / "keep_out.yaml").read_text())
    violations = Problem.from_dict(data).coasting_violations()
    assert any(v.startswith("constraints.workspace: coasting violates it by 8 at t = 10") for v in violations)
    # a disc of radius 1 centred on that line at (10, 0) (reached at t = 5): penetration depth 1
    data["constraints"] = {"keep_out": [{"center": [10.0, 0.0], "radius": 1.0}]}
    crossing = ["constraints.keep_out[0]: coasting violates it by 1 at t = 5"]
    assert Problem.from_dict(data).coasting_violations() == crossing
    data["constraints"] = {"keep_out": [{"center": [13.0, 0.0], "radius": 1.0}]}  # 3 L beside the line: clear
    assert Problem.from_dict(data).coasting_violations() == []


@pytest.mark.slow
def test_a_plan_whose_flown_path_breaks_a_constraint_between_the_nodes_is_reported_so() -> None:
    # a start on a disc's edge heading to its centre at the speed limit: no path stays out (it would need an
    # infinite deceleration), yet the NLP, holding the disc at the nodes only, converges ("solved"); flown, its
    # controls enter the disc by 3.4 cm at the first node (the audit's re-integration with scipy: 0.03398)
    data = base(intervals=40, constraints={"keep_out": [{"center": [10.0, 8.5], "radius": 1.5}], "max_speed": 2.0})
    data["solver"]["strategy"] = "cold"
    solution = solve_direct(Problem.from_dict(data))
    assert solution.success
    entry = solution.stats["constraints"]["keep_out[0]"]
    assert entry["max_violation_at_nodes"] < 1e-5 and entry["max_violation"] > 0.01 * 1.5
    warning = solution.summary()["warning"]
    assert "the plan's controls, flown, break keep_out[0] by" in warning and "K = 40 intervals" in warning
    # the shipped example's flown path keeps its constraints within 1e-4 of their sizes: no warning
    clear = solve_direct(Problem.from_dict(yaml.safe_load((PROBLEMS / "keep_out.yaml").read_text())))
    assert "warning" not in clear.summary()


def _default_with(**sensor) -> dict:
    data = yaml.safe_load((PROBLEMS / "hussein2008.yaml").read_text())
    data["solver"]["collocation"]["intervals"] = 40
    data["sensors"][0].update(sensor)
    return data


def test_a_terminal_state_out_of_reach_is_refused_naming_it_and_one_just_within_reach_is_solved() -> None:
    # first-hour audit: p = (100, 100) with u_max = 0.5 in 10 T ran 6 starts for 17 s to "Infeasible_Problem_Detected
    # … continuity of sensor s1 velocity y at t = 0.1"; necessary conditions now refuse it when the file is read
    coast = np.array([10.0, 10.0]) + 10.0 * np.array([0.0, -2.0])  # p0 + v0 (tf − t0) of the default sensor
    reach = 0.5 * 0.5 * 10.0**2  # u_max (tf − t0)² / 2 = 25
    far = (coast + 1.01 * reach * np.array([0.6, 0.8])).tolist()
    with pytest.raises(ConfigError, match=r"sensors\[0\]\.terminal\.p: expected a position reachable with \|u\|"):
        Problem.from_dict(_default_with(terminal={"p": far}, u_max=0.5))
    with pytest.raises(ConfigError, match=r"sensors\[0\]\.terminal\.v: expected a velocity reachable"):
        Problem.from_dict(_default_with(terminal={"v": [0.0, 3.1]}, u_max=0.5))  # |Δv| = 5.1 > u_max T = 5
    with pytest.raises(ConfigError, match=r"sensors\[0\]\.terminal\.p: expected a position reachable under "
                                          r"constraints\.max_speed"):  # fmt: skip
        Problem.from_dict({**_default_with(terminal={"p": [10.0, -21.0]}), "constraints": {"max_speed": 3.0}})
    # 95 % of the reach: a constant push gets there (u = u_max toward it), so the NLP is feasible and solved
    near = (coast + 0.95 * reach * np.array([0.6, 0.8])).tolist()
    solution = solve_direct(Problem.from_dict(_default_with(terminal={"p": near}, u_max=0.5)))
    assert solution.success, solution.message
    assert np.allclose(solution.p[-1, 0], near, atol=1e-6)
    assert np.linalg.norm(solution.u, axis=-1).max() <= 0.5 * (1 + 1e-6)
