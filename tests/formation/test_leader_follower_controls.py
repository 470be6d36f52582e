"""Leader–follower kinematics and Controls 1–3 against their analytic closed-loop behaviour.

Theory: docs/theory/leader_follower.md §1–§4; source: Karasalo & Hu (2010).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from mobisense.formation.leader_follower.controls import (
    Control1,
    Control2,
    Control3,
    FormationReference,
    FormationSingularityError,
    RelativeMeasurement,
    SingularityWarning,
    make_control,
    warn_near_singular,
)
from mobisense.formation.leader_follower.references import BearingRampReference, ConstantReference
from mobisense.formation.leader_follower.simulation import (
    IntegrationSettings,
    LeaderFollowerProblem,
    LeaderMotion,
    simulate,
)
from mobisense.formation.leader_follower.unicycle import (
    reference_point_error,
    relative_rates,
    relative_state,
    unicycle_rates,
)

# the paper's §8.2 set-up (Karasalo & Hu (2010)): v1 = 10, ω1 = π/3, k = 1, d0 = 1, β0 = π/7, R2 at (−0.97, −0.70, π/10)
LEADER = LeaderMotion(np.zeros(3), 10.0, math.pi / 3)
FOLLOWER = np.array([[-0.97, -0.70, math.pi / 10]])
RAMP = BearingRampReference(0.5, math.pi / 7, 0.001, 0.1, 45.0)  # eq. 55 read as d0' = 0.1 cos(45 β0)
RTOL = 1e-11
# DOP853 keeps each step's local error below rtol·|y|; over T = 10 s with contraction rate k = 1 the global
# error stays below ~T·rtol·max|y| (max|y| ≈ 20 m on the leader's 9.5 m circle). x_e is a difference of
# positions, so 10·rtol·max|y| bounds its error (measured: 1.1e-10 m at rtol = 1e-11, i.e. 0.5·rtol·max|y|).
SCALE = 20.0


def _problem(control: str, reference=None, rtol: float = RTOL, followers=FOLLOWER, leader=LEADER, duration=10.0):
    return LeaderFollowerProblem(
        leader=leader,
        follower_poses=followers,
        control=make_control(control),
        reference=reference or ConstantReference(1.0, math.pi / 7),
        gain=1.0,
        duration=duration,
        step=0.01,
        integration=IntegrationSettings("DOP853", rtol, 1e-14),
    )


def _exponential_error(result, follower: int = 2) -> float:
    r = result.sel(follower=follower)
    t = r["time"].values
    decay = np.exp(-t)  # k = 1
    return max(
        float(np.max(np.abs(r["xe"].values - r["xe"].values[0] * decay))),
        float(np.max(np.abs(r["ye"].values - r["ye"].values[0] * decay))),
    )


def test_relative_kinematics_match_the_derivatives_of_the_geometry():
    """Eqs. 2–4 against central differences of (d, β, γ) computed from poses moved by eq. 1."""
    rng = np.random.default_rng(1)
    h = 1e-5
    for _ in range(20):
        follower, predecessor = rng.uniform(-3, 3, 3), rng.uniform(-3, 3, 3)
        v, w, v_p, w_p = rng.uniform(-2, 2, 4)

        def state(s: float, f=follower, p=predecessor, v=v, w=w, v_p=v_p, w_p=w_p):
            # exact unicycle arcs over time s (constant inputs)
            def move(pose, speed, rate):
                phi = pose[2] + rate * s
                if abs(rate) > 0:
                    dx = speed / rate * (math.sin(phi) - math.sin(pose[2]))
                    dy = -speed / rate * (math.cos(phi) - math.cos(pose[2]))
                else:
                    dx, dy = speed * s * math.cos(phi), speed * s * math.sin(phi)
                return np.array([pose[0] + dx, pose[1] + dy, phi])

            return np.array(relative_state(move(f, v, w), move(p, v_p, w_p)), dtype=float)

        numeric = (state(h) - state(-h)) / (2 * h)
        numeric[1:] = (np.remainder(state(h)[1:] - state(-h)[1:] + np.pi, 2 * np.pi) - np.pi) / (2 * h)
        d, beta, gamma = state(0.0)
        analytic = np.array(relative_rates(d, beta, gamma, v, w, v_p, w_p), dtype=float)
        # central differences: truncation h²·|x'''|/6 ≲ 1e-9 for these O(1) states, round-off 1e-16/h = 1e-11
        np.testing.assert_allclose(analytic, numeric, rtol=0, atol=1e-7 * max(1.0, 1.0 / d**2))


def test_unicycle_rates_shape_and_values():
    pose = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, math.pi / 2]])
    rates = unicycle_rates(pose, np.array([2.0, 3.0]), np.array([0.1, -0.2]))
    np.testing.assert_allclose(rates, [[2.0, 0.0, 0.1], [0.0, 3.0, -0.2]], atol=1e-15)


@pytest.mark.parametrize("control", [Control1(), Control3()])
def test_control1_and_3_solve_the_linear_system_of_eq12(control):
    """(v, ω) of eq. 9 (+ eq. 25) solve M(φ)[v; ω] = −k e + v_{i−1} u(φ_{i−1}) (− Φ for Control 3), eqs. 12, 30."""
    rng = np.random.default_rng(2)
    for _ in range(50):
        follower, predecessor = rng.uniform(-2, 2, 3), rng.uniform(-2, 2, 3)
        v_p, k = rng.uniform(0, 5), rng.uniform(0.1, 3)
        ref = FormationReference(rng.uniform(0.2, 2), rng.uniform(-1.4, 1.4), rng.uniform(-1, 1), rng.uniform(-1, 1))
        d, beta, gamma = relative_state(follower, predecessor)
        v, w = control.command(RelativeMeasurement(float(d), float(beta), float(gamma), v_p), ref, k)
        phi, phi_p, d0, b0 = follower[2], predecessor[2], ref.distance, ref.bearing
        M = np.array([[math.cos(phi), -d0 * math.sin(phi + b0)], [math.sin(phi), d0 * math.cos(phi + b0)]])
        e = np.array(reference_point_error(follower, predecessor, d0, b0), dtype=float)
        rhs = -k * e + v_p * np.array([math.cos(phi_p), math.sin(phi_p)])
        if isinstance(control, Control3):  # eq. 30: cancel Φ = ḋ0 u(φ+β0) + d0 β̇0 u⊥(φ+β0)
            u = np.array([math.cos(phi + b0), math.sin(phi + b0)])
            u_perp = np.array([-u[1], u[0]])
            rhs -= ref.distance_rate * u + d0 * ref.bearing_rate * u_perp
        # cond(M) ≲ 1/(d0 cos β0) ≲ 50 here: 1e-11 relative is a few hundred ulps
        np.testing.assert_allclose([v, w], np.linalg.solve(M, rhs), rtol=1e-11, atol=1e-11)


def test_control1_reference_point_error_decays_exactly():
    """Theorem 1 / eq. 13: x_e(t) = x_e(0) e^{−kt}, y_e likewise, to integration tolerance."""
    result = simulate(_problem("control1"))
    assert _exponential_error(result) < 10 * RTOL * SCALE


def test_control1_residual_is_integration_error():
    """The residual shrinks with the tolerance (it is the integrator's, not a model mismatch)."""
    loose = _exponential_error(simulate(_problem("control1", rtol=1e-8)))
    tight = _exponential_error(simulate(_problem("control1", rtol=1e-11)))
    assert tight < loose / 100  # 1000× tighter tolerance; DOP853 error ∝ rtol (measured ratio ≈ 5000)


def test_cascade_of_followers_each_decays_exactly():
    """Chains: every follower's reference-point error decays as e^{−kt} whatever its predecessor does."""
    followers = np.array([[-1.2, 0.3, 0.2], [-2.0, -0.9, -0.4], [-3.1, 0.4, 0.6]])
    result = simulate(_problem("control1", followers=followers, duration=6.0))
    for f in (2, 3, 4):
        assert _exponential_error(result, f) < 10 * RTOL * SCALE


def test_control2_d_hat_decays_and_bearing_error_is_monotone():
    """Theorem 2 / eq. 19: d̂ = d cos β − d0 cos β0 = d̂(0) e^{−kt}; |β − β0| decreases monotonically."""
    result = simulate(_problem("control2")).sel(follower=2)
    t = result["time"].values
    d_hat = (result["d"] * np.cos(result["beta"]) - result["d0"] * np.cos(result["beta0"])).values
    assert np.max(np.abs(d_hat - d_hat[0] * np.exp(-t))) < 10 * RTOL * SCALE
    beta_err = np.abs(result["beta"].values - result["beta0"].values)
    # strictly decreasing: each 0.01 s step removes ≥ k (d0/d) |sin β̂| Δt, far above the 1e-9 integration noise
    assert np.all(np.diff(beta_err[beta_err > 1e-6]) < 0)
    # and Control 1 does not have that property on the same case (the paper's Fig. 11)
    c1 = simulate(_problem("control1")).sel(follower=2)
    assert np.max(np.diff(np.abs(c1["beta"].values - c1["beta0"].values))) > 1e-5  # ≫ 1e-9 integration noise


@pytest.mark.slow
def test_control2_bearing_follows_the_reduced_equation():
    """β̂' = −k d0 sin β̂ / d with d = (d̂ + d0 cos β0)/cos β (eq. 19), integrated alone with Radau."""
    result = simulate(_problem("control2")).sel(follower=2)
    d0, b0, k = 1.0, math.pi / 7, 1.0
    d_hat0 = float(result["d"][0] * np.cos(result["beta"][0])) - d0 * math.cos(b0)

    def rhs(t, y):
        beta = y[0] + b0
        d = (d_hat0 * math.exp(-k * t) + d0 * math.cos(b0)) / math.cos(beta)
        return [-k * d0 * math.sin(y[0]) / d]

    t = result["time"].values
    ref = solve_ivp(rhs, (0, t[-1]), [float(result["beta"][0]) - b0], method="Radau", t_eval=t, rtol=1e-12, atol=1e-14)
    # both integrations at rtol ≤ 1e-11 on an O(0.1) rad quantity: agreement to 1e-8 rad leaves a 100× margin
    np.testing.assert_allclose(result["beta"].values - b0, ref.y[0], rtol=0, atol=1e-8)


def test_control3_restores_exact_decay_with_time_varying_parameters():
    """Theorem 3: with d0(t), β0(t) of eq. 55, Control 3 gives x_e = x_e(0) e^{−kt} exactly."""
    assert _exponential_error(simulate(_problem("control3", RAMP))) < 10 * RTOL * SCALE


def test_control1_with_time_varying_parameters_obeys_the_bound_of_eq23():
    """‖e(t)‖ ≤ ‖e(0)‖ e^{−kt} + (M/k)(1 − e^{−kt}), M = max √(ḋ0² + d0² β̇0²) (eqs. 21–23), and is not exact."""
    full = simulate(_problem("control1", RAMP))
    result = full.sel(follower=2)
    t = result["time"].values
    refs = [RAMP.at(float(s)) for s in np.linspace(0, 10, 2001)]
    M = max(math.hypot(r.distance_rate, r.distance * r.bearing_rate) for r in refs)
    norm = np.hypot(result["xe"].values, result["ye"].values)
    bound = norm[0] * np.exp(-t) + M * (1 - np.exp(-t))
    assert np.all(norm <= bound + 10 * RTOL * SCALE)
    assert _exponential_error(full) > 1e-3  # the static error of Fig. 21 (Control 3 removes it)


def test_ramp_reference_matches_numerical_integration_of_its_rates():
    """Closed form of eq. 55 against solve_ivp of d0' = a cos(f β0), β0' = c."""
    sol = solve_ivp(
        lambda t, y: [0.1 * math.cos(45 * y[1]), 0.001], (0, 30), [0.5, math.pi / 7], rtol=1e-12, atol=1e-14,
        dense_output=True,
    )
    for t in np.linspace(0, 30, 31):
        ref = RAMP.at(float(t))
        # rtol 1e-12 on O(1) values: 1e-10 is a 100× margin
        np.testing.assert_allclose([ref.distance, ref.bearing], sol.sol(t), rtol=0, atol=1e-10)
        np.testing.assert_allclose(ref.distance_rate, 0.1 * math.cos(45 * ref.bearing), rtol=1e-14)
    # the paper's Fig. 19 window: d0 rises from 0.5 to a maximum ≈ 0.556 at t = 5 s and returns
    d0 = [RAMP.at(float(t)).distance for t in np.linspace(0, 10, 101)]
    assert 0.55 < max(d0) < 0.56 and abs(d0[-1] - 0.5) < 2e-3


def test_guards_raise_on_the_singular_set():
    meas = RelativeMeasurement(1.0, 0.2, 0.0, 1.0)
    with pytest.raises(FormationSingularityError, match="cos β0"):
        Control1().command(meas, FormationReference(1.0, math.pi / 2), 1.0)
    with pytest.raises(FormationSingularityError, match="d0"):
        Control1().command(meas, FormationReference(0.0, 0.1), 1.0)
    with pytest.raises(FormationSingularityError, match="cos β"):
        Control2().command(RelativeMeasurement(1.0, -math.pi / 2, 0.0, 1.0), FormationReference(1.0, 0.1), 1.0)
    with pytest.raises(FormationSingularityError, match="d ="):
        Control2().command(RelativeMeasurement(0.0, 0.1, 0.0, 1.0), FormationReference(1.0, 0.1), 1.0)
    assert issubclass(FormationSingularityError, ValueError)
    with pytest.warns(SingularityWarning, match="gains scale"):
        warn_near_singular(math.cos(1.5), "cos beta0")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warn_near_singular(math.cos(math.pi / 7), "cos beta0")  # no warning far from π/2


def test_singularity_reached_in_closed_loop_is_an_error():
    """Control 2 started with the predecessor abeam (β = π/2, outside Theorem 2's domain)."""
    problem = _problem("control2", followers=np.array([[0.0, -1.0, 0.0]]), duration=1.0)
    with pytest.raises(FormationSingularityError):
        simulate(problem)
