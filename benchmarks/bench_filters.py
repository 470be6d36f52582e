"""Cooperative Kalman filter speed against filterpy, a plain numpy loop and a plain numba loop (one run).

    .venv/bin/python benchmarks/bench_filters.py [--steps 4000] [--runs 20000] [--repeats 5]

Same filter and data for every variant: 3 states ``[z, ∇z]``, N = 4 platforms on a moving, rotating cross,
σ = (0.05, 0.3, 0.2), a constant Hessian input. Every variant's states are checked against filterpy
before anything is timed; times are medians of ``--repeats`` interleaved rounds, so ratios are measured
under the same load.

1. Step API (one Python call per predict and per update), named variants:
   - ``filterpy KalmanFilter``: the model matrices (F, u, Q, C, R, D vec Ĥ) built vectorised up front,
     then ``predict``/``update`` per step;
   - ``plain numpy loop``: the same precomputed matrices, Joseph update with ``np.linalg.solve``;
   - ``CooperativeKalmanFilter`` with ``backend="numpy"`` and ``backend="numba"`` (each step builds its
     own Taylor rows, drift and noise from the positions: the closed-loop use).
   Compiled against compiled: ``plain numba loop`` (the whole trajectory in one compiled call, matrices
   precomputed) and the CasADi rollout ``run_cooperative_filter(engine="casadi")`` are rollouts, not step
   APIs; they are listed as the floor a step API's Python calls sit above.
   Target (issue 14): the step API at least as fast as filterpy per step.
2. Batched (numpy, batch first, K = 100 steps): run-steps per second with the trajectory shared by all
   runs (target ≥ 1.5e7, states and covariances only: ``outputs="posterior"``; all outputs listed too)
   and with one trajectory per run (target ≥ 1e6).
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import time
from collections.abc import Callable

import numpy as np
from filterpy.kalman import KalmanFilter

from mobisense.estimation.cooperative import (
    CooperativeKalmanFilter,
    CooperativeNoise,
    cross_formation,
    model_sequence,
    run_cooperative_filter,
)

HAVE_NUMBA = importlib.util.find_spec("numba") is not None


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


def numpy_loop(positions, H, noise, measurements, x0, P0) -> np.ndarray:  # noqa: ANN001
    """The textbook loop on the same precomputed matrices: predict, gain by solve, Joseph update."""
    model = model_sequence(positions, H, noise)
    F, Q, u, C, R = model["F"], model["Q"], model["u"], model["C"], model["R"]
    y = measurements - model["DH"]
    x, P, eye = x0.reshape(3, 1).astype(float), P0.astype(float).copy(), np.eye(3)
    out = np.empty((len(y), 3))
    for k in range(len(y)):
        if k:
            x = F[k] @ x + u[k]
            P = F[k] @ P @ F[k].T + Q[k]
        CP = C[k] @ P
        K = np.linalg.solve(CP @ C[k].T + R[k], CP).T
        x = x + K @ (y[k][:, None] - C[k] @ x)
        IKC = eye - K @ C[k]
        P = IKC @ P @ IKC.T + K @ R[k] @ K.T
        out[k] = x[:, 0]
    return out


def numba_loop() -> Callable[..., np.ndarray] | None:
    """The same loop compiled whole by numba (precomputed matrices), or None without numba."""
    if not HAVE_NUMBA:
        return None
    import numba

    @numba.njit(cache=True)
    def loop(F, Q, u, C, R, y, x0, P0):  # noqa: ANN001, ANN202
        x, P, eye = x0.copy(), P0.copy(), np.eye(3)
        out = np.empty((y.shape[0], 3))
        for k in range(y.shape[0]):
            if k:
                x = F[k] @ x + u[k]
                P = F[k] @ P @ F[k].T + Q[k]
            CP = C[k] @ P
            K = np.linalg.solve(CP @ C[k].T + R[k], CP).T
            x = x + K @ (y[k:k + 1].T - C[k] @ x)
            IKC = eye - K @ C[k]
            P = IKC @ P @ IKC.T + K @ R[k] @ K.T
            out[k] = x[:, 0]
        return out

    def run(positions, H, noise, measurements, x0, P0):  # noqa: ANN001, ANN202
        m = model_sequence(positions, H, noise)
        c = {k: np.ascontiguousarray(m[k]) for k in ("F", "Q", "u", "C", "R")}
        y = np.ascontiguousarray(measurements - m["DH"])
        return loop(c["F"], c["Q"], c["u"], c["C"], c["R"], y, x0.reshape(3, 1).astype(float), P0.astype(float))

    return run


def step_api(backend: str) -> Callable[..., np.ndarray]:
    def run(positions, H, noise, measurements, x0, P0):  # noqa: ANN001, ANN202
        f = CooperativeKalmanFilter(noise, x0, P0, positions[0], backend=backend)
        out = np.empty((len(measurements), 3))
        for k in range(len(measurements)):
            if k:
                f.predict(positions[k])
            out[k] = f.update(measurements[k], H[k])[0]
        return out

    return run


def interleaved(fns: dict[str, Callable[[], object]], repeats: int) -> dict[str, float]:
    """Median wall time (s) of each function over ``repeats`` interleaved rounds."""
    times: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(repeats):
        for k, f in fns.items():
            t = time.perf_counter()
            f()
            times[k].append(time.perf_counter() - t)
    return {k: statistics.median(v) for k, v in times.items()}


def verdict(ok: bool) -> str:
    return "PASS" if ok else "MISS"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=4000, help="steps of the single run")
    parser.add_argument("--runs", type=int, default=20000, help="runs of the batched shared-trajectory benchmark")
    parser.add_argument("--repeats", type=int, default=5, help="interleaved rounds (median)")
    args = parser.parse_args()
    print(f"load average before: {os.getloadavg()[0]:.2f} (2 cores)")
    rng = np.random.default_rng(0)
    K = args.steps
    data = problem(K, rng) + (np.zeros(3), np.eye(3))
    positions, H, noise, meas, x0, P0 = data
    reference = filterpy_run(*data)

    variants: dict[str, Callable[..., np.ndarray]] = {
        "filterpy KalmanFilter (step API)": filterpy_run,
        "plain numpy loop (step by step)": numpy_loop,
        "CooperativeKalmanFilter, numpy": step_api("numpy"),
    }
    if HAVE_NUMBA:
        variants["CooperativeKalmanFilter, numba"] = step_api("numba")
        variants["plain numba loop (one compiled rollout)"] = numba_loop()
    variants["CasADi rollout (run_cooperative_filter)"] = lambda *a: run_cooperative_filter(
        a[0], a[3], a[2], a[4], a[5], a[1], engine="casadi").states  # fmt: skip
    for name, fn in variants.items():  # also compiles (numba, CasADi) before timing
        err = np.abs(fn(*data) - reference).max()
        assert err < 1e-9 * max(1.0, np.abs(reference).max()), f"{name} disagrees with filterpy by {err:.2e}"
    t = interleaved({k: (lambda fn=fn: fn(*data)) for k, fn in variants.items()}, args.repeats)
    fp = t["filterpy KalmanFilter (step API)"]
    print(f"1. one run, {K} steps, N = 4 (every variant's states equal filterpy's to < 1e-9 relative)")
    for name, v in t.items():
        print(f"   {name:42s} {1e6 * v / K:8.2f} µs/step   {fp / v:6.2f}x filterpy")
    best = "CooperativeKalmanFilter, numba" if HAVE_NUMBA else "CooperativeKalmanFilter, numpy"
    ratio = fp / t[best]
    print(f"{verdict(ratio >= 1.0)}  step API ({best.split(', ')[1]}, the default when installed) vs filterpy: "
          f"{ratio:.2f}x (target >= 1x)")  # fmt: skip
    if not HAVE_NUMBA:
        print("      numba not installed (pip install 'mobisense[fast]'): the numpy step API is the one measured")

    B, Kb = args.runs, 100
    pos_b, H_b, noise_b, _ = problem(Kb, rng)
    meas_b, x0_b = rng.normal(size=(B, Kb, 4)), rng.normal(size=(B, 3))
    Bp = max(1, B // 4)
    pos_r = pos_b[None] + 0.05 * rng.normal(size=(Bp, Kb, 4, 2))
    one = {"shared": (pos_b, 0), "per-run": (pos_r[0], 0)}
    for label, (pos, b) in one.items():  # batched runs equal one run of the step API
        batch = run_cooperative_filter(pos_b if label == "shared" else pos_r, meas_b[:Bp], noise_b, x0_b[:Bp], P0, H_b)
        ref = step_api("numpy")(pos, H_b, noise_b, meas_b[b], x0_b[b], P0)
        assert np.abs(batch.states[b] - ref).max() < 1e-9 * max(1.0, np.abs(ref).max()), label
    cases = {
        "shared trajectory, states + covariances": (
            B, lambda: run_cooperative_filter(pos_b, meas_b, noise_b, x0_b, P0, H_b, outputs="posterior")),
        "shared trajectory, all outputs": (B, lambda: run_cooperative_filter(pos_b, meas_b, noise_b, x0_b, P0, H_b)),
        "trajectory per run, states + covariances": (
            Bp, lambda: run_cooperative_filter(pos_r, meas_b[:Bp], noise_b, x0_b[:Bp], P0, H_b, outputs="posterior")),
        "trajectory per run, all outputs": (
            Bp, lambda: run_cooperative_filter(pos_r, meas_b[:Bp], noise_b, x0_b[:Bp], P0, H_b)),
    }  # fmt: skip
    t = interleaved({k: fn for k, (_, fn) in cases.items()}, max(2, args.repeats // 2))
    print(f"2. batched, K = {Kb} steps, N = 4 (runs equal the step API's to < 1e-9 relative)")
    rates = {}
    for name, (runs, _) in cases.items():
        rates[name] = runs * Kb / t[name]
        print(f"   {name:42s} B = {runs:6d}  {rates[name]:10.3g} run-steps/s")
    shared = rates["shared trajectory, states + covariances"]
    per_run = rates["trajectory per run, states + covariances"]
    print(f"{verdict(shared >= 1.5e7)}  batched, shared trajectory: {shared:.3g} run-steps/s (target >= 1.5e7)")
    print(f"{verdict(per_run >= 1e6)}  batched, trajectory per run: {per_run:.3g} run-steps/s (target >= 1e6)")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
