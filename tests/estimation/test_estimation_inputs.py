"""Invalid arguments of the estimation classes are refused at once, naming the argument; valid edge cases are not.

Each refusal is a ``ValueError`` whose one-line message names the argument and what was expected (the cases a
review found silently accepted, or failing deep inside numpy). The companion tests keep the legitimate edge
cases working: a singular prior, pairs and formations that see no gradient at one instant (observability is a
window property, docs/theory/cooperative.md §4), a platform count that changes, noise-free models.
"""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest

from mobisense.estimation.checks import check_finite, check_finite_array, check_non_negative, check_positive
from mobisense.estimation.cooperative.filter import CooperativeKalmanFilter
from mobisense.estimation.cooperative.formation_design import design_cross_formation
from mobisense.estimation.cooperative.information_model import cross_formation
from mobisense.estimation.cooperative.noise_config import CooperativeNoise
from mobisense.estimation.cooperative.steady_state import cross_steady_state
from mobisense.estimation.tracking.range_ring import KHEPERA_MOUNT_ANGLES_DEG, RangeSensorRing
from mobisense.estimation.tracking.switching_filter import SwitchingKalmanFilter, random_walk_model

NOISE = CooperativeNoise.from_sigmas(0.1, 0.1, 0.1)
CROSS = cross_formation(1.0, 1.0)  # 4 platforms
BACKENDS = ["numpy"] + (["numba"] if importlib.util.find_spec("numba") is not None else [])


# ------------------------------------------------------------------------------------- shared checks
def test_scalar_and_array_checks_name_the_argument():
    assert check_positive("h", 2) == 2.0 and check_positive("limit", math.inf, allow_inf=True) == math.inf
    assert check_non_negative("q", 0.0) == 0.0 and check_finite("omega", -3) == -3.0
    for call, match in [
        (lambda: check_positive("h", 0.0), "h: expected a finite number > 0, got 0.0"),
        (lambda: check_positive("h", math.inf), "h: expected a finite number > 0, got inf"),
        (lambda: check_positive("h", "x"), "h: expected a finite number > 0, got 'x'"),
        (lambda: check_non_negative("q", -1e-300), "q: expected a finite number >= 0"),
        (lambda: check_finite("omega", math.nan), "omega: expected a finite number, got nan"),
        (lambda: check_finite_array("x", [1.0, math.nan], "(2,)"), "x: expected finite numbers, got 1 non-finite"),
        (lambda: check_finite_array("x", [1.0], "(2,)", lambda s: s == (2,)), r"x: expected .* \(2,\), got shape"),
    ]:
        with pytest.raises(ValueError, match=match):
            call()


# ------------------------------------------------------------------------ 1. CooperativeKalmanFilter
@pytest.mark.parametrize(
    "state,covariance,positions,match",
    [
        (np.zeros(3), -np.eye(3), CROSS, "initial_covariance: expected symmetric positive semidefinite.*-1"),
        (np.zeros(3), np.full((3, 3), np.nan), CROSS, "initial_covariance: expected finite numbers"),
        (np.zeros(3), np.eye(3)[:2], CROSS, r"initial_covariance: expected \(\[B,\] 3, 3\) matrices"),
        (np.array([np.nan, 0.0, 0.0]), np.eye(3), CROSS, "initial_state: expected finite numbers"),
        (np.zeros(2), np.eye(3), CROSS, r"initial_state: expected an array of shape \(\.\.\., 3\)"),
        (np.zeros(3), np.eye(3), np.zeros((4, 3)), r"initial_positions: .*\(\.\.\., N, 2\).*got shape \(4, 3\)"),
        (np.zeros(3), np.eye(3), np.zeros((0, 2)), r"initial_positions: .*N >= 1, got shape \(0, 2\)"),
        (np.zeros(3), np.eye(3), np.full((4, 2), np.inf), "initial_positions: expected finite numbers"),
    ],
    ids=["negative-definite", "nan-covariance", "covariance-shape", "nan-state", "state-shape", "positions-3d",
         "no-platforms", "infinite-positions"],
)  # fmt: skip
@pytest.mark.parametrize("backend", ["auto", "numpy"])
def test_cooperative_filter_refuses_a_bad_prior_or_positions(state, covariance, positions, match, backend):
    with pytest.raises(ValueError, match=match):
        CooperativeKalmanFilter(NOISE, state, covariance, positions, backend=backend)


