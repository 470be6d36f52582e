"""Zhang & Leonard (2010), §VII: Fig. 5 shape adaptation, Fig. 3 noisy-curve tracking, the two-charges level error.

Theory: docs/theory/replay.md §2.5–§2.7.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mobisense.core.config import load_config, parse_config
from mobisense.estimation.cooperative.noise_config import CooperativeNoise
from mobisense.estimation.fields.library import QuadraticField
from mobisense.formation.replay.estimator import ClosedLoopEstimator, WindowHessian
from mobisense.formation.replay.results import mean_abs_curvature, replay_dataset
from mobisense.formation.replay.scenario import FieldReplayScenario
from mobisense.formation.replay.simulation import build_system, simulate

PROBLEMS = Path(__file__).resolve().parents[2] / "problems"


def replay(name: str, **changes):
    """Dataset, system and record of a scenario with top-level or ``filter.`` overrides (``filter__key=value``)."""
    data = load_config(PROBLEMS / f"{name}.yaml", FieldReplayScenario).model_dump(mode="python")
    for key, value in changes.items():
        *path, last = key.split("__")
        target = data
        for part in path:
            target = target[part]
        target[last] = value
    scenario = parse_config(data, FieldReplayScenario, source="@")
    system = build_system(scenario, PROBLEMS / f"{name}.yaml")
    record = simulate(system)
    return replay_dataset(record, system, scenario.seed), system, record


def _estimator(rho: float, **options) -> ClosedLoopEstimator:
    field = QuadraticField(hessian=[[0.4, -0.3], [-0.3, 1.1]], gradient=[1.0, 2.0], value=3.0)
    noise = CooperativeNoise.from_sigmas(0.1, 0.05, 0.02)
    return ClosedLoopEstimator(noise, None, "fixed", field, relative_error=rho, **options)


def test_hessian_error_model_is_relative_in_the_level_curve_frame() -> None:
    """U_k of eq. replay.10: σ3² I + ρ² diag(vec Ĥ)² for a gradient along y (F = I); it rotates with the field."""
    rho, sigma3 = 0.7, 0.02
    H = np.array([[0.3, -0.2], [-0.2, 0.9]])
    aligned = _estimator(rho).hessian_error(H, np.array([0.0, 2.0]))
    expected = sigma3**2 * np.eye(4) + np.diag(rho**2 * H.T.reshape(4) ** 2)
    np.testing.assert_allclose(aligned, expected, rtol=0, atol=1e-15)
    # the platforms 1-2 entry: σ3² + ρ² (‖∇z‖ κ)² with κ = −H_F,11 / ‖∇z‖ along the level curve
    assert aligned[0, 0] == pytest.approx(sigma3**2 + (rho * H[0, 0]) ** 2, abs=1e-15)
    # rotate field and frame by φ: U transforms as vec(R X R') = (R ⊗ R) vec X, so the model is frame-free
    phi = 0.83
    R = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
    rotated = _estimator(rho).hessian_error(R @ H @ R.T, R @ np.array([0.0, 2.0]))
    T = np.kron(R, R)
    np.testing.assert_allclose(rotated, T @ aligned @ T.T, rtol=0, atol=1e-15)
    assert np.array_equal(_estimator(0.0).hessian_error(H, np.array([0.0, 2.0])), sigma3**2 * np.eye(4))


def test_window_fit_estimate_is_exact_on_a_quadratic_field() -> None:
    """The no-filter estimate (window_fit): value and gradient moved to the current centre, exact on a quadratic."""
    field = QuadraticField(hessian=[[0.4, -0.3], [-0.3, 1.1]], gradient=[1.0, 2.0], value=3.0)
    source = WindowHessian(window=3)
    for k in range(4):  # a rotating pair moving along x: rank 6 after three samples
        angle = 0.6 * k
        arm = 0.5 * np.array([np.cos(angle), np.sin(angle)])
        r = np.array([0.2 * k, 0.1]) + np.stack([arm, -arm])
        fitted = source.fit(r, field.value(r))
        assert (fitted is None) == (k < 2)
    state, hessian = fitted
    centre = r.mean(axis=0)
    truth = np.concatenate([[field.value(centre)], field.gradient(centre)])
    np.testing.assert_allclose(state, truth, rtol=0, atol=1e-12)  # least squares on exact data: round-off
    np.testing.assert_allclose(hessian, field.H, rtol=0, atol=1e-12)


@pytest.mark.slow  # closed-loop replays of 8-40 time units
def test_constant_noise_freezes_step_3a_and_the_hessian_error_model_frees_it() -> None:
    """8 h of the isotherm replay. Constant U: a(t) moves < 5 m in 3-8 h (measured 1.3 m, a = 1.918 km).

    U_k = σ3² I + ρ² diag(vec Ĥ_F)² (ρ = 1): a narrows to 1.83 km at 3.6 h (κ peaks, 0.25/km, at 4.1 h), is 1.885 km
    at 4 h and widens to 3.44 km at 8 h where the isotherm straightens (κ = 0.04/km); we require ≥ 1 km of change.
    """
    ds, _, _ = replay("replay_isotherm13", duration=8.0)
    t, a = ds["time"].values, ds["a"].values
    late = (t >= 3.0) & (t <= 8.0)
    assert np.ptp(a[late]) < 0.005
    ds, _, _ = replay("replay_isotherm13_adaptive", duration=8.0)
    t, a = ds["time"].values, ds["a"].values
    a4, a8 = a[np.abs(t - 4.0).argmin()], a[np.abs(t - 8.0).argmin()]
    assert a4 < 1.95 and a8 - a4 > 1.0


@pytest.mark.slow  # closed-loop replays of 8-40 time units
def test_fig3_the_filtered_centre_path_is_smoother_than_the_noisy_level_curve() -> None:
    """Fig. 3. Mean |curvature| (1/L): true curve 0.19, noisy curve z + w = 4 0.96, centre with the filter 0.22,
    without (quadratic fit to the last 6 samples) 1.27; RMS |z − 4| 0.118 vs 0.404 (seed 2; seeds 3, 4 alike)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with_filter, system, record = replay("replay_two_charges_fig3")
    without, _, _ = replay("replay_two_charges_fig3", filter__estimator="window_fit")
    w = record.spatial_noise  # the noise realisation of the filtered run
    x, y = np.meshgrid(np.linspace(-10, 10, 801), np.linspace(-7, 7, 561))
    grid = np.stack([x, y], axis=-1)
    with np.errstate(divide="ignore"):
        noisy = system.field.value(grid) + w(grid.reshape(-1, 2)).reshape(x.shape)
    contour = plt.contour(x, y, noisy, levels=[4.0])
    noisy_curve = max(contour.allsegs[0], key=len)
    plt.close("all")
    t = with_filter["time"].values
    rough = {
        name: mean_abs_curvature(ds["center"].values[t >= 5.0])
        for name, ds in (("kf", with_filter), ("none", without))
    }
    assert rough["kf"] < 0.5 * mean_abs_curvature(noisy_curve) and rough["kf"] < 0.5 * rough["none"]
    half = t >= 20.0
    rms = {
        name: float(np.sqrt(np.mean((ds["z_true"].values[half] - 4.0) ** 2)))
        for name, ds in (("kf", with_filter), ("none", without))
    }
    assert rms["kf"] < 0.5 * rms["none"]


