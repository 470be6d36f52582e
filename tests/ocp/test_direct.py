"""Direct collocation against analytic results and independent computations.

Theory: docs/theory/ocp.md, docs/theory/direct.md.
"""

from __future__ import annotations

import numpy as np
import pytest
from reference_problems import (
    coupled_two_sensor,
    hussein2008,
    scalar_steady_state,
    sensor_at_rest,
    two_scalar_processes,
)

from mobisense.ocp.collocation import CollocationScheme
from mobisense.ocp.direct.guesses import initial_guess, state_grid
from mobisense.ocp.direct.solver import solve_direct
from mobisense.ocp.direct.transcription import transcription_for
from mobisense.ocp.problem import Problem
from mobisense.ocp.simulate import integrate


def solve(data: dict) -> object:
    solution = solve_direct(Problem.from_dict(data))
    assert solution.success, solution.message
    return solution


@pytest.fixture(scope="module")
def default_solution():
    return solve(hussein2008(tolerance=1e-12))


def _sigma_error_at_tiny_eps(intervals: int) -> float:
    """Max |Σ_NLP − Σ_IVP| over the state nodes when ε = 1e-10 (sensors coast)."""
    problem = Problem.from_dict(hussein2008(collocation={"intervals": intervals}, tolerance=1e-12))
    tr = transcription_for(problem)
    values = tr.layout.values(problem)
    t_grid, order = state_grid(tr, 0.0, 10.0)
    coasting = integrate(tr.model, tr.layout.pack(values), t_grid)
    values["cost_scale"] = coasting.cost
    P = tr.layout.pack({**values, "eps": 1e-10})
    result = tr.solve(P, initial_guess(tr, coasting, P))
    assert result.success
    parts = tr.unpack(result.w, P)
    x = np.concatenate([parts["xs"], parts["xc"].reshape(-1, tr.structure.nx)])[order]
    return float(np.abs(x[:, 0] - coasting.x[:, 0]).max())


@pytest.mark.slow
def test_tiny_eps_matches_riccati_ivp():
    # As ε → 0 the sensors coast and Σ solves the Riccati IVP. The remaining difference is the Radau IIA
    # (d = 3) stage error, O(h^(d+1)) = O(h^4) at the nodes: check its size (≤ 1e-6 of Σ0 = 200 at K = 100)
    # and that halving h divides it by ≥ 2^3.5.
    e50, e100 = _sigma_error_at_tiny_eps(50), _sigma_error_at_tiny_eps(100)
    assert e100 < 1e-6 * 200.0
    assert e50 / e100 > 2**3.5