def test_cooperative_filter_refuses_a_bad_initial_hessian():
    with pytest.raises(ValueError, match=r"initial_hessian: expected an array of shape \(\.\.\., 2, 2\)"):
        CooperativeKalmanFilter(NOISE, np.zeros(3), np.eye(3), CROSS, np.zeros(4))
    with pytest.raises(ValueError, match="initial_hessian: expected finite numbers"):
        CooperativeKalmanFilter(NOISE, np.zeros(3), np.eye(3), CROSS, np.full((2, 2), np.nan))


@pytest.mark.parametrize("backend", BACKENDS)
def test_cooperative_filter_steps_check_shapes(backend):
    filt = CooperativeKalmanFilter(NOISE, np.zeros(3), np.eye(3), CROSS, backend=backend)
    expected = r"measurements: expected shape \((\.\.\., )?4,?\), one per platform"  # numba: (4,)
    with pytest.raises(ValueError, match=expected + r".*got \(3,\)"):
        filt.update(np.zeros(3))
    with pytest.raises(ValueError, match=r"measurements: expected shape \((\.\.\., )?4,?\).*got \(\)"):
        filt.update(0.0)  # a scalar used to be broadcast to every platform
    filt.update(np.zeros(4))
    for bad in (np.zeros((0, 2)), np.zeros((4, 3)), np.zeros(2)):
        with pytest.raises(ValueError, match=r"positions: expected shape \(\.\.\., N, 2\) with N >= 1"):
            filt.predict(bad)


@pytest.mark.parametrize("backend", BACKENDS)
def test_cooperative_filter_accepts_singular_priors_and_formations_blind_to_the_gradient(backend):
    # a known initial value (zero variance) is a singular but valid prior
    known = np.diag([0.0, 1.0, 1.0])
    _, P = CooperativeKalmanFilter(NOISE, np.zeros(3), known, CROSS, backend=backend).update(np.zeros(4))
    assert P[0, 0] == pytest.approx(0.0, abs=1e-15) and np.all(np.isfinite(P))
    # one platform, coincident platforms, a pair: accepted; what one instant cannot see keeps its prior variance
    # and motion of the centre observes the gradient along it (docs/theory/cooperative.md §4: a window property)
    for positions in (np.array([[1.0, 2.0]]), np.zeros((4, 2)), np.array([[0.0, 0.0], [1.0, 0.0]])):
        filt = CooperativeKalmanFilter(NOISE, np.zeros(3), np.eye(3), positions, backend=backend)
        _, P = filt.update(np.zeros(len(positions)))
        filt.predict(positions + [1.0, 0.0])
        _, P = filt.update(np.zeros(len(positions)))
        assert P[1, 1] < 0.1  # the x-gradient, observed by moving along x
        assert P[2, 2] == pytest.approx(1.0 + NOISE.process[2, 2], rel=1e-12)  # the y-gradient: prior + M


