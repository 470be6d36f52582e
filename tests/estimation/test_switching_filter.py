"""Directional range-sensor ring, triangulation, activity test and switching Kalman filter.

Theory: docs/theory/leader_follower.md §6–§7; source: Karasalo & Hu (2010), §7.
"""

from __future__ import annotations

import math

import control
import numpy as np
import pytest
from scipy.linalg import expm

from mobisense.estimation.tracking.range_ring import (
    KHEPERA_MOUNT_ANGLES_DEG,
    KHEPERA_PAIRS,
    RangeSensorRing,
    cosine_ratio,
    triangulate,
)
from mobisense.estimation.tracking.switching_filter import (
    C_POSITION,
    SwitchingKalmanFilter,
    merge_closest,
    merge_information,
    random_walk_model,
)

ANGLES = np.deg2rad(KHEPERA_MOUNT_ANGLES_DEG)


def _ring(noise_std: float = 0.002, pairs=KHEPERA_PAIRS, target_radius: float = 0.0) -> RangeSensorRing:
    return RangeSensorRing(
        mount_radius=0.25,
        mount_angles=ANGLES,
        headings=ANGLES,
        field_of_view=math.radians(100),
        max_range=2.5,
        noise_std=noise_std,
        target_radius=target_radius,
        pairs=np.asarray(pairs) - 1,
    )


def test_triangulation_is_exact_for_noise_free_readings():
    """Eqs. 42–46: every active pair returns the true target position (any pose, target radius r)."""
    rng = np.random.default_rng(0)
    ring = _ring(target_radius=0.05)
    checked = 0
    for _ in range(300):
        pose = np.array([*rng.uniform(-5, 5, 2), rng.uniform(-np.pi, np.pi)])
        bearing, distance = rng.uniform(-np.pi, np.pi), rng.uniform(0.4, 2.5)
        target = pose[:2] + distance * np.array([math.cos(pose[2] + bearing), math.sin(pose[2] + bearing)])
        pairs = ring.pair_measurements(pose, ring.read(pose, target))
        for position in pairs.positions[pairs.active]:
            # law of cosines on O(1) lengths, coordinates up to 7.5 m: a few ulps of 10 m
            np.testing.assert_allclose(position, target, rtol=0, atol=1e-12)
            checked += 1
    assert checked > 200  # most random geometries have at least one active pair


def test_mirror_choice_does_not_depend_on_pair_order():
    """The solution is taken on the outer side of the baseline, for either sensor order in the pair."""
    ring, reversed_ring = _ring(), _ring(pairs=[(b, a) for a, b in KHEPERA_PAIRS])
    pose = np.array([0.3, -0.2, 0.4])
    for bearing in np.linspace(-1.5, 1.5, 13):
        target = pose[:2] + 1.3 * np.array([math.cos(pose[2] + bearing), math.sin(pose[2] + bearing)])
        a = ring.pair_measurements(pose, ring.read(pose, target))
        b = reversed_ring.pair_measurements(pose, reversed_ring.read(pose, target))
        np.testing.assert_array_equal(a.active, b.active)
        np.testing.assert_allclose(a.positions[a.active], b.positions[b.active], rtol=0, atol=1e-12)


def test_triangulation_covariance_matches_finite_differences():
    """R = σ² U⁻¹U⁻ᵀ against σ² J Jᵀ with J = ∂p/∂(δ_q, δ_{q−1}) by central differences of triangulate."""
    ring = _ring(noise_std=0.01)
    pose = np.zeros(3)
    sensors = ring.sensor_positions(pose)
    for bearing in (0.9, 0.5, 0.0, -0.6):
        target = 1.2 * np.array([math.cos(bearing), math.sin(bearing)])
        pairs = ring.pair_measurements(pose, ring.read(pose, target))
        for j in np.flatnonzero(pairs.active):
            q_prev, q = ring.pairs[j]
            delta = np.hypot(*(target - sensors[[q, q_prev]]).T)
            h = 1e-6
            J = np.empty((2, 2))
            for c in range(2):
                step = np.zeros(2)
                step[c] = h
                plus = triangulate(sensors[q], sensors[q_prev], *(delta + step), pose[:2])
                minus = triangulate(sensors[q], sensors[q_prev], *(delta - step), pose[:2])
                J[:, c] = (plus - minus) / (2 * h)
            # central differences: O(h²) truncation, O(ε/h) round-off ≈ 1e-10 relative to |J| ~ 10
            np.testing.assert_allclose(pairs.covariances[j], 0.01**2 * J @ J.T, rtol=1e-6, atol=1e-12)


