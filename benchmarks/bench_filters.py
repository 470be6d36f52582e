"""Cooperative Kalman filter throughput against filterpy, measured in one run (ratios, not absolutes).

    .venv/bin/python benchmarks/bench_filters.py [--steps 4000] [--runs 20000]

1. single run: ``run_cooperative_filter`` (compiled CasADi rollout, and the numpy engine) vs filterpy's
   ``KalmanFilter`` stepping the same model (F, B·u, Q, H, R set at every step) in a Python loop;
   the estimates are checked to agree before anything is timed. Target: >= 5x filterpy per step.
2. batched Monte Carlo (numpy, batch first): run-steps per second with the trajectory shared by all runs
   (the covariance recursion runs once) and with one trajectory per run. Target: >= 1e6 run-steps/s.
"""

from __future__ import annotations

import argparse

import numpy as np
from filterpy.kalman import KalmanFilter
from timing import best_time

from mobisense.estimation.cooperative import CooperativeNoise, cross_formation, model_sequence, run_cooperative_filter


def problem(K: int, rng: np.random.Generator):  # noqa: ANN201
    s = np.linspace(0.0, 0.01 * K, K)
    positions = cross_formation(1.0, 1.4, center=np.stack([s, np.sin(s)], -1), orientation=0.2 * np.sin(s))
    H = np.broadcast_to(np.array([[0.3, 0.1], [0.1, -0.2]]), (K, 2, 2))
    noise = CooperativeNoise.from_sigmas(0.05, 0.3, 0.2)
    measurements = rng.normal(size=(K, 4))
    return positions, H, noise, measurements


def filterpy_run(positions, H, noise, measurements, x0, P0) -> np.ndarray:  # noqa: ANN001
    """filterpy KalmanFilter on the same model; the model matrices are built the same (vectorised) way."""
    model = model_sequence(positions, H, noise)
    y = measurements - model["DH"]
    kf = KalmanFilter(dim_x=3, dim_z=4, dim_u=3)
    kf.x, kf.P, kf.B = x0.reshape(3, 1).copy(), P0.copy(), np.eye(3)
    out = np.empty((len(y), 3))
    for k in range(len(y)):
        kf.F, kf.Q = model["F"][k], model["Q"][k]
        kf.predict(u=model["u"][k])
        kf.H, kf.R = model["C"][k], model["R"][k]
        kf.update(y[k].reshape(4, 1))
        out[k] = kf.x[:, 0]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=4000, help="steps of the single run")
    parser.add_argument("--runs", type=int, default=20000, help="Monte Carlo runs of the batched benchmark")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    K = args.steps
    positions, H, noise, measurements = problem(K, rng)
    x0, P0 = np.zeros(3), np.eye(3)

    reference = filterpy_run(positions, H, noise, measurements, x0, P0)
    ours = run_cooperative_filter(positions, measurements, noise, x0, P0, H)  # compiles the rollout once
    numpy_engine = run_cooperative_filter(positions, measurements, noise, x0, P0, H, engine="numpy")
    for name, result in (("casadi", ours), ("numpy", numpy_engine)):
        err = np.abs(result.states - reference).max()
        assert err < 1e-9 * max(1.0, np.abs(reference).max()), f"{name} engine disagrees with filterpy by {err}"

    t_filterpy = best_time(lambda: filterpy_run(positions, H, noise, measurements, x0, P0), repeats=2)
    t_casadi = best_time(lambda: run_cooperative_filter(positions, measurements, noise, x0, P0, H), repeats=5)
    t_numpy = best_time(lambda: run_cooperative_filter(positions, measurements, noise, x0, P0, H, engine="numpy"), 2)
    print(f"single run, {K} steps, N = 4 platforms (states agree with filterpy to < 1e-9)")
    print(f"  filterpy KalmanFilter      {K / t_filterpy:12.0f} steps/s")
    ratio = t_filterpy / t_casadi
    print(f"  mobisense (casadi rollout) {K / t_casadi:12.0f} steps/s   ratio {ratio:5.1f}x  (target >= 5x)")
    print(f"  mobisense (numpy engine)   {K / t_numpy:12.0f} steps/s   ratio {t_filterpy / t_numpy:5.1f}x")

    B, Kb = args.runs, 100
    positions_b, H_b, noise_b, _ = problem(Kb, rng)
    meas_b = rng.normal(size=(B, Kb, 4))
    x0_b = rng.normal(size=(B, 3))
    t_shared = best_time(lambda: run_cooperative_filter(positions_b, meas_b, noise_b, x0_b, P0, H_b), 2)
    Bp = max(1, B // 4)
    per_run = np.broadcast_to(positions_b, (Bp,) + positions_b.shape)
    t_per_run = best_time(lambda: run_cooperative_filter(per_run, meas_b[:Bp], noise_b, x0_b[:Bp], P0, H_b), 2)
    print(f"batched Monte Carlo, {Kb} steps (numpy, batch first)")
    rate_shared, rate_run = B * Kb / t_shared, Bp * Kb / t_per_run
    print(f"  shared trajectory, B = {B:6d}  {rate_shared:12.3g} run-steps/s  vs 1e6 target {rate_shared / 1e6:.2f}")
    print(f"  per-run trajectory, B = {Bp:5d}  {rate_run:12.3g} run-steps/s  vs 1e6 target {rate_run / 1e6:.2f}")
    print(f"  vs filterpy single-run loop: {rate_shared * t_filterpy / K:6.0f}x (shared), "
          f"{rate_run * t_filterpy / K:6.1f}x (per-run)")  # fmt: skip


if __name__ == "__main__":
    main()
