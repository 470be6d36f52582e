"""Field processes, point sensors and the reduced-space shooting method (docs/theory/field.md).

Independent references: the stationary Lyapunov equation, the kriging identity at the nodes, scipy's
DOP853 on the full Riccati equation, central finite differences, and the direct collocation.
"""

from __future__ import annotations

import re

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from short_runs import field_problem, field_solution

import mobisense as ms
from mobisense.core.config import ConfigError
from mobisense.ocp.field import FieldSpec
from mobisense.ocp.shooting import FieldShooting
from mobisense.ocp.solution import StartKind


def _spec(grid=(3, 3), kernel="matern32", length=3.0):
    return FieldSpec(grid=list(grid), extent=[[0.0, 10.0], [0.0, 10.0]], time_constant=20.0,
                     kernel={"type": kernel, "length_scale": length, "variance": 1.0})  # fmt: skip


def _problem(**changes):
    data = field_problem(**changes.pop("solver", {}))
    data.update(changes)
    return ms.Problem.from_dict(data)


@pytest.mark.parametrize("kernel", ["matern32", "squared_exponential", "exponential"])
def test_field_matrices_make_the_kernel_the_stationary_covariance(kernel):
    m = _spec(kernel=kernel).process().matrices()
    residual = m["A"] @ m["Sigma0"] + m["Sigma0"] @ m["A"].T + m["B"] @ m["Q"] @ m["B"].T
    assert np.abs(residual).max() < 1e-15  # exact up to rounding of entries <= 1/τ·σ²


def test_jitter_is_raised_until_the_squared_exponential_kernel_is_well_conditioned():
    process = _spec(grid=(10, 10), kernel="squared_exponential").process()
    assert process.jitter_used > 1e-8  # measured: cond 3.5e9 at 1e-8
    assert np.linalg.cond(process.Ks) <= 1e8 * (1 + 1e-6)


def test_kriging_rows_are_exact_at_the_nodes_and_match_the_symbolic_form():
    process = _spec().process()
    # c(s_j) = e_j up to the jitter 1e-8 σ² times ‖Kₛ⁻¹‖ (λ_min ≈ 0.07 on 3×3: ≲ 1e-6)
    assert np.abs(process.weights(process.locations) - np.eye(9)).max() < 1e-6
    p = ca.SX.sym("p", 2)
    c = ca.Function("c", [p], [process.symbolic_weights(p, ca.DM(process.Ks_inv), ca.DM(process.locations))])
    for point in ([1.3, 7.1], [5.0, 5.0], list(process.locations[4])):
        assert np.allclose(np.asarray(c(point)).ravel(), process.weights(np.array([point]))[0], atol=1e-14)
    jac = ca.Function("j", [p], [ca.jacobian(c(p), p)])(process.locations[4])
    assert np.all(np.isfinite(np.asarray(jac)))  # the smoothing δ removes the 0/0 at a node


def test_nothing_measured_keeps_the_stationary_prior():
    problem = _problem(sensors=[{"name": "far", "p0": [900.0, 900.0], "v0": [0, 0], "measures": "point",
                                 "noise": {"model": "constant", "variance_value": 0.1}}])  # fmt: skip
    shooting = FieldShooting(problem, 10)
    Sigma = shooting.evaluate(np.zeros(shooting.nw)).Sigma
    Ks = problem.process.field.process().Ks
    assert np.abs(Sigma - Ks).max() < 1e-12  # beyond the cut-off the rows are 1e-20σ²: Σ' = 0 to rounding


def test_the_plan_check_of_a_field_solution_is_an_independent_integration():
    """summary.json's plan_check of a shooting solution: its controls re-integrated by scipy's DOP853 in numpy."""
    far = _problem(sensors=[{"name": "far", "p0": [900.0, 900.0], "v0": [0, 0], "measures": "point",
                             "noise": {"model": "constant", "variance_value": 0.1}}])  # fmt: skip
    solution = ms.solve(far)  # nothing to measure: Σ stays Kₛ whatever the plan, J = Tr[M Kₛ] + α/2 ∫|u|²
    check = solution.stats["plan_check"]
    mats = far.matrices()
    exact = float(np.trace(mats["M"] @ mats["Sigma0"])) + solution.control_energy
    assert check["integrator"].startswith("DOP853") and check["cost"] == pytest.approx(exact, rel=1e-10)
    # on a plan that measures, the difference is the shooting's own error: one RK4 step per interval, order 4,
    # so doubling K divides it by ≳ 16 (measured 2.0e-5 → 5.9e-7 → 2.3e-8 at K = 10, 20, 40: the optimal plans
    # change with K too) — the check is not the shooting's integration again
    differences = []
    for K in (10, 20):
        coarse = ms.solve(_problem(solver={"shooting": {"intervals": K, "substeps": 1, "coarse_intervals": 10}}))
        differences.append(abs(coarse.stats["plan_check"]["relative_difference"]))
    assert differences[0] > 1e-9 and differences[0] / differences[1] > 8, differences


def _cubic_positions(problem, t_nodes, u):
    """p(t) of the exact double integrator with piecewise-linear u (independent of eq. field.7)."""
    p0 = np.array([s.p0 for s in problem.sensors], float)
    v0 = np.array([s.v0 for s in problem.sensors], float)
    h = t_nodes[1] - t_nodes[0]
    ps, vs = [p0], [v0]
    for k in range(len(t_nodes) - 1):
        ps.append(ps[-1] + h * vs[-1] + h**2 * (u[k] / 3 + u[k + 1] / 6))
        vs.append(vs[-1] + h * (u[k] + u[k + 1]) / 2)

    def at(t):
        k = min(int((t - t_nodes[0]) / h), len(t_nodes) - 2)
        s = t - t_nodes[k]
        return ps[k] + vs[k] * s + u[k] * s**2 / 2 + (u[k + 1] - u[k]) * s**3 / (6 * h)

    return at


