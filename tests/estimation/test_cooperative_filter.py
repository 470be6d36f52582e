"""Cooperative Kalman filter: engines, batching, consistency, coloured noise, Gramians.

Theory: docs/theory/cooperative.md §2–§5.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from mobisense.estimation import kalman
from mobisense.estimation.cooperative.coloured_filter import run_coloured_filter
from mobisense.estimation.cooperative.filter import CooperativeKalmanFilter, run_cooperative_filter
from mobisense.estimation.cooperative.gramians import gramians
from mobisense.estimation.cooperative.hessian import LeastSquaresHessian
from mobisense.estimation.cooperative.information_model import (
    cross_formation,
    formation_center,
    hessian_drift,
    hessian_to_vec,
    taylor_matrices,
    transition_matrix,
    vec_to_hessian,
)
from mobisense.estimation.cooperative.noise_config import CooperativeNoise
from mobisense.estimation.cooperative.spatial_noise import SpatialNoise
from mobisense.estimation.cooperative.steady_state import steady_state
from mobisense.estimation.fields.library import QuadraticField


def _trajectory(K: int, a: float = 1.0, b: float = 1.4) -> np.ndarray:
    s = np.linspace(0.0, 6.0, K)
    centers = np.stack([s, 0.5 * np.sin(s)], axis=-1)
    return cross_formation(a, b, center=centers, orientation=0.3 * np.sin(0.7 * s))


def _truth(field: QuadraticField, positions: np.ndarray) -> np.ndarray:
    c = formation_center(positions)
    return np.concatenate([field.value(c)[..., None], field.gradient(c)], axis=-1)


def test_taylor_model_is_exact_on_quadratic_fields() -> None:
    field = QuadraticField([[1.0, -0.4], [-0.4, 2.5]], [0.3, 1.2], -1.0, [0.2, 0.1])
    positions = np.random.default_rng(0).normal(size=(5, 2))
    C, D = taylor_matrices(positions)
    s = _truth(field, positions)
    z = C @ s + D @ hessian_to_vec(field.H)  # docs/theory/cooperative.md, eq. cooperative.4
    np.testing.assert_allclose(z, field.value(positions), atol=1e-13)
    np.testing.assert_allclose(vec_to_hessian(hessian_to_vec(field.H)), field.H, atol=0)
    # state equation (eq. 8-9, with the second-order value term) is exact: s_k = A s_{k-1} + h
    shift = np.array([0.7, -0.2])
    moved = positions + shift
    h = hessian_drift(field.H, shift)
    np.testing.assert_allclose(h, np.r_[0.5 * shift @ field.H @ shift, field.H @ shift], atol=1e-15)
    np.testing.assert_allclose(_truth(field, moved), transition_matrix(shift) @ s + h, atol=1e-13)
    # the symbolic cross rows used by the shape design agree with taylor_matrices
    from mobisense.estimation.cooperative.formation_design import cross_taylor_symbolic

    Cs, Ds = cross_taylor_symbolic(0.7, 1.3, 0.4)
    Cn, Dn = taylor_matrices(cross_formation(0.7, 1.3, orientation=0.4))
    np.testing.assert_allclose(np.asarray(Cs.full()), Cn, atol=1e-15)
    np.testing.assert_allclose(np.asarray(Ds.full()), Dn, atol=1e-15)


def test_engines_batches_and_step_api_agree() -> None:
    K, B = 60, 7
    rng = np.random.default_rng(1)
    positions = _trajectory(K)
    noise = CooperativeNoise.from_sigmas(0.05, 0.3, 0.2)
    H = rng.normal(size=(K, 2, 2))
    H = H + np.swapaxes(H, -1, -2)
    meas = rng.normal(size=(B, K, 4))
    x0, P0 = rng.normal(size=3), np.diag([2.0, 1.0, 0.5])
    numpy_single = run_cooperative_filter(positions, meas[3], noise, x0, P0, H, engine="numpy")
    casadi_single = run_cooperative_filter(positions, meas[3], noise, x0, P0, H, engine="casadi")
    batched = run_cooperative_filter(positions, meas, noise, x0, P0, H)
    per_run_positions = run_cooperative_filter(
        np.broadcast_to(positions, (B,) + positions.shape), meas, noise, x0, P0, H
    )
    # Joseph (numpy) vs information form (compiled): same equations, differing only by round-off,
    # amplified by at most cond(P) ~ 1e2 over 60 steps
    for name in ("states", "covariances", "states_prior", "covariances_prior", "innovations", "innovation_covariances"):
        ref = getattr(numpy_single, name)
        atol = 1e-12 * max(1.0, np.abs(ref).max())
        np.testing.assert_allclose(getattr(casadi_single, name), ref, atol=atol, err_msg=name)
        np.testing.assert_allclose(
            getattr(batched, name)[3]
            if name not in ("covariances", "covariances_prior", "innovation_covariances")
            else getattr(batched, name),
            ref,
            atol=atol,
        )
        np.testing.assert_allclose(getattr(per_run_positions, name)[3], ref, atol=atol, err_msg=name)
    assert batched.covariances.shape == (K, 3, 3)  # shared positions: one covariance recursion
    # step-by-step class reproduces the one-shot run
    filt = CooperativeKalmanFilter(noise, x0, P0, positions[0], H[0])
    filt.update(meas[3, 0], H[0])
    for k in range(1, K):
        filt.predict(positions[k])
        filt.update(meas[3, k], H[k])
    np.testing.assert_allclose(filt.state[..., 0], numpy_single.states[-1], atol=1e-12)
    ds = batched.to_dataset()
    assert ds["estimate"].dims == ("run", "step", "state") and ds["covariance"].dims == ("step", "state", "state2")


def test_a_known_initial_value_runs_on_every_engine() -> None:
    """A singular prior (the value known exactly) has no information form: step 0 is fused by the covariance form."""
    K, B = 40, 3
    rng = np.random.default_rng(5)
    positions = _trajectory(K)
    noise = CooperativeNoise.from_sigmas(0.05, 0.3, 0.2)
    meas = rng.normal(size=(B, K, 4))
    x0, P0 = np.array([2.0, 0.1, -0.3]), np.diag([0.0, 1.0, 0.5])
    joseph = run_cooperative_filter(positions, meas[1], noise, x0, P0, engine="numpy")  # covariance form only
    compiled = run_cooperative_filter(positions, meas[1], noise, x0, P0)  # auto: the compiled rollout
    per_run = run_cooperative_filter(np.broadcast_to(positions, (B,) + positions.shape), meas, noise, x0, P0)
    assert compiled.meta["rollout"] == "compiled" and per_run.meta["rollout"] == "components"
    # the known value stays known at step 0 (the update cannot change an exactly known state)
    assert joseph.states[0, 0] == pytest.approx(2.0, abs=1e-12) and abs(joseph.covariances[0, 0, 0]) < 1e-12
    # the same recursion in two forms: round-off only (cond(P) ≲ 1e2 over 40 steps)
    for name in ("states", "covariances"):
        ref = getattr(joseph, name)
        np.testing.assert_allclose(getattr(compiled, name), ref, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(getattr(per_run, name)[1], ref, atol=1e-12, err_msg=name)
    # with M singular too, every prior stays singular: the covariance form (auto picks it) or a clear error
    static = CooperativeNoise(np.zeros((3, 3)), 0.09, 0.04 * np.eye(4))
    auto = run_cooperative_filter(positions, meas[1], static, x0, P0)
    assert auto.meta["rollout"] == "shared" and np.all(np.isfinite(auto.states))
    with pytest.raises(ValueError, match="process noise M is singular too"):
        run_cooperative_filter(positions, meas[1], static, x0, P0, engine="casadi")
    with pytest.raises(ValueError, match="positive semidefinite"):
        run_cooperative_filter(positions, meas[1], noise, x0, -P0)


def test_sensors_without_measurement_noise_are_fused_by_the_covariance_form_or_refused() -> None:
    # R = 0 (audit): the default engine raised LinAlgError and the per-run rollout returned NaN at every step with
    # only a RuntimeWarning; N = 3 with R = U = 0 raised ZeroDivisionError. S = CPC' + DUD' is positive
    # definite, so the covariance form is well defined: checked against a plain Kalman filter written here
    K, B = 30, 2
    rng = np.random.default_rng(8)
    positions = _trajectory(K)
    meas = rng.normal(size=(B, K, 4))
    noise = CooperativeNoise(1e-2 * np.eye(3), 0.0, 1e-2 * np.eye(4))
    x0, P0 = np.array([0.5, -0.2, 0.1]), np.eye(3)
    auto = run_cooperative_filter(positions, meas[0], noise, x0, P0)
    assert auto.meta["rollout"] == "shared"  # not the information form
    centers = formation_center(positions)
    x, P = x0.copy(), P0.copy()
    for k in range(K):
        if k > 0:  # zero Hessian estimates: no drift input
            F = transition_matrix(centers[k] - centers[k - 1])
            x, P = F @ x, F @ P @ F.T + noise.process
        C, D = taylor_matrices(positions[k])
        S = C @ P @ C.T + D @ noise.hessian_error @ D.T
        gain = P @ C.T @ np.linalg.inv(S)
        x, P = x + gain @ (meas[0, k] - C @ x), (np.eye(3) - gain @ C) @ P
    # one filter, two codes: round-off of 30 steps with cond(S) ≲ 1e3
    np.testing.assert_allclose(auto.states[-1], x, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(auto.covariances[-1], P, rtol=1e-10, atol=1e-12)
    batched = np.broadcast_to(positions, (B,) + positions.shape)
    for engine, where in (("casadi", positions), ("auto", batched)):  # information forms: a clear refusal
        with pytest.raises(ValueError, match="measurement covariance R: singular"):
            run_cooperative_filter(where, meas[0] if where is positions else meas, noise, x0, P0, engine=engine)
    three = CooperativeNoise(1e-2 * np.eye(3), 0.0, np.zeros((4, 4)))
    with pytest.raises(ValueError, match="measurement covariance R: singular"):
        run_cooperative_filter(batched[..., :3, :], meas[..., :3], three, x0, P0)
    with pytest.raises(ValueError, match="measurement covariance R: expected a positive semidefinite"):
        CooperativeNoise(np.eye(3), [0.1, -0.1, 0.1, 0.1], np.eye(4))


def test_coincident_platforms_are_refused_by_the_coloured_filter() -> None:
    positions = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.0, 1.0]])[None] + np.linspace(0, 1, 5)[:, None, None]
    noise = CooperativeNoise.from_sigmas(0.1, 0.1, 0.1)
    for method in ("augmented", "differenced"):
        with pytest.raises(ValueError, match="positions: the spatial-noise covariance W .* is singular"):
            run_coloured_filter(positions, np.zeros((5, 4)), noise, SpatialNoise(0.3, 2.0), np.zeros(3), np.eye(3),
                                method=method)  # fmt: skip


def test_information_form_equals_joseph_update() -> None:
    rng = np.random.default_rng(2)
    X = rng.normal(size=(5, 3, 3))
    P = X @ np.swapaxes(X, -1, -2) + np.eye(3)
    H = rng.normal(size=(5, 4, 3))
    Y = rng.normal(size=(5, 4, 4))
    R = Y @ np.swapaxes(Y, -1, -2) + 0.1 * np.eye(4)
    x, y = rng.normal(size=(5, 3, 1)), rng.normal(size=(5, 4, 1))
    x1, P1, _, _ = kalman.update(x, P, y, H, R)
    x2, P2 = kalman.information_update(x, P, *kalman.information_contribution(y, H, R))
    np.testing.assert_allclose(x2, x1, atol=1e-11)  # round-off of 3x3/4x4 solves with cond <= ~1e3
    np.testing.assert_allclose(P2, P1, atol=1e-11)


@pytest.mark.parametrize(
    "field",
    [
        QuadraticField([[0.0, 0.0], [0.0, 0.0]], [0.8, -0.5], 12.0),  # linear field
        QuadraticField([[0.6, 0.2], [0.2, -0.3]], [0.8, -0.5], 12.0),  # exact second-order model
    ],
    ids=["linear", "quadratic"],
)
def test_filter_is_unbiased_and_consistent(field: QuadraticField) -> None:
    """NEES over 600 Monte Carlo runs inside its 95 % χ² band (the model is exact: M = 0, U = 0)."""
    K, B, sigma = 30, 600, 0.3
    rng = np.random.default_rng(11)
    positions = _trajectory(K)
    truth = _truth(field, positions)
    noise = CooperativeNoise(process=np.zeros((3, 3)), measurement=sigma**2, hessian_error=np.zeros((4, 4)))
    P0 = np.diag([1.0, 0.25, 0.25])
    x0 = truth[0] + rng.normal(size=(B, 3)) * np.sqrt(np.diag(P0))  # prior drawn from N(truth, P0)
    meas = field.value(positions) + sigma * rng.normal(size=(B, K, 4))
    result = run_cooperative_filter(positions, meas, noise, x0, P0, np.broadcast_to(field.H, (K, 2, 2)))
    anees = result.nees(truth).mean(axis=0)  # B · ANEES ~ χ²(3B) at every step if consistent
    # 95 % band for the whole trajectory: the errors are strongly correlated in time (M = 0: the estimate
    # accumulates all past data), so a per-step 5 % rate does not make steps independent trials; a
    # Bonferroni split of 5 % over the K steps bounds the family-wise false alarm by 5 % for any dependence
    lo, hi = stats.chi2.ppf([0.025 / K, 1 - 0.025 / K], 3 * B) / B
    assert np.all((anees > lo) & (anees < hi)), f"ANEES outside [{lo:.3f}, {hi:.3f}]: {anees.round(3)}"
    # unbiased: mean error over runs within 4 standard errors for all 3K components (P(|Z| > 4) = 6e-5)
    error = result.states - truth
    z = error.mean(axis=0) / (error.std(axis=0, ddof=1) / np.sqrt(B))
    assert np.abs(z).max() < 4.0
    # the covariance is the actual error covariance: compare traces over the last 10 steps
    ratio = np.trace(np.cov(error[:, -1].T)) / np.trace(result.covariances[-1])
    assert abs(ratio - 1) < 4 * np.sqrt(2 / B)  # sample variance relative std ≈ sqrt(2/B) per component


def test_covariance_converges_to_the_dare_steady_state() -> None:
    """Moving along a level curve of a fixed formation: P_k(+) → P∞ from python-control dare."""
    K = 400
    positions = cross_formation(0.8, 1.5, center=np.zeros((K, 2)), orientation=0.2)  # A = I
    noise = CooperativeNoise.from_sigmas(0.1, 0.5, 1.0)
    result = run_cooperative_filter(positions, np.zeros((K, 4)), noise, np.zeros(3), 10 * np.eye(3))
    ss = steady_state(positions[0], noise)
    np.testing.assert_allclose(result.covariances[-1], ss.posterior, atol=1e-12)
    np.testing.assert_allclose(result.covariances_prior[-1], ss.prior, atol=1e-12)


def test_closed_loop_least_squares_hessian_is_exact_on_a_quadratic_field() -> None:
    """Noise-free pentagon on a quadratic field: the loop recovers H and the state exactly."""
    field = QuadraticField([[0.6, 0.2], [0.2, -0.3]], [0.8, -0.5], 12.0)
    K = 25
    angles = 2 * np.pi * np.arange(5) / 5 + 0.3
    shape = np.stack([np.cos(angles), np.sin(angles)], -1)
    centers = np.stack([np.linspace(0, 5, K), np.zeros(K)], -1)
    positions = centers[:, None, :] + shape
    noise = CooperativeNoise(np.zeros((3, 3)), 1e-6, 9.0 * np.eye(4))  # Ĥ starts at 0: σ3 = 3 covers it
    truth = _truth(field, positions)
    result = run_cooperative_filter(
        positions, field.value(positions), noise, truth[0], 1e-8 * np.eye(3), LeastSquaresHessian(noise)
    )
    # eq. 33 leaks a fraction ~ R / (D U D') ≈ 1e-6 / 2 of the prediction error into z̃ (values O(1))
    np.testing.assert_allclose(result.hessians, np.broadcast_to(field.H, (K, 2, 2)), atol=1e-5)
    np.testing.assert_allclose(result.states, truth, atol=1e-6)


# ------------------------------------------------------------------------------------ coloured noise
def _correlated_problem(K: int, B: int, seed: int):
    rng = np.random.default_rng(seed)
    field = QuadraticField([[0.0, 0.0], [0.0, 0.0]], [0.5, -0.3], 2.0)
    centers = np.stack([np.linspace(0, 8, K), np.zeros(K)], -1)
    positions = cross_formation(1.0, 1.0, center=centers)
    spatial = SpatialNoise(0.5, 2.0)
    noise = CooperativeNoise(1e-6 * np.eye(3), 0.1**2, np.zeros((4, 4)))
    P0 = np.diag([4.0, 1.0, 1.0])
    truth = _truth(field, positions)
    x0 = truth[0] + rng.normal(size=(B, 3)) * np.sqrt(np.diag(P0))
    return rng, field, positions, spatial, noise, P0, truth, x0


def test_coloured_filter_beats_the_white_filter_on_correlated_noise() -> None:
    K, B = 40, 400
    rng, field, positions, spatial, noise, P0, truth, x0 = _correlated_problem(K, B, seed=5)
    w = spatial.sample(positions, rng, size=(B,))  # a static Gaussian field along the track, exact
    meas = field.value(positions) + w + 0.1 * rng.normal(size=(B, K, 4))
    coloured = run_coloured_filter(positions, meas, noise, spatial, x0, P0)
    white_noise = CooperativeNoise(
        noise.process, noise.measurement_matrix(4) + spatial.W(positions[0]), noise.hessian_error
    )
    white = run_cooperative_filter(positions, meas, white_noise, x0, P0)
    rmse = {name: np.sqrt(((r.states - truth) ** 2).mean(axis=0))[K // 2 :].mean(axis=0) for name, r in
            (("coloured", coloured), ("white", white))}  # fmt: skip
    # same runs, same seeds: the coloured filter's error is lower for z and both gradient components,
    # by more than the Monte Carlo spread of the difference (~1/sqrt(B) relative)
    assert np.all(rmse["coloured"] < (1 - 2 / np.sqrt(B)) * rmse["white"]), rmse
    # and the white filter, treating correlated noise as independent, is overconfident
    assert white.nees(truth).mean() > 3 * 3


def test_coloured_filters_are_consistent_for_markov_noise_and_agree_without_white_noise() -> None:
    K, B = 30, 500
    rng, field, positions, spatial, noise, P0, truth, x0 = _correlated_problem(K, B, seed=9)
    w = np.zeros((B, K, 4))
    w[:, 0] = rng.normal(size=(B, 4)) @ np.linalg.cholesky(spatial.W(positions[0])).T
    for k in range(1, K):  # noise that *is* the first-order model of docs/theory/cooperative.md, eq. cooperative.11
        A_w, Q_w = spatial.markov(positions[k], positions[k - 1])
        w[:, k] = w[:, k - 1] @ A_w.T + rng.normal(size=(B, 4)) @ np.linalg.cholesky(Q_w + 1e-12 * np.eye(4)).T
    meas = field.value(positions) + w + 0.1 * rng.normal(size=(B, K, 4))
    augmented = run_coloured_filter(positions, meas, noise, spatial, x0, P0, method="augmented")
    anees = augmented.nees(truth).mean(axis=0)
    lo, hi = stats.chi2.ppf([0.005, 0.995], 3 * B) / B
    assert lo < anees.mean() < hi  # time-averaged ANEES inside the 99 % band of a single step
    # differenced (Bryson–Henrikson) ignores the v_{k-1} correlation: conservative, never overconfident
    differenced = run_coloured_filter(positions, meas, noise, spatial, x0, P0, method="differenced")
    assert differenced.nees(truth).mean(axis=0)[1:].max() < hi
    # with no white noise both methods are exact and must give identical estimates
    exact = CooperativeNoise(noise.process, 0.0, np.zeros((4, 4)))
    H = np.broadcast_to(np.array([[0.3, 0.1], [0.1, -0.2]]), (K, 2, 2))
    a = run_coloured_filter(positions, meas[0], exact, spatial, x0[0], P0, H, method="augmented")
    d = run_coloured_filter(positions, meas[0], exact, spatial, x0[0], P0, H, method="differenced")
    np.testing.assert_allclose(d.states, a.states, atol=1e-9 * np.abs(a.states).max())
    np.testing.assert_allclose(d.covariances, a.covariances, atol=1e-9 * np.abs(a.covariances).max())


# ------------------------------------------------------------------------------------------ Gramians
def test_gramians_detect_a_non_rotating_line_and_match_a_direct_sum() -> None:
    K, window = 40, 5
    t = np.arange(K) * 0.2
    centers = np.stack([t, 0.0 * t], -1)  # moving along the line itself: Cd5.1 fails too
    line = np.array([[-0.5, 0.0], [0.5, 0.0]])
    rot = np.stack([np.cos(t), -np.sin(t), np.sin(t), np.cos(t)], -1).reshape(K, 2, 2)
    fixed = centers[:, None, :] + line
    rotating = centers[:, None, :] + line @ np.swapaxes(rot, -1, -2)
    noise = CooperativeNoise.from_sigmas(0.1, 0.5, 0.5)
    g_fixed, g_rot = gramians(fixed, noise, window), gramians(rotating, noise, window)
    assert np.all(np.isnan(g_fixed.observability_min[:window]))
    scale = np.abs(g_rot.observability[window:]).max()
    # N = 2 on a line sliding along itself: ∂z/∂y never seen (Cd5), zero up to round-off of a 3x3 eigvalsh
    assert np.all(np.abs(g_fixed.observability_min[window:]) < 1e-12 * scale)
    oblique = gramians(fixed + np.stack([0 * t, 0.3 * t], -1)[:, None, :], noise, window)
    assert np.all(oblique.observability_min[window:] > 1e-4 * scale)  # motion across the line: Cd5.1 holds
    assert np.all(g_rot.observability_min[window:] > 1e-3 * scale)  # rotating pair: observable
    assert np.all(g_rot.controllability_min[window:] > 0)
    # independent evaluation at one step: Φ(j, k) as products of one-step transitions A (Lemma 3.1)
    k = 20
    C, D = taylor_matrices(rotating)
    R = noise.total_measurement_covariance(D)
    J = np.zeros((3, 3))
    for j in range(k - window, k + 1):
        Phi_kj = np.eye(3)
        for i in range(j + 1, k + 1):
            Phi_kj = transition_matrix(centers[i] - centers[i - 1]) @ Phi_kj
        Phi_jk = np.linalg.inv(Phi_kj)
        J += Phi_jk.T @ C[j].T @ np.linalg.solve(R[j], C[j]) @ Phi_jk
    np.testing.assert_allclose(g_rot.observability[k], J, rtol=1e-12, atol=1e-12 * np.abs(J).max())
