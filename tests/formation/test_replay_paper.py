"""Issue 17, Zhang & Leonard 2010: Fig. 5 shape adaptation, Fig. 3 noisy-curve tracking, the two-charges level error."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mobisense.core.config import load_config, parse_config
from mobisense.formation.replay.results import replay_dataset
from mobisense.formation.replay.scenario import FieldReplayScenario
from mobisense.formation.replay.simulation import build_system, simulate

PROBLEMS = Path(__file__).resolve().parents[2] / "problems"


def replay(name: str, **changes):
    """Dataset of a scenario with top-level or ``filter.`` overrides (``filter__key=value``)."""
    data = load_config(PROBLEMS / f"{name}.yaml", FieldReplayScenario).model_dump(mode="python")
    for key, value in changes.items():
        *path, last = key.split("__")
        target = data
        for part in path:
            target = target[part]
        target[last] = value
    scenario = parse_config(data, FieldReplayScenario, source="@")
    system = build_system(scenario, PROBLEMS / f"{name}.yaml")
    return replay_dataset(simulate(system), system, scenario.seed), system


def test_constant_noise_freezes_step_3a_and_the_hessian_error_model_frees_it() -> None:
    """8 h of the isotherm replay. Constant U: a(t) moves < 5 m in 3-8 h (measured 1.3 m, a = 1.918 km).

    U_k = σ3² I + ρ² diag(vec Ĥ_F)² (ρ = 1): a narrows to 1.83 km at 3.6 h (κ peaks, 0.25/km, at 4.1 h), is 1.885 km
    at 4 h and widens to 3.44 km at 8 h where the isotherm straightens (κ = 0.04/km); we require ≥ 1 km of change.
    """
    ds, _ = replay("replay_isotherm13", duration=8.0)
    t, a = ds["time"].values, ds["a"].values
    late = (t >= 3.0) & (t <= 8.0)
    assert np.ptp(a[late]) < 0.005
    ds, _ = replay("replay_isotherm13_adaptive", duration=8.0)
    t, a = ds["time"].values, ds["a"].values
    a4, a8 = a[np.abs(t - 4.0).argmin()], a[np.abs(t - 8.0).argmin()]
    assert a4 < 1.95 and a8 - a4 > 1.0


def _mean_abs_curvature(path: np.ndarray, step: float = 0.05) -> float:
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    su = np.arange(0.0, s[-1], step)
    p = np.stack([np.interp(su, s, path[:, i]) for i in range(2)], axis=-1)
    v = np.gradient(p, step, axis=0)
    acc = np.gradient(v, step, axis=0)
    k = (v[:, 0] * acc[:, 1] - v[:, 1] * acc[:, 0]) / np.linalg.norm(v, axis=1) ** 3
    return float(np.mean(np.abs(k[5:-5])))


def test_fig3_the_filtered_centre_path_is_smoother_than_the_noisy_level_curve() -> None:
    """Seed Fig. 3. Mean |curvature| (1/L): true curve 0.19, noisy curve z + w = 4 0.96, centre with the filter 0.22,
    without (quadratic fit to the last 6 samples) 1.27; RMS |z − 4| 0.118 vs 0.404 (seed 2; seeds 3, 4 alike)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with_filter, system = replay("replay_two_charges_fig3")
    without, _ = replay("replay_two_charges_fig3", filter__estimator="window_fit")
    scenario = system.scenario
    w = scenario.spatial_noise.to_noise().realisation(np.random.default_rng(scenario.seed))  # the replay's first draw
    x, y = np.meshgrid(np.linspace(-10, 10, 801), np.linspace(-7, 7, 561))
    grid = np.stack([x, y], axis=-1)
    with np.errstate(divide="ignore"):
        noisy = system.field.value(grid) + w(grid.reshape(-1, 2)).reshape(x.shape)
    contour = plt.contour(x, y, noisy, levels=[4.0])
    noisy_curve = max(contour.allsegs[0], key=len)
    plt.close("all")
    t = with_filter["time"].values
    rough = {
        name: _mean_abs_curvature(ds["center"].values[t >= 5.0])
        for name, ds in (("kf", with_filter), ("none", without))
    }
    assert rough["kf"] < 0.5 * _mean_abs_curvature(noisy_curve) and rough["kf"] < 0.5 * rough["none"]
    half = t >= 20.0
    rms = {
        name: float(np.sqrt(np.mean((ds["z_true"].values[half] - 4.0) ** 2)))
        for name, ds in (("kf", with_filter), ("none", without))
    }
    assert rms["kf"] < 0.5 * rms["none"]


def test_two_charges_level_error_is_the_hessian_fits_curvature_offset_not_noise() -> None:
    """20 T runs, RMS |z − 4| over [10, 20]: shipped 0.086, noise-free 0.071, noise-free with the true Hessian 0.025.

    Removing all noise keeps ≥ 70 % of the error; replacing the window-fit Hessian removes ≥ 50 % of what is left.
    """

    def rms(**changes):
        ds, _ = replay("replay_two_charges", duration=20.0, **changes)
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