def test_mobius_rk4_matches_dop853_at_order_four():
    problem = _problem(sensors=[{"name": f"g{i}", "p0": [0.5 + i, 0.5], "v0": [0.1, 0.2], "measures": "point",
                                 "noise": {"model": "constant", "variance_value": 0.05}} for i in range(2)])
    process, mats = problem.process.field.process(), problem.matrices()
    rng = np.random.default_rng(3)
    K = 20
    u = 0.3 * rng.standard_normal((K + 1, 2, 2))
    t_nodes = np.linspace(0.0, 5.0, K + 1)
    at = _cubic_positions(problem, t_nodes, u)

    def riccati(t, y):  # eq. ocp.7 with eq. field.4
        S = y.reshape(4, 4)
        C = process.weights(at(t))
        return (mats["A"] @ S + S @ mats["A"].T + mats["BQB"] - S @ C.T @ C @ S / 0.05).ravel()

    ref = solve_ivp(riccati, (0, 5), mats["Sigma0"].ravel(), method="DOP853", rtol=1e-12, atol=1e-14,
                    max_step=5.0 / K / 4).y[:, -1].reshape(4, 4)  # fmt: skip
    errors = []
    for m in (1, 2, 4):
        shooting = FieldShooting(problem, K, substeps=m)
        w = shooting.controls_to_w(t_nodes, u, 1.0)
        errors.append(np.abs(shooting.evaluate(w).Sigma[-1] - ref).max())
    # measured 5.6e-6, 3.7e-7, 2.3e-8 (|Σ| ≤ 1; step 0.25/m with r = 0.05, twice the defaults' stiffness)
    assert errors[1] < 1e-6
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert orders.min() > 3.5, (errors, orders)  # RK4: 4


def test_gradient_is_the_exact_discrete_adjoint():
    problem = _problem(sensors=[{"name": "g", "p0": [0.5, 0.5], "v0": [0, 0], "measures": "point",
                                 "noise": {"model": "constant", "variance_value": 0.1}}])  # fmt: skip
    shooting = FieldShooting(problem, 10)
    f = ca.Function("f", [shooting.nlp["x"], shooting.nlp["p"]], [shooting.nlp["f"]])
    grad = ca.Function("g", [shooting.nlp["x"], shooting.nlp["p"]], [ca.gradient(shooting.nlp["f"], shooting.nlp["x"])])
    P = shooting.parameters(0.7, 1.0)
    rng = np.random.default_rng(0)
    w, d = rng.standard_normal(shooting.nw), rng.standard_normal(shooting.nw)
    step = 1e-5  # central difference: truncation O(step²) ~ 1e-10, rounding ~ 1e-16/step ~ 1e-11
    fd = (float(f(w + step * d, P)) - float(f(w - step * d, P))) / (2 * step)
    assert float(ca.dot(grad(w, P), d)) == pytest.approx(fd, rel=1e-7)


def test_schema_refuses_inconsistent_field_files():
    data = field_problem()
    bad = {**data, "process": {**data["process"], "A": [[1.0]]}}
    with pytest.raises(ConfigError, match="process.A"):
        ms.Problem.from_dict(bad)
    point_without_field = ms.Problem.from_dict({**data, "solver": {"method": "direct"}})  # accepted
    assert point_without_field.solver.method == "direct"
    with pytest.raises(ConfigError, match="shooting"):
        ms.Problem.from_dict(field_problem(grid=(4, 4), method="direct"))
    with pytest.raises(ConfigError, match="constant"):
        noisy = field_problem()
        noisy["sensors"][0]["noise"] = {"model": "quadratic_range", "beta": 1.0, "gamma": 1.0}
        ms.Problem.from_dict(noisy)
    assert ms.Problem.from_dict(field_problem()).solver.method == "shooting"  # the default for a field
    fixed = field_problem()  # a fixed row was measured as a point sensor: J 27 % below the file's model (audit)
    fixed["sensors"][0]["measures"] = [[1.0] + [0.0] * 8]
    with pytest.raises(ConfigError, match=r"sensors\[0\]\.measures: expected 'point' with method 'shooting'"):
        ms.Problem.from_dict(fixed)
    zoned = {**field_problem(), "constraints": {"max_speed": 2.0}}  # the shooting method holds path constraints
    assert ms.Problem.from_dict(zoned).solver.method == "shooting"
    with pytest.raises(ConfigError, match=r"constraints: .* 'indirect': the indirect method has no state-constrained"):
        ms.Problem.from_dict({**zoned, "solver": {"method": "indirect"}})


def _zoned_field(method: str, intervals: int) -> dict:
    """One sensor on the 2 × 2 field whose free path runs up the diagonal, past a disc and under a speed limit."""
    data = field_problem(grid=(2, 2), sensors=1, method=method, collocation={"intervals": intervals},
                         shooting={"intervals": intervals, "coarse_intervals": 10})  # fmt: skip
    if method == "shooting":
        del data["solver"]["collocation"]
    else:
        del data["solver"]["shooting"]
    data["constraints"] = {"keep_out": [{"center": [1.7, 1.4], "radius": 0.5}], "max_speed": 0.6}
    return data