@pytest.mark.slow  # closed-loop replays of 8-40 time units
def test_two_charges_level_error_is_the_hessian_fits_curvature_offset_not_noise() -> None:
    """20 T runs, RMS |z − 4| over [10, 20]: shipped 0.086, noise-free 0.071, noise-free with the true Hessian 0.025.

    Removing all noise keeps ≥ 70 % of the error; replacing the window-fit Hessian removes ≥ 50 % of what is left.
    """

    def rms(**changes):
        ds, _, _ = replay("replay_two_charges", duration=20.0, **changes)
        t, z = ds["time"].values, ds["z_true"].values
        return float(np.sqrt(np.mean((z[t >= 10.0] - 4.0) ** 2)))

    shipped = rms()
    noise_free = rms(
        spatial_noise=None, filter__noise={"sigma_process": 0.05, "sigma_measurement": 1e-6, "sigma_hessian": 0.05}
    )
    exact_hessian = rms(
        spatial_noise=None,
        filter__hessian="true_field",
        filter__noise={"sigma_process": 0.05, "sigma_measurement": 1e-6, "sigma_hessian": 0.05},
    )
    assert noise_free > 0.7 * shipped
    assert exact_hessian < 0.5 * noise_free


def test_mean_abs_curvature_of_circles_and_lines() -> None:
    """|κ| = 0.5 on a circle of radius 2 (400-point polygon, linear resampling: within 0.1 %); 0 on a line."""
    theta = np.linspace(0.0, 1.5 * np.pi, 400)
    assert mean_abs_curvature(2.0 * np.stack([np.cos(theta), np.sin(theta)], axis=-1)) == pytest.approx(0.5, rel=1e-3)
    assert mean_abs_curvature(np.stack([np.linspace(0, 5, 7), np.linspace(1, 3, 7)], axis=-1)) < 1e-9