def test_cooperative_filter_follows_a_change_of_platform_count():
    # a platform lost between steps: the estimate moves to the centre of the remaining ones (numpy and numba agree)
    results = []
    for backend in BACKENDS:
        filt = CooperativeKalmanFilter(NOISE, np.zeros(3), np.eye(3), CROSS, backend=backend)
        filt.update(np.array([0.1, -0.1, 0.2, 0.0]))
        filt.predict(CROSS[:3] + 0.5)
        results.append(filt.update(np.array([0.3, 0.1, 0.2])))
    for x, P in results[1:]:
        np.testing.assert_allclose(x, results[0][0], rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(P, results[0][1], rtol=1e-12, atol=1e-14)


def test_batched_cooperative_filter_checks_every_prior():
    priors = np.stack([np.eye(3), np.diag([1.0, -1e-3, 1.0])])
    with pytest.raises(ValueError, match="initial_covariance: expected symmetric positive semidefinite.*-0.001"):
        CooperativeKalmanFilter(NOISE, np.zeros((2, 3)), priors, CROSS)
    x, P = CooperativeKalmanFilter(NOISE, np.zeros((2, 3)), np.abs(priors), CROSS).update(np.zeros((2, 4)))
    assert x.shape == (2, 3) and P.shape == (2, 3, 3)


# ----------------------------------------------------------------------------- 2. SwitchingKalmanFilter
@pytest.mark.parametrize(
    "args,match",
    [
        ((6, 0.0, 1.0), "sample_time: expected a finite number > 0, got 0.0"),
        ((6, -1.0, 1.0), "sample_time: expected a finite number > 0, got -1.0"),
        ((6, math.nan, 1.0), "sample_time: expected a finite number > 0, got nan"),
        ((6, 0.1, -1.0), "acceleration_std: expected a finite number >= 0, got -1.0"),
        ((6, 0.1, math.inf), "acceleration_std: expected a finite number >= 0, got inf"),
        ((-1, 0.1, 1.0), "n_pairs: expected an integer >= 1 .*got -1"),
        ((0, 0.1, 1.0), "n_pairs: expected an integer >= 1"),
        ((6.0, 0.1, 1.0), "n_pairs: expected an integer >= 1 .*got 6.0"),
        ((6, 0.1, 1.0, "closest", -1.0), "initial_velocity_std: expected a finite number >= 0"),
    ],
)
def test_switching_filter_refuses_bad_settings(args, match):
    with pytest.raises(ValueError, match=match):
        SwitchingKalmanFilter(*args)


def test_random_walk_model_refuses_a_bad_sample_time():
    with pytest.raises(ValueError, match="sample_time: expected a finite number > 0"):
        random_walk_model(math.nan, 1.0)


def test_switching_filter_refuses_bad_pair_measurements():
    skf = SwitchingKalmanFilter(2, 0.1, 1.0)
    active, positions = np.ones(2, dtype=bool), np.zeros((2, 2))
    bad = np.stack([np.eye(2), -np.eye(2)])
    with pytest.raises(ValueError, match=r"position_covariances: expected a symmetric positive semidefinite \(2, 2\) "
                                         r"matrix for the active pair 1, got \[\[-1.0"):  # fmt: skip
        skf.step(active, positions, bad)
    asymmetric = np.stack([np.eye(2), [[1.0, 0.5], [0.0, 1.0]]])
    with pytest.raises(ValueError, match="position_covariances: expected a symmetric positive semidefinite"):
        skf.step(active, positions, asymmetric)
    with pytest.raises(ValueError, match="positions: expected a finite position for the active pair 0"):
        skf.step(active, np.array([[np.nan, 0.0], [0.0, 0.0]]), np.stack([np.eye(2)] * 2))
    with pytest.raises(ValueError, match=r"expected shapes \(2,\), \(2, 2\), \(2, 2, 2\) for 2 pairs"):
        skf.step(np.ones(3, dtype=bool), positions, np.stack([np.eye(2)] * 2))
    assert not skf.initialised  # nothing was taken in


def test_switching_filter_accepts_noise_free_models_and_nan_for_inactive_pairs():
    skf = SwitchingKalmanFilter(2, 0.1, 0.0, "closest", 0.0)  # constant velocity, known (zero) initial velocity
    positions = np.array([[1.0, 2.0], [np.nan, np.nan]])
    covariances = np.stack([np.zeros((2, 2)), np.full((2, 2), np.nan)])  # a noise-free fix is PSD
    step = skf.step(np.array([True, False]), positions, covariances)
    np.testing.assert_array_equal(step.state, [1.0, 2.0, 0.0, 0.0])
    step = skf.step(np.array([False, False]), np.full((2, 2), np.nan), np.full((2, 2, 2), np.nan))
    np.testing.assert_array_equal(step.state, [1.0, 2.0, 0.0, 0.0])


# --------------------------------------------------------------------------------- 3. cross_steady_state
@pytest.mark.parametrize(
    "args,match",
    [
        ((0.0, 0.0, 0.1, 0.1, 0.1), "a: expected a finite number > 0, got 0.0"),
        ((1.0, 0.0, 0.1, 0.1, 0.1), "b: expected a finite number > 0, got 0.0"),
        ((math.nan, 1.0, 0.1, 0.1, 0.1), "a: expected a finite number > 0, got nan"),
        ((1.0, 1.0, 0.0, 0.1, 0.1), "sigma_process: expected a finite number > 0"),
        ((1.0, 1.0, 0.1, 0.0, 0.1), "sigma_measurement: expected a finite number > 0"),
        ((1.0, 1.0, 0.1, 0.1, -0.1), "sigma_hessian: expected a finite number >= 0"),
    ],
)
def test_cross_steady_state_refuses_degenerate_crosses_and_noise(args, match):
    with pytest.raises(ValueError, match=match):
        cross_steady_state(*args)


def test_cross_steady_state_accepts_an_exact_hessian():
    with np.errstate(all="raise"):
        state = cross_steady_state(1.0, 2.0, 0.1, 0.1, 0.0)
    assert np.all(np.isfinite(state.prior)) and state.trace > 0


# ----------------------------------------------------------------------------------- 4. CooperativeNoise
@pytest.mark.parametrize("R", [np.zeros(0), np.zeros((0, 0))], ids=["(0,)", "(0, 0)"])
def test_noise_refuses_an_empty_measurement_covariance(R):
    with pytest.raises(ValueError, match=r"measurement covariance R: expected .* with N >= 1, got shape \(0"):
        CooperativeNoise(np.eye(3), R, np.eye(4))


def test_noise_accepts_a_single_platform_and_a_noise_free_one():
    assert CooperativeNoise(np.eye(3), np.ones(1), np.eye(4)).measurement_matrix(1).shape == (1, 1)
    assert CooperativeNoise(np.eye(3), 0.0, np.eye(4)).measurement_matrix(2).sum() == 0.0


# ------------------------------------------------------------------------------------ 5. RangeSensorRing
ANGLES = np.deg2rad(KHEPERA_MOUNT_ANGLES_DEG)
RING = dict(mount_radius=0.25, mount_angles=ANGLES, headings=ANGLES, field_of_view=math.radians(100), max_range=2.5,
            noise_std=0.002)  # fmt: skip


@pytest.mark.parametrize(
    "change,match",
    [
        (dict(field_of_view=-1.0), "field_of_view: expected a finite number > 0, got -1.0"),
        (dict(field_of_view=7.0), r"field_of_view: expected a full opening angle in \(0, 2π\] rad, got 7"),
        (dict(headings=ANGLES[:7]), r"headings: expected an array of shape \(8,\), one per sensor, got shape \(7,\)"),
        (dict(mount_angles=ANGLES[:1], headings=ANGLES[:1]), r"mount_angles: .*S >= 2, got shape \(1,\)"),
        (dict(mount_angles=np.full(8, np.nan)), "mount_angles: expected finite numbers"),
        (dict(mount_radius=0.0), "mount_radius: expected a finite number > 0"),
        (dict(max_range=math.nan), "max_range: expected a finite number > 0"),
        (dict(noise_std=-0.1), "noise_std: expected a finite number >= 0"),
        (dict(target_radius=-0.1), "target_radius: expected a finite number >= 0"),
        (dict(pairs=np.array([[0, 8]])), "pairs: expected P >= 1 rows .* indices in 0 … 7"),
        (dict(pairs=np.array([[2, 2]])), "pairs: expected P >= 1 rows of two different"),
        (dict(pairs=np.zeros((0, 2), dtype=int)), "pairs: expected P >= 1 rows"),
    ],
)  # fmt: skip
def test_range_ring_refuses_an_impossible_layout(change, match):
    with pytest.raises(ValueError, match=match):
        RangeSensorRing(**{**RING, **change})


def test_range_ring_accepts_an_omnidirectional_noise_free_ring():
    ring = RangeSensorRing(**{**RING, "field_of_view": 2 * math.pi, "noise_std": 0.0, "mount_angles": list(ANGLES)})
    assert ring.mount_angles.shape == (8,) and ring.visible(np.zeros(3), np.array([0.0, -1.0])).sum() >= 2


def test_cross_design_with_degenerate_noise_says_the_steady_state_is_not_finite():
    # the optimiser's optimum is NaN here; cross_steady_state refuses NaN, so the design says why first
    with pytest.raises(RuntimeError, match="the steady state is not finite"):
        design_cross_formation(1e-90, 1e90, 1e90, ((0.5, 2.0), (0.5, 2.0)))