@pytest.mark.slow
def test_path_constraints_on_a_field_match_the_direct_method_and_hold_between_the_nodes():
    # independent computation: the same 4-state problem by direct collocation (which holds the constraints at its
    # Radau nodes, by other code); the free path goes through the disc (diagonal from (0.5, 0.5) to (2.6, 2.6))
    shot = ms.solve(ms.Problem.from_dict(_zoned_field("shooting", 80)))
    direct = ms.solve(ms.Problem.from_dict(_zoned_field("direct", 80)))
    assert shot.success and direct.success
    free = ms.solve(ms.Problem.from_dict({**_zoned_field("shooting", 80), "constraints": None}))
    assert shot.cost > free.cost * 1.02  # the constraints bind: 0.35498 against 0.34331
    # measured 1.7e-8; each method's own change from K = 80 to 160: shooting 1e-8, direct 8.4e-7
    assert shot.cost == pytest.approx(direct.cost, rel=2e-6)
    report = shot.stats["constraints"]
    assert report["keep_out[0]"]["active"] and report["max_speed"]["active"]
    # on the flown path (exact between the nodes): within 1e-4 of the radius and of v_max (measured 3.4e-5, 1.2e-6)
    assert report["keep_out[0]"]["max_violation"] < 1e-4 and report["max_speed"]["max_violation"] < 1e-4
    from scipy.integrate import solve_ivp

    t = shot.t_u  # the controls are linear between the nodes: integrate them independently and measure the margins
    u = shot.u[:, 0]

    def rhs(time: float, y: np.ndarray) -> np.ndarray:
        return np.r_[y[2:], [np.interp(time, t, u[:, c]) for c in range(2)]]

    fine = np.linspace(t[0], t[-1], 4001)
    y = solve_ivp(rhs, (t[0], t[-1]), np.r_[0.5, 0.5, 0.0, 0.0], t_eval=fine, rtol=1e-11, atol=1e-12,
                  max_step=(t[1] - t[0]) / 4).y  # fmt: skip
    depth = 0.5 - np.hypot(y[0] - 1.7, y[1] - 1.4)
    speed = np.hypot(y[2], y[3]) - 0.6
    # the report's refined maxima bound the sampled ones of the independent integration (to its 1e-9 error)
    assert depth.max() <= report["keep_out[0]"]["max_violation"] + 1e-9
    assert speed.max() <= report["max_speed"]["max_violation"] + 1e-9
    assert depth.max() > report["keep_out[0]"]["max_violation"] - 1e-5  # and are found: 4000 samples come close


@pytest.mark.slow
def test_a_field_plan_that_cannot_keep_its_constraints_reports_the_worst_one_in_its_units():
    # a speed limit that the target is within (4.24 L ≤ v_max T = 4.5) but not under |u| ≤ 0.5 from rest (≈ 3.7):
    # Ipopt fails, the worst row is named in problem terms and sized in its own quantity, as the direct method does
    # (measured: |u| ≤ u_max at t = 0.5, 0.93 over)
    data = field_problem(shooting={"intervals": 20, "coarse_intervals": 10})
    data["sensors"][0].update(terminal={"p": [3.5, 3.5]}, u_max=0.5)
    data["constraints"] = {"max_speed": 0.9}
    solution = ms.solve(ms.Problem.from_dict(data))
    assert not solution.success
    _check_worst_violation(solution, u_max=0.5, v_max=0.9, p_end=[3.5, 3.5])


@pytest.mark.slow
def test_a_control_bound_that_does_not_bind_neither_fails_the_solve_nor_moves_the_optimum():
    # first-hour audit: on a 3 × 3 field (largest |u| 0.37 unbounded) u_max = 0.5, 1 and 10 each ran Ipopt to its
    # iteration limit (exit 1, J up to 4× the optimum and above the no-control baseline): the row was
    # (|u|² − u_max²)/u_scale², far from 1 where u_max ≫ u_scale; now |u|²/u_max² − 1
    base = field_problem(grid=(3, 3), sensors=2, shooting={"intervals": 40, "coarse_intervals": 10})
    base["horizon"]["tf"] = 20.0
    base["process"]["field"].update(extent=[[0, 10], [0, 10]], time_constant=20.0)
    base["solver"]["tolerance"] = 1e-8
    free = ms.solve(ms.Problem.from_dict(base))
    assert free.success and np.linalg.norm(free.u, axis=2).max() < 0.4
    for u_max in (0.5, 1.0, 10.0):
        data = {**base, "sensors": [{**s, "u_max": u_max} for s in base["sensors"]]}
        cold = ms.solve(ms.Problem.from_dict(data))
        assert cold.success and cold.cost < cold.baseline["cost"] and "worst_violation" not in cold.stats
        assert np.linalg.norm(cold.u, axis=2).max() <= u_max * (1 + 1e-8)
        warm = ms.solve(ms.Problem.from_dict(data), init=free)  # from the unbounded optimum, where no bound binds
        assert warm.success and warm.cost <= free.cost * (1 + 1e-9)  # measured −6e-12, −2.5e-3, −1e-12


@pytest.mark.slow
def test_an_inactive_control_bound_does_not_move_the_coarse_homotopy_into_another_basin():
    # random-problem audit: on this 2 × 3 field the unbounded optimum uses |u| ≤ 2.0, yet with u_max = 5 the coarse
    # homotopy (holding the bound's rows) found another basin, J 7.6008 "solved", 19 % above 6.3788; u_max = 100
    # failed. The coarse steps now leave the bound to the fine solve
    data = {"name": "m1", "horizon": {"t0": 0.0, "tf": 10.1106},
            "process": {"field": {"grid": [2, 3], "extent": [[-1.3842, 7.6041], [-4.0737, 0.3366]],
                                  "kernel": {"type": "squared_exponential", "length_scale": 0.9886,
                                             "variance": 1.8082}, "time_constant": 12.603}},
            "sensors": [{"name": "g1", "p0": [0.8866, -1.7331], "v0": [-0.288, -0.3112], "measures": "point",
                         "noise": {"model": "constant", "variance_value": 0.7535}}],
            "cost": {"M": "sum", "K": "zero", "alpha": 0.0558},
            "solver": {"method": "shooting", "shooting": {"intervals": 87}}}  # fmt: skip
    free = ms.solve(ms.Problem.from_dict(data))
    assert free.success and np.linalg.norm(free.u, axis=2).max() < 2.1
    for u_max in (5.0, 100.0):
        data["sensors"][0]["u_max"] = u_max
        bounded = ms.solve(ms.Problem.from_dict(data))
        assert bounded.success
        assert bounded.cost == pytest.approx(free.cost, rel=1e-8)  # measured 2e-14 and 1e-14