def test_activity_test_rejects_impossible_pairs():
    """Definition 1: both sensors must read, and eq. 48, (cos ψ)² < 1, i.e. a real triangle (Δs, δ_q, δ_{q−1})."""
    baseline = 0.2
    assert cosine_ratio(np.array(baseline), np.array(1.0), np.array(1.05)) ** 2 < 1  # a triangle
    assert cosine_ratio(np.array(baseline), np.array(1.0), np.array(1.3)) ** 2 > 1  # |δ_q − δ_{q−1}| > Δs
    assert cosine_ratio(np.array(baseline), np.array(0.05), np.array(0.1)) ** 2 > 1  # δ_q + δ_{q−1} < Δs
    assert cosine_ratio(np.array(baseline), np.array(1.0), np.array(1.2)) ** 2 == pytest.approx(1.0)  # degenerate
    ring = _ring()
    pose = np.zeros(3)
    target = np.array([1.0, 0.0])
    readings = ring.read(pose, target)
    good = ring.pair_measurements(pose, readings)
    assert good.active[2]  # pair p3 = (s3, s4) straddles the heading
    s3, s4 = 2, 3
    baseline = np.hypot(*(ring.sensor_positions(pose)[s3] - ring.sensor_positions(pose)[s4]))
    for bad in ({s3: readings[s4] + 1.5 * baseline}, {s3: 0.3 * baseline, s4: 0.3 * baseline}, {s4: np.nan}):
        corrupted = readings.copy()
        for index, value in bad.items():
            corrupted[index] = value
        pairs = ring.pair_measurements(pose, corrupted)
        assert not pairs.active[2]
        assert np.all(np.isnan(pairs.positions[2]))


def test_sensor_visibility_cone_and_range():
    ring = _ring()
    pose = np.zeros(3)
    assert np.all(np.isnan(ring.read(pose, np.array([3.5, 0.0]))))  # beyond max_range
    behind = ring.visible(pose, np.array([-1.0, 0.0]))
    np.testing.assert_array_equal(np.flatnonzero(behind), [6, 7])  # only the rear sensors s7, s8
    ahead = ring.visible(pose, np.array([1.0, 0.0]))
    assert ahead[2] and ahead[3] and not ahead[6] and not ahead[7]


def test_random_walk_model_is_the_exact_discretisation_of_eq38():
    F = np.zeros((4, 4))
    F[0, 2] = F[1, 3] = 1.0
    A, Q = random_walk_model(0.1, 2.0)
    np.testing.assert_allclose(A, expm(F * 0.1), rtol=0, atol=1e-15)
    G = np.vstack([0.005 * np.eye(2), 0.1 * np.eye(2)])  # eq. 40
    np.testing.assert_allclose(Q, 4.0 * G @ G.T, rtol=1e-15)


def test_sub_filter_covariance_converges_to_the_dare_solution():
    """Stationary target, noise-free readings (constant R): P → the Riccati fixed point from python-control's dare."""
    ring = _ring(noise_std=0.01, pairs=[(2, 3)])
    pose = np.zeros(3)
    target = 1.1 * np.array([math.cos(0.5), math.sin(0.5)])
    pairs = ring.pair_measurements(pose, ring.read(pose, target))
    assert pairs.active[0]
    skf = SwitchingKalmanFilter(1, 0.1, 1.0, "closest", 1.0)
    for _ in range(500):
        earlier = skf.step(pairs.active, pairs.positions, pairs.covariances)
    for _ in range(100):
        step = skf.step(pairs.active, pairs.positions, pairs.covariances)
    # converged: the recursion no longer moves P (so any remaining difference to dare would be a model error)
    np.testing.assert_allclose(step.covariance, earlier.covariance, rtol=1e-12, atol=1e-16)
    A, Q = random_walk_model(0.1, 1.0)
    R = pairs.covariances[0]
    X, _, _ = control.dare(A.T, C_POSITION.T, Q, R)  # steady prior covariance (estimation dual)
    S = C_POSITION @ X @ C_POSITION.T + R
    P_post = X - X @ C_POSITION.T @ np.linalg.solve(S, C_POSITION @ X)
    # dare solves to ~1e-12 relative; 1e-8 leaves room for the conditioning of the 4×4 Riccati equation
    np.testing.assert_allclose(step.covariance, P_post, rtol=1e-8, atol=1e-14)
    np.testing.assert_allclose(step.state, [*target, 0.0, 0.0], rtol=0, atol=1e-10)