def test_sensor_at_rest_reaches_scalar_steady_state():
    # α = 1e12 makes any motion prohibitively expensive: the sensor stays at range 5 and, after 30 time
    # units (convergence rate 2 sqrt(a² + Q/r) ≈ 1.02 → e^-30.5 ≈ 6e-14), Σ(tf) equals the steady state.
    solution = solve(sensor_at_rest(alpha=1e12, tf=30.0))
    assert np.abs(solution.p - np.array([3.0, 4.0])).max() < 1e-8
    r = 5.0 * 25.0 + 3.0
    assert solution.Sigma[-1, 0, 0] == pytest.approx(scalar_steady_state(-0.5, 1.0, r), rel=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("scheme,degree", [("radau", 2), ("radau", 3), ("legendre", 2), ("legendre", 3)])
def test_cost_converges_at_scheme_order(scheme, degree):
    # With controls at the collocation points the cost converges at order 2d−1 (Radau) / 2d (Legendre).
    # Reference: Legendre d = 3 on 80 intervals (error ≈ 3e-11, far below the errors measured here).
    reference = solve(
        hussein2008(collocation={"scheme": "legendre", "degree": 3, "intervals": 80}, tolerance=1e-12)
    ).cost
    errors = [
        abs(
            solve(hussein2008(collocation={"scheme": scheme, "degree": degree, "intervals": K}, tolerance=1e-12)).cost
            - reference
        )
        for K in (10, 20, 40)
    ]
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    expected = CollocationScheme(scheme, degree).order
    assert orders[-1] > expected - 0.5, (errors, orders)


@pytest.mark.slow
def test_radau_and_legendre_agree(default_solution):
    legendre = solve(hussein2008(collocation={"scheme": "legendre"}, tolerance=1e-12))
    # both are O(h^5) or better at K = 100 (errors measured ≤ 1e-9)
    assert legendre.cost == pytest.approx(default_solution.cost, rel=1e-9)


def test_default_problem_improves_on_coasting(default_solution):
    s = default_solution
    assert s.cost < s.baseline["cost"]
    assert s.min_sigma_eigenvalue > 0
    # independent check of the baseline: the coasting Riccati IVP at a finer tolerance
    problem = s.problem
    tr = transcription_for(problem)
    fine = integrate(tr.model, tr.layout.pack(tr.layout.values(problem)), np.linspace(0, 10, 11), rtol=1e-13)
    assert s.baseline["cost"] == pytest.approx(fine.cost, rel=1e-9)


@pytest.mark.slow
def test_resimulated_control_reproduces_cost(default_solution):
    # Interpolate the optimal control on each interval (Lagrange through its d nodes) and integrate the
    # sensor + Riccati ODE with DOP853 (rtol 1e-11): J agrees to the collocation error (measured 5e-11).
    s = default_solution
    tr = transcription_for(s.problem)
    K, h = tr.intervals, 10.0 / tr.intervals
    U = s.u.reshape(K, tr.colloc.degree, 2)

    def control(t: float) -> np.ndarray:
        k = min(int(t / h), K - 1)
        weights = tr.colloc.interpolation_matrix(np.array([(t - k * h) / h]))[0]
        return weights @ U[k]

    sim = integrate(tr.model, tr.layout.pack(tr.layout.values(s.problem)), np.linspace(0, 10, 501), control=control)
    assert sim.cost == pytest.approx(s.cost, rel=1e-8)
    np.testing.assert_allclose(sim.x[-1, 1:3], s.p[-1, 0], atol=1e-5)


@pytest.mark.slow
@pytest.mark.parametrize("axis", [0, 1])
def test_initial_costate_is_cost_sensitivity(default_solution, axis):
    # λ_p(t0) = ∂J*/∂p0 (envelope theorem); central differences with δ = 1e-3 have O(δ²) truncation
    # error and solver noise ≈ 1e-12·J/δ, both < 1e-6 relative here.
    delta = 1e-3
    costs = []
    for sign in (1, -1):
        data = hussein2008(tolerance=1e-12)
        data["sensors"][0]["p0"][axis] += sign * delta
        costs.append(solve(data).cost)
    fd = (costs[0] - costs[1]) / (2 * delta)
    assert default_solution.lam_p[0, 0, axis] == pytest.approx(fd, rel=1e-6)


def test_transversality(default_solution):
    s = default_solution
    # Λ(tf) = M; the multiplier estimate at the last Radau node carries an O(h) error (5e-5 at K = 100)
    assert s.Lam[-1, 0, 0] == pytest.approx(20.0, rel=1e-3)
    scale = np.abs(s.lam_p).max()
    assert np.abs(s.lam_p[-1]).max() < 1e-6 * scale
    assert np.abs(s.lam_v[-1]).max() < 1e-6 * np.abs(s.lam_v).max()


@pytest.mark.slow
def test_decoupled_problem_equals_two_scalar_problems():
    # cold solves: the joint coasting guess is the two scalar ones side by side, so Ipopt follows the same
    # path in the joint NLP as in its two halves (the default strategy's random starts differ between them:
    # on the joint problem they find a lower optimum, 64.45, than both halves' starts, 46.15 + 22.97)
    joint, first, second = (Problem.from_dict(d).with_solver(strategy="cold") for d in two_scalar_processes())
    sj, s0, s1 = solve_direct(joint), solve_direct(first), solve_direct(second)
    assert sj.success and s0.success and s1.success
    # same NLP split in two: equal to the Ipopt tolerance (1e-9 relative)
    assert sj.cost == pytest.approx(s0.cost + s1.cost, rel=1e-8)
    best = solve_direct(joint.with_solver(strategy="auto"))
    assert best.cost <= sj.cost * (1 + 1e-9)  # the default keeps the lowest of its starts, the cold one included
    np.testing.assert_allclose(sj.Sigma[:, 0, 0], s0.Sigma[:, 0, 0], rtol=1e-6)
    np.testing.assert_allclose(sj.Sigma[:, 1, 1], s1.Sigma[:, 0, 0], rtol=1e-6)
    assert np.abs(sj.Sigma[:, 0, 1]).max() < 1e-9
    np.testing.assert_allclose(sj.p[:, 1], s1.p[:, 0], atol=1e-4)


@pytest.mark.slow
def test_coupled_problem_with_terminal_velocity():
    s = solve(coupled_two_sensor(terminal_velocity=True))
    np.testing.assert_allclose(s.v[-1, 0], [0.0, 0.0], atol=1e-9)
    assert s.min_sigma_eigenvalue > 0
    assert s.cost < s.baseline["cost"]
    free = solve(coupled_two_sensor(terminal_velocity=False))
    assert free.cost <= s.cost + 1e-9  # a constraint cannot lower the optimum
    assert np.abs(free.v[-1, 0]).max() > 1e-3  # and it was active


@pytest.mark.slow
def test_control_bound_is_respected():
    data = hussein2008(collocation={"intervals": 60})
    data["sensors"][0]["u_max"] = 0.5
    s = solve(data)
    assert np.linalg.norm(s.u[:, 0], axis=1).max() <= 0.5 + 1e-8
    unbounded = solve(hussein2008(collocation={"intervals": 60}))
    assert np.linalg.norm(unbounded.u[:, 0], axis=1).max() > 0.5  # the bound is active
    assert s.cost >= unbounded.cost


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["adaptive", "none"])
def test_homotopy_modes_reach_the_same_optimum(default_solution, mode):
    def continuation(mode: str) -> object:  # the ε-continuation alone (strategy homotopy without a budget)
        data = hussein2008(homotopy={"mode": mode, "budget": None}, tolerance=1e-12)
        data["solver"]["strategy"] = "homotopy"
        return solve(data)

    s = continuation(mode)
    assert s.cost == pytest.approx(default_solution.cost, rel=1e-9)
    if mode == "adaptive":
        assert len(s.homotopy) < len(continuation("fixed").homotopy)