def test_terminal_position_and_control_bound_hold():
    data = field_problem(shooting={"intervals": 20, "coarse_intervals": 10})
    data["sensors"][0].update(terminal={"p": [3.0, 3.0], "v": [0.0, 0.0]}, u_max=0.8)
    solution = ms.solve(ms.Problem.from_dict(data))
    assert solution.success
    assert np.abs(solution.p[-1, 0] - [3.0, 3.0]).max() < 1e-8  # linear equality constraints, Ipopt tol 1e-10
    assert np.abs(solution.v[-1, 0]).max() < 1e-8
    assert np.linalg.norm(solution.u[:, 0], axis=1).max() <= 0.8 * (1 + 1e-6)
    # the summary's u_max group (it had none for a shooting solution, though path_constraints.md §3 promises it):
    # |u| is convex between the nodes of piecewise-linear controls, so the nodes' largest |u| − u_max is the path's
    report = solution.stats["constraints"]["u_max"]
    excess = np.linalg.norm(solution.u[:, 0], axis=1) - 0.8
    assert report["max_violation"] == pytest.approx(excess.max(), abs=1e-15)
    assert report["max_violation_time"] == solution.t_u[np.argmax(excess)]
    assert report["units"] == "m s-2"  # the problem's acceleration unit (UDUNITS)
    # the bound binds (the price of the largest row is positive), and no single row's price exceeds the total, the
    # central difference of J in u_max (h = 1e-4: O(h²) ≈ 1e-8 relative, far below the 0.0087 against 0.0217 measured)
    assert report["active"] and report["max_multiplier"] > 0
    costs = []
    for u_max in (0.8 - 1e-4, 0.8 + 1e-4):
        data["sensors"][0]["u_max"] = u_max
        costs.append(ms.solve(ms.Problem.from_dict(data)).cost)
    assert report["max_multiplier"] <= -(costs[1] - costs[0]) / 2e-4


def test_homotopy_costs_are_those_of_the_direct_method():
    """summary.json's homotopy costs are J_ε of eq. direct.9 (Φ + E/ε) for every method, not eq. field.8's ε Φ + E.

    The optimal Φ + E/ε cannot increase with ε (every plan's does not), while ε Φ + E of the same plans
    grows with ε: at the shooting's coarse steps (one grid, Ipopt tolerance 1e-6 relative) the reported costs
    must not increase (they did, 0.0134 at ε = 0.03 against 0.30 at ε = 1, before)."""
    solution = ms.solve(_problem(solver={"shooting": {"intervals": 20, "coarse_intervals": 10}}))
    coarse = [s.cost for s in solution.homotopy[:-1]]  # the coarse grid's ε steps; the last is the fine solve
    assert len(coarse) >= 3 and all(b <= a * (1 + 1e-6) for a, b in zip(coarse, coarse[1:], strict=False))
    assert coarse[0] > solution.cost


@pytest.mark.slow
def test_shooting_agrees_with_the_direct_collocation():
    # n = 4, N = 1. Collocation (Radau-3) at K = 40 against shooting at K = 200 (its error ~ 1e-10 at the
    # measured order 4): the gap is the collocation's discretisation error, measured 2.0e-8 relative (K = 20:
    # 6.5e-7, an observed order 5); both start cold with their default strategies and reach the same optimum.
    direct = ms.solve(_problem(solver={"method": "direct", "collocation": {"intervals": 40}}))
    shooting = ms.solve(_problem(solver={"shooting": {"intervals": 200}}))
    assert direct.success and shooting.success
    assert shooting.cost == pytest.approx(direct.cost, rel=1e-7)
    assert np.abs(shooting.p[-1] - direct.p[-1]).max() < 1e-3


@pytest.mark.slow
def test_cost_converges_at_order_four_under_refinement():
    # one RK4 step per interval at every K (the default substeps change with K and would mix two errors)
    ref = ms.solve(_problem(solver={"shooting": {"intervals": 320, "substeps": 1}}))
    costs = []
    for K in (10, 20, 40):
        costs.append(ms.solve(_problem(solver={"shooting": {"intervals": K, "substeps": 1}}), init=ref).cost)
    errors = np.abs(np.array(costs) - ref.cost)
    orders = np.log2(errors[:-1] / errors[1:])
    assert orders.min() > 3.5, (costs, orders)  # docs/theory/field.md §3.3: stated order 4


def test_the_key_named_for_too_many_substeps_is_the_larger_term_of_the_rate():
    # λ_max² = a² + 2aσ²/r with a = 1/τ = 1000 and r = 1e-3: 1e6 + 2e6, the measurement term is the larger (2×),
    # so the noise variance is named, not the time constant; K = 2 on 5 T: m = ceil(2.5 · 1732 / 0.25) = 17321
    data = field_problem(shooting={"intervals": 2})
    data["process"]["field"]["time_constant"] = 1e-3
    data["sensors"][0]["noise"]["variance_value"] = 1e-3
    with pytest.raises(ms.ConfigError, match=r"sensors\[0\]\.noise\.variance_value: the noise variance 0\.001 makes"):
        ms.Problem.from_dict(data)