def test_merges():
    states = np.array([[0.0, 0.0, 1.0, 0.0], [0.3, 0.1, 0.9, 0.1], [1.0, 1.0, 0.0, 0.0]])
    covariances = np.stack([np.eye(4), 2 * np.eye(4), 4 * np.eye(4)])
    x, P, index = merge_closest(states, covariances, np.array([0.25, 0.15, 0.0, 0.0]))
    assert index == 1 and np.array_equal(x, states[1])
    assert merge_closest(states, covariances, None)[2] == 0  # no prior: smallest position variance
    # covariance intersection with uniform weights: information-weighted mean, P⁻¹ = mean of P_j⁻¹
    x, P, index = merge_information(states, covariances, None)
    weights = np.array([1.0, 0.5, 0.25])
    np.testing.assert_allclose(x, weights @ states / weights.sum(), rtol=1e-14)
    np.testing.assert_allclose(P, np.eye(4) / weights.mean(), rtol=1e-14)
    assert index == -1
    # consistency whatever the correlation: fusing an estimate with itself does not shrink its covariance
    x, P, _ = merge_information(states[:1].repeat(2, 0), covariances[:1].repeat(2, 0), None)
    np.testing.assert_allclose(P, covariances[0], rtol=1e-14)


@pytest.mark.slow
@pytest.mark.parametrize("merge", ["closest", "information"])
def test_switching_filter_error_stays_bounded_across_sensor_boundaries(merge):
    """A target sweeping the front half-plane of a stationary ring crosses every pair boundary and two gaps.

    The estimate must stay statistically consistent (normalised error within χ² bounds) and bounded
    throughout, including while coasting through the gaps where no pair is active.
    """
    ring = _ring(noise_std=0.002)  # σ·range/baseline ≪ 1: the linearised pair covariance is valid (NEES ≈ 2)
    pose = np.zeros(3)
    h, radius, rate = 0.01, 1.0, 0.5
    nees, errors, selected, any_active = [], [], [], []
    for seed in range(3):
        rng = np.random.default_rng(seed)
        skf = SwitchingKalmanFilter(ring.n_pairs, h, 1.0, merge, 1.0)  # centripetal 0.25 m/s² ≪ q^½ = 1
        for k in range(592):
            angle = 1.48 - rate * h * k  # 85° to −85°
            target = radius * np.array([math.cos(angle), math.sin(angle)])
            pairs = ring.pair_measurements(pose, ring.read(pose, target, rng))
            step = skf.step(pairs.active, pairs.positions, pairs.covariances)
            any_active.append(pairs.active.any())
            if not skf.initialised:
                continue
            e = step.state[:2] - target
            errors.append(float(np.hypot(*e)))
            nees.append(float(e @ np.linalg.solve(step.covariance[:2, :2], e)))
            selected.append(step.selected)
    nees = np.asarray(nees)
    assert not all(any_active)  # the sweep does cross gaps with no active pair
    if merge == "closest":
        assert set(selected) >= {0, 1, 2, 3, 4}  # every front pair was used
    # consistency: E[NEES] = 2 for a 2-D position; ≈ 90 effective samples (correlation ~20 steps) give a
    # standard error ≈ 0.2 on the mean — the band [1, 3] is 5 standard errors wide
    assert 1.0 < nees.mean() < 3.0
    # per-sample χ²₂ quantile at 1 − 1e-6 (27.6): no outlier over the 1 770 samples
    assert nees.max() < 27.6
    # bounded: a handful of σ_lateral (σ·range/baseline ≈ 0.002·1/0.09 ≈ 0.02 m) even through the gaps
    assert max(errors) < 0.05