def test_save_and_load_round_trip(default_solution, tmp_path):
    from mobisense.ocp.solution import Solution

    default_solution.save(tmp_path)
    loaded = Solution.load(tmp_path / "solution.nc")
    assert loaded.problem == default_solution.problem
    assert loaded.cost == default_solution.cost
    np.testing.assert_array_equal(loaded.Sigma, default_solution.Sigma)
    np.testing.assert_array_equal(loaded.lam_p, default_solution.lam_p)
    assert [h.eps for h in loaded.homotopy] == [h.eps for h in default_solution.homotopy]
    assert loaded.summary() == default_solution.summary()


def test_cvodes_coasting_equals_scipy_integration():
    # the compiled CVODES coasting solution (initial guess, baseline) against scipy's DOP853 at rtol 1e-12
    from mobisense.ocp.simulate import coast

    problem = Problem.from_dict(coupled_two_sensor())
    tr = transcription_for(problem)
    P = tr.layout.pack(tr.layout.values(problem))
    t = np.linspace(0.0, 5.0, 51)
    a, b = coast(tr.model, P, t), integrate(tr.model, P, t, rtol=1e-12)
    np.testing.assert_allclose(a.x, b.x, rtol=1e-8, atol=1e-9)
    assert a.cost == pytest.approx(b.cost, rel=1e-9)


def test_coasting_is_integrated_once_for_tasks_that_differ_only_in_alpha():
    # u ≡ 0: α multiplies an exact zero, so the coasting solution of another α is the one already computed —
    # and it is still the coasting solution of that α (checked against scipy's DOP853, as above)
    from mobisense.ocp.simulate import coast

    data = coupled_two_sensor()
    t = np.linspace(0.0, 5.0, 41)
    first = Problem.from_dict(data)
    data["cost"]["alpha"] = 7.5 * first.cost.alpha
    other = Problem.from_dict(data)
    tr = transcription_for(first)
    P1, P2 = (tr.layout.pack(tr.layout.values(p)) for p in (first, other))
    assert not np.array_equal(P1, P2)
    a, b = coast(tr.model, P1, t), coast(tr.model, P2, t)
    assert b is a  # no second integration
    reference = integrate(tr.model, P2, t, rtol=1e-12)
    np.testing.assert_allclose(b.x, reference.x, rtol=1e-8, atol=1e-9)
    assert b.cost == pytest.approx(reference.cost, rel=1e-9)
    with pytest.raises(ValueError, match="read-only"):
        b.x[0, 0] = 1.0  # shared between tasks: nobody may change it in place
    p0 = data["sensors"][0]["p0"]
    data["sensors"][0]["p0"] = [p0[0] + 1.0, p0[1]]  # anything else is another coasting problem
    moved = Problem.from_dict(data)
    assert coast(tr.model, tr.layout.pack(tr.layout.values(moved)), t) is not a


def test_an_init_that_does_not_fit_is_not_used_and_says_so() -> None:
    import warnings

    import mobisense as ms

    coarse = ms.solve(Problem.from_dict(hussein2008(collocation={"intervals": 30})))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        # another polynomial degree: other interval rows (another K alone is moved onto the grid: test_warm_shift)
        other_grid = ms.solve(Problem.from_dict(hussein2008(collocation={"intervals": 30, "degree": 2})), init=coarse)
        same_grid = ms.solve(Problem.from_dict(hussein2008(collocation={"intervals": 30})), init=coarse)
    assert other_grid.stats["start"] == "init ignored: different structure or grid"
    assert same_grid.stats["start"] == "warm start from init"
    assert [str(w.message).split(":")[0] for w in caught] == ["init was not used"]  # one warning: other_grid's
    assert "init was not used" in other_grid.summary()["warning"]
    # not used means solved as without it: the same optimum as a solve without init
    alone = ms.solve(Problem.from_dict(hussein2008(collocation={"intervals": 30, "degree": 2})))
    assert other_grid.cost == pytest.approx(alone.cost, rel=1e-12)