def _noise(value: float):
    def apply(data):
        data["sensors"][0]["noise"]["variance_value"] = value
        return data

    return apply


def _kernel_variance(value: float):
    def apply(data):
        data["process"]["field"]["kernel"]["variance"] = value
        return data

    return apply


def _sensors(count: int):
    def apply(data):
        data["sensors"] = [{**data["sensors"][0], "name": f"s{i}", "p0": [0.004 * i, 0.5]} for i in range(count)]
        return data

    return apply


@pytest.mark.parametrize(
    ("grid", "shooting", "change", "options", "message"),
    [((1000, 1000), {}, None, [], "process.field.grid: expected nx·ny <= 2500"),
     # memory n² K m: the budget's message (memory does not fall with K: m grows as K falls)
     ((50, 50), {"intervals": 2000}, None, [], "too large: the shooting NLP (n = 2500 field states, N = 1 sensors, "
                                               "K = 2000 intervals of m = 1 RK4 substeps) needs about 839 GiB"),
     ((20, 20), {}, None, ["--max-memory", "200M"], "the shooting NLP (n = 400 field states"),
     # λ_max = sqrt(a² + 2aσ²/r) = sqrt(0.01 + 2e8) = 1.41e4 for a = 1/τ = 0.1, σ² = 1, r = 1e-9; h = 5/100:
     # m = ceil(h λ_max / 0.25) = 2829 substeps; the noise variance (2aσ²/r ≫ a²) is the key named
     ((2, 2), {}, _noise(1e-9), [], "sensors[0].noise.variance_value: the noise variance 1e-09 makes the field's "
                                    "fastest rate λ_max = 1.41e+04 per unit time; on intervals h = 0.05 the shooting "
                                    "method needs m = 2829 RK4 substeps (h·λ_max ≤ 0.25), expected at most 1000"),
     # the sensors' N × N blocks per substep: 1000 sensors were estimated as one (353 MiB) and died of bad_alloc
     # after 3.6 GB; 3N² + 4Nn doubles a substep (measured 0.30 MB at N = 100 against 0.32 MB)
     ((5, 5), {}, _sensors(1000), ["--max-memory", "4G"], "the shooting NLP (n = 25 field states, N = 1000 "
                                                          "sensors, K = 100 intervals of m = 9 RK4 substeps) needs "
                                                          "about 21.3 GiB"),
     ((3, 3), {}, _sensors(200), ["--max-time", "1s"], "would compute for at least"),
     # a kernel variance of 1e90 was blamed on the sensors' noise variance 0.1 (red team)
     ((2, 2), {}, _kernel_variance(1e90), [], "process.field.kernel.variance: the kernel variance 1e+90 makes"),
     # the time estimate counted 10 fine iterations only: 100 random coarse starts (each ≥ 40 iterations measured)
     # ran past a minute under --max-time 20s (red team); the coarse phase is now counted too
     ((5, 5), {"starts": 100}, None, ["--max-time", "20s"], "would compute for at least"),
     # 200 000 ε steps, or 1e18 Ipopt iterations per coarse step, reached the solver (exit 1, or a hang)
     ((2, 2), {"homotopy": [float(x) for x in np.linspace(1e-3, 1.0, 2000)]}, None, [],
      "solver.shooting.homotopy: expected at most 1000 items, not 2000"),
     ((2, 2), {"coarse_max_iterations": 10**18}, None, [],
      "solver.shooting.coarse_max_iterations: expected less than or equal to 1000000")],
    ids=["grid", "memory", "budget", "substeps", "sensors-memory", "sensors-time", "kernel-variance", "starts-time",
         "schedule",
         "coarse-iterations"],
)  # fmt: skip
def test_hostile_sizes_are_refused_before_allocation(tmp_path, capsys, grid, shooting, change, options, message):
    import tracemalloc

    import yaml

    from mobisense import cli

    path = tmp_path / "huge.yaml"
    data = field_problem(grid=grid, shooting=shooting)
    path.write_text(yaml.safe_dump(change(data) if change else data, allow_unicode=True))
    tracemalloc.start()
    code = cli.main(["solve", str(path), "--out", str(tmp_path / "out"), *options])
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and message in err and str(path) in err
    assert not (tmp_path / "out").exists()
    assert peak < 50e6  # one dense n × n float matrix would be 8 GB (10⁶ states) or 50 MB (2500)


@pytest.mark.slow
def test_field_mapping_5x5_from_the_command_line(tmp_path, capsys):
    import json

    from mobisense import cli
    from mobisense.core.netcdf import open_dataset

    out = tmp_path / "out"
    assert cli.main(["solve", "field_mapping_5x5", "--out", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["method"] == "shooting" and summary["status"] == "solved"
    # research measurement of this problem: J = 0.30428127 (K = 100, m = 2); local optima differ by > 1e-3
    assert summary["cost"] == pytest.approx(0.30428127, rel=1e-6)
    assert summary["trace_Sigma_tf"] < 0.5 * summary["baseline"]["trace_Sigma_tf"]
    ds = open_dataset(out / "solution.nc")
    assert ds["sigma_diag"].dims == ("time", "state") and ds["sigma_diag"].shape == (101, 25)
    assert np.allclose(ds["sigma_diag"].values, np.diagonal(ds["Sigma"].values, axis1=1, axis2=2))
    for figure in ("variance_maps.png", "trace.png", "controls.png", "homotopy.png"):
        assert (out / figure).stat().st_size > 0


@pytest.mark.slow
def test_a_sensor_far_out_of_reach_does_not_set_the_other_sensors_control_unit():
    # the shipped 5 × 5 example with g1 moved 1e6 away: the fine solve ran out of Ipopt's iterations (exit 1)
    # on a plan whose J equals, to 12 digits, the solves with g1 at x = 60 … 1e5 (field audit)
    import yaml
    from reference_problems import PROBLEMS

    costs = []
    for x in (300.0, 1e6):
        data = yaml.safe_load((PROBLEMS / "field_mapping_5x5.yaml").read_text())
        data["sensors"][0]["p0"] = [x, 1.0]
        solution = ms.solve(ms.Problem.from_dict(data))
        assert solution.success, solution.message
        costs.append(solution.cost)
    assert costs[1] == pytest.approx(costs[0], rel=1e-9)  # out of reach either way: the same optimum


def test_options_of_the_direct_methods_homotopy_are_refused_for_a_field(tmp_path, capsys):
    # --strategy, --homotopy, --step were accepted and changed nothing (the same 7 ε steps and J: field audit)
    import yaml

    from mobisense import cli

    path = tmp_path / "field.yaml"
    path.write_text(yaml.safe_dump(field_problem()))
    for options, named in ((["--strategy", "cold"], "--strategy"), (["--homotopy", "none", "--step", "0.5"],
                                                                     "--homotopy/--step")):  # fmt: skip
        assert cli.main(["solve", str(path), "--out", str(tmp_path / "out"), *options]) == 2
        err = capsys.readouterr().err
        assert f"{path}: {named}: the shooting method runs its own ε schedule" in err and err.count("\n") == 1
        assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("solver, named, why", [
    ({"strategy": "thorough"}, "solver.strategy", "its own ε schedule"),
    ({"starts": 3}, "solver.starts", "solver.shooting.starts"),
    ({"homotopy": {"step": 0.1}}, "solver.homotopy.step", "solver.shooting.homotopy"),
    ({"collocation": {"intervals": 40}}, "solver.collocation.intervals", "solver.shooting.intervals"),
    ({"method": "shooting", "codegen": "off"}, "solver.codegen", "no collocation kernels"),
])  # fmt: skip
def test_the_direct_methods_settings_in_a_field_file_are_refused_not_ignored(solver, named, why):
    # solver.strategy: thorough in a field file ran the same shooting solve as without it (stop-33 left item)
    data = field_problem()
    data["solver"] = {**data.get("solver", {}), **solver}
    with pytest.raises(ConfigError, match=rf"{re.escape(named)}: not used by solver.method 'shooting' \(.*"
                                          rf"{re.escape(why)}"):  # fmt: skip
        ms.Problem.from_dict(data)
    problem = ms.Problem.from_dict({**data, "solver": {**data["solver"], "method": "direct"}})
    assert problem.solver.method == "direct"  # the same settings with the method that uses them


def test_a_normalised_field_problem_with_every_default_written_out_reads_back():
    # the refusal compares with the defaults: a solution file's problem (every key written) must still load
    problem = ms.Problem.from_dict(field_problem())
    again = ms.Problem.from_dict(problem.normalised())
    assert again.digest() == problem.digest() and again.solver.method == "shooting"


def _check_worst_violation(solution, u_max=None, v_max=None, p_end=None, v_end=None) -> dict:
    """The reported worst violation, checked against the returned plan in its own quantity (whichever row it is)."""
    worst = solution.summary()["worst_violation"]
    what, when = worst["constraint"], worst["time"]
    k = int(np.argmin(np.abs(solution.t_u - when)))
    if what == "|u| ≤ u_max of sensor g1":
        expected = np.linalg.norm(solution.u[k, 0]) - u_max
    elif what == "max_speed of sensor g1":
        expected = np.linalg.norm(solution.sample(when).v[0, 0]) - v_max
    else:
        key, c = what[len("terminal ")], int(what[len("terminal p[")])
        assert what.startswith(f"terminal {key}[") and when == solution.t[-1]
        expected = abs((solution.p if key == "p" else solution.v)[-1, 0, c] - (p_end if key == "p" else v_end)[c])
    assert worst["violation"] == pytest.approx(expected, rel=1e-9)
    assert worst["violation"] > 0.1
    assert f"worst-violated constraint: {what} at t = " in solution.message
    return worst


def test_an_infeasible_field_solve_reports_what_was_solved_and_its_worst_constraint_in_physical_units():
    # summary.json said eps_reached 1.0 and worst_violation null when no step had succeeded (field audit). Each
    # target is reachable alone (|Δp| 4.24 < u_max T²/2 = 5, |Δv| 1.7 < u_max T = 2, so the file is accepted) but
    # not both: ending at 1.7 L/T towards the start, the sensor gets no further than ≈ 0 along the way
    data = field_problem(shooting={"intervals": 20, "coarse_intervals": 10})
    data["sensors"][0].update(terminal={"p": [3.5, 3.5], "v": [-1.2, -1.2]}, u_max=0.4)
    solution = ms.solve(ms.Problem.from_dict(data))
    assert not solution.success
    summary = solution.summary()
    # the largest ε solved below 1: the coarse ε = 1 step solves a relaxed problem (no |u| ≤ u_max, coarse grid)
    assert summary["eps_reached"] == max([s.eps for s in solution.homotopy if s.success and s.eps < 1], default=0.0)
    assert summary["improvement_percent"] is None  # as the table says: none quoted for a failed solve (audit)
    # in physical units, as the returned plan has it: Ipopt stopped on a plan that reaches the target by breaking
    # the bound, or keeps the bound and misses the target (measured: terminal p[1], 5.5 off)
    _check_worst_violation(solution, u_max=0.4, p_end=[3.5, 3.5], v_end=[-1.2, -1.2])


def test_sampling_a_shooting_solution_gives_its_own_piecewise_linear_controls_and_exact_path(tmp_path):
    # sample() went through cubic splines (controls 0.7 % off the plan's at mid-intervals) and raised IndexError
    # on a loaded solution without Σ (field audit)
    from short_runs import field_solution

    solution = field_solution(shooting={"full_sigma": False})
    solution.save(tmp_path)
    loaded = ms.Solution.load(tmp_path / "solution.nc")
    times = np.sort(np.random.default_rng(0).uniform(0.0, 5.0, 40))
    sample = loaded.sample(times)
    assert np.isnan(sample.Sigma).all()  # not stored: said so, not guessed
    t, u = solution.t, solution.u[:, 0]

    def control(s: float) -> np.ndarray:  # the plan: linear between the nodes
        return np.array([np.interp(s, t, u[:, 0]), np.interp(s, t, u[:, 1])])

    # the double integrator under that control, by scipy at tight tolerances (independent of eq. field.7)
    flown = solve_ivp(lambda s, y: np.concatenate([y[2:], control(s)]), (0.0, 5.0),
                      np.concatenate([solution.p[0, 0], solution.v[0, 0]]), method="DOP853", t_eval=times,
                      rtol=1e-12, atol=1e-12, max_step=float(t[1] - t[0]))  # fmt: skip
    np.testing.assert_allclose(sample.u[:, 0], np.array([control(s) for s in times]), atol=1e-12)
    np.testing.assert_allclose(sample.p[:, 0], flown.y[:2].T, atol=1e-9)
    np.testing.assert_allclose(sample.v[:, 0], flown.y[2:].T, atol=1e-9)


def test_a_loaded_field_solution_without_its_full_sigma_keeps_its_variances_plots_and_saves_again(tmp_path):
    # a field file of more than 25 states keeps diag Σ only: it was written but not read back, so the loaded
    # solution could neither draw variance_maps.png nor be saved again (np.diagonal of None)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from short_runs import field_solution

    from mobisense.ocp.field_plots import FIELD_FIGURES

    solution = field_solution(shooting={"full_sigma": False})
    solution.save(tmp_path / "first")
    loaded = ms.Solution.load(tmp_path / "first")
    assert loaded.Sigma is None
    # the file's float64 diagonal, bit for bit
    np.testing.assert_array_equal(loaded.variances(), np.diagonal(solution.Sigma, axis1=1, axis2=2))
    for draw in FIELD_FIGURES.values():
        plt.close(draw(loaded))
    loaded.save(tmp_path / "again")
    np.testing.assert_array_equal(ms.Solution.load(tmp_path / "again").variances(), loaded.variances())
    assert loaded.non_finite() is None


def test_variance_maps_draw_every_panel_on_the_same_frame_around_field_and_paths():
    # the middle panel (the paths) was autoscaled to paths leaving the field, and came out smaller than the others
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from short_runs import field_solution

    from mobisense.ocp.field_plots import plot_variance_maps

    solution = field_solution()
    fig = plot_variance_maps(solution)
    frames = {(ax.get_xlim(), ax.get_ylim()) for ax in fig.axes[:-1]}  # the last axes: the colour bar
    assert len(frames) == 1
    (x0, x1), (y0, y1) = frames.pop()
    (ex0, ex1), (ey0, ey1) = solution.problem.process.field.extent
    p = solution.p
    assert x0 < min(ex0, p[..., 0].min()) and x1 > max(ex1, p[..., 0].max())
    assert y0 < min(ey0, p[..., 1].min()) and y1 > max(ey1, p[..., 1].max())
    plt.close(fig)


@pytest.mark.slow
def test_random_coarse_starts_find_the_lower_optimum_the_homotopy_misses_on_a_small_field():
    # one sensor on a 3 × 3 field: the homotopy's basin J = 0.5908834; a random ε = 1 start 0.5532824, also
    # reached by the field audit's independent evaluation (0.5532824) and below every homotopy it tried
    import yaml
    from reference_problems import PROBLEMS

    data = yaml.safe_load((PROBLEMS / "field_mapping_5x5.yaml").read_text())
    data["process"]["field"]["grid"] = [3, 3]
    data["sensors"] = data["sensors"][:1]
    data["sensors"][0]["p0"] = [1.0, 1.0]
    plain = ms.solve(ms.Problem.from_dict(data))
    data["solver"]["shooting"] = {"starts": 2}
    started = ms.solve(ms.Problem.from_dict(data))
    assert plain.success and started.success
    assert started.cost < 0.95 * plain.cost  # measured 0.55328 against 0.59088: 6.4 % lower
    starts = started.stats["coarse_starts"]
    assert [s["start"] for s in starts] == ["homotopy", "random start 1", "random start 2"]
    assert sum(s["kept"] for s in starts) >= 1 and not starts[0]["kept"]
    assert min(s["cost"] for s in starts) == pytest.approx(started.cost, rel=1e-3)  # coarse vs fine grid


def test_an_init_of_other_sensors_is_not_used_and_says_so():
    # first-hour audit: a field solve ignored an init it could not use without a word (the direct method warns)
    one = field_solution()
    problem = ms.Problem.from_dict(field_problem(sensors=2, shooting={"intervals": 20, "coarse_intervals": 10}))
    with pytest.warns(UserWarning, match="init was not used: it has 1 sensors, the problem 2"):
        two = ms.solve(problem, init=one)
    assert two.success and two.stats["start"] == StartKind.COARSE.value


def test_the_time_estimate_counts_the_substeps_a_running_cost_takes():
    # random-problem audit: with K = mean the solver takes at least 4 substeps (FieldShooting), the estimate 1, so
    # its time bound was 4× low ("m = 1 … at least 2.72 s" for a solve that took 577 s)
    from mobisense.ocp.sizes import shooting_estimate

    data = field_problem()
    zero = shooting_estimate(ms.Problem.from_dict(data))
    data["cost"]["K"] = "mean"
    problem = ms.Problem.from_dict(data)
    mean = shooting_estimate(problem)
    fine = FieldShooting(problem, problem.solver.shooting.intervals)
    assert f"m = {fine.m} RK4" in mean.what and fine.m >= 4 and "m = 4" not in zero.what
    from mobisense.ocp.field import COARSE_H_LAMBDA, STEP_ITERATIONS, shooting_seconds

    # both phases' bounds take the solver's own substeps (the coarse grid's too, since the rule is shared): 1 → 4
    o, n, N = problem.solver.shooting, problem.n, problem.N
    coarse = FieldShooting(problem, o.coarse_intervals, scaling="energy", max_h_lambda=COARSE_H_LAMBDA)
    steps = STEP_ITERATIONS * len(o.homotopy)
    expected = (shooting_seconds(n, o.intervals, fine.m, N) - shooting_seconds(n, o.intervals, 1, N)
                + shooting_seconds(n, o.coarse_intervals, coarse.m, N, steps)
                - shooting_seconds(n, o.coarse_intervals, 1, N, steps))  # fmt: skip
    assert coarse.m == 4 and mean.seconds - zero.seconds == pytest.approx(expected, rel=1e-12)


def test_a_grid_far_coarser_than_the_length_scale_is_reported_with_the_variance_it_leaves_between_nodes():
    # field audit: ℓ = 0.3 on a spacing of 2 solved without a word; a hand plan beat the "optimum" by 8 % and the map
    # painted a cell at its node's 0.095 where the model's own mean variance over the cell was 0.95
    from mobisense.ocp.field import FieldSpec
    from mobisense.ocp.solution_warnings import UNRESOLVED_FIELD, field_grid_warning

    def spec(ell: float, grid: int) -> FieldSpec:
        return FieldSpec.model_validate({"grid": [grid, grid], "extent": [[0, 10], [0, 10]], "time_constant": 20.0,
                                         "kernel": {"type": "matern32", "length_scale": ell, "variance": 2.0}})

    # independent check of the fraction on the whole 5 × 5 grid (its central cell, every node, numpy only):
    # σ² − k'Kₛ⁻¹k averaged over a 9 × 9 lattice of the cell, in units of σ²
    s = spec(3.0, 5)
    loc = s.locations()
    kern = lambda r: 2.0 * (1 + np.sqrt(3) * r / 3.0) * np.exp(-np.sqrt(3) * r / 3.0)  # noqa: E731
    Ks = kern(np.linalg.norm(loc[:, None] - loc[None], axis=-1)) + 1e-8 * 2.0 * np.eye(25)
    g = np.linspace(4.0, 6.0, 9)
    pts = np.array([[x, y] for x in g for y in g])
    k = kern(np.linalg.norm(pts[:, None] - loc[None], axis=-1))
    independent = np.mean(2.0 - np.einsum("ij,ij->i", k @ np.linalg.inv(Ks), k)) / 2.0
    # the block of 5 × 5 is the whole grid here: the same numbers, to the smoothing δ = 1e-6 ℓ (1e-9 relative)
    assert s.unresolved_fraction() == pytest.approx(independent, rel=1e-6)
    assert spec(3.0, 10).unresolved_fraction() < 0.01 < spec(3.0, 5).unresolved_fraction() < UNRESOLVED_FIELD
    assert spec(0.3, 5).unresolved_fraction() > 0.9

    class Solved:  # what the warning reads of a solution
        problem = ms.Problem.from_dict(field_problem())

    Solved.problem.process.field = spec(0.3, 5)
    assert "leave 96 % of the field's variance unknown between the nodes" in field_grid_warning(Solved)
    Solved.problem.process.field = spec(3.0, 5)
    assert field_grid_warning(Solved) is None


def test_a_field_solution_given_as_init_to_the_direct_method_is_named_as_another_methods():
    # red team: the warning said it "carries no converged ε = 1 NLP point (a failed solve, or one read from a file)"
    # of a shooting solution that had converged: the reason is the method
    shot = field_solution()
    assert shot.success
    data = field_problem()
    data["solver"] = {"method": "direct", "collocation": {"intervals": 10}}
    with pytest.warns(UserWarning, match="it was solved by another method"):
        direct = ms.solve(ms.Problem.from_dict(data), init=shot)
    assert direct.success and direct.stats["start"] == "init ignored: solved by another method"


def test_a_bound_far_below_the_control_unit_on_every_sensor_solves_to_the_no_control_cost():
    # red team: u_max = 1e-9 on both sensors of a 3 × 3 field (feasible: u ≡ 0) ran Ipopt to its iteration limit —
    # the row |u|²/u_max² − 1 in a control unit of ~0.1 had gradients of 1e16. With every sensor bounded below the
    # unit, the unit is the smallest bound. The sensors can move at most ½·1e-9·T² = 1.3e-8 L, so J is the
    # no-control J to about 1e-8 relative
    data = field_problem(grid=(3, 3), sensors=2, shooting={"intervals": 10, "coarse_intervals": 5})
    for sensor in data["sensors"]:
        sensor["u_max"] = 1e-9
    solution = ms.solve(ms.Problem.from_dict(data))
    assert solution.success
    assert solution.cost == pytest.approx(solution.baseline["cost"], rel=1e-8)
    assert np.linalg.norm(solution.u, axis=2).max() <= 1e-9 * (1 + 1e-6)
