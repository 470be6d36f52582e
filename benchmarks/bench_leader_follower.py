"""Leader–follower throughput, measured in one run (ratios, not absolutes).

    PYTHONPATH=. .venv/bin/python benchmarks/bench_leader_follower.py

1. switching Kalman filter (batched ``mobisense.estimation.kalman`` kernels) vs the same algorithm written with
   filterpy's ``KalmanFilter`` (one object per sensor pair, same restart and closest-merge rules), on one
   recorded sweep of a target across the sensor pairs of a Khepera-like ring; the estimates are checked to
   agree before anything is timed. The shared kernels are batched over the active pairs, which carries a
   fixed numpy overhead per step: targets >= 0.5x filterpy with 100° cones (1–2 active pairs) and >= 1x
   with 300° cones (all five front pairs active).
2. real-time factor (simulated seconds per wall-clock second) of the shipped scenarios: continuous
   (``control2``, one ``solve_ivp`` call) and sampled (``khepera``, ring + filter, one call per sample).
   Target: >= 10x real time for the sampled Khepera scenario (a controller could run it on board).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from filterpy.kalman import KalmanFilter
from timing import best_time

from mobisense.core import load_config
from mobisense.estimation.tracking import (
    C_POSITION,
    KHEPERA_MOUNT_ANGLES_DEG,
    KHEPERA_PAIRS,
    RangeSensorRing,
    SwitchingKalmanFilter,
    random_walk_model,
)
from mobisense.formation.leader_follower import LeaderFollowerScenario, simulate_scenario

PROBLEMS = Path(__file__).resolve().parent.parent / "problems"
H, Q_STD = 0.01, 1.0


def sweep(field_of_view_deg: float, steps: int = 3000):  # noqa: ANN201
    """Pair measurements of a target sweeping ±85° in front of a stationary ring (σ = 2 mm)."""
    angles = np.deg2rad(KHEPERA_MOUNT_ANGLES_DEG)
    fov = math.radians(field_of_view_deg)
    ring = RangeSensorRing(0.25, angles, angles, fov, 2.5, 0.002, 0.0, np.asarray(KHEPERA_PAIRS) - 1)
    rng = np.random.default_rng(0)
    pose = np.zeros(3)
    out = []
    for k in range(steps):
        angle = 1.48 * math.cos(2 * math.pi * k / 1200)
        target = np.array([math.cos(angle), math.sin(angle)])
        m = ring.pair_measurements(pose, ring.read(pose, target, rng))
        out.append((m.active, m.positions, m.covariances))
    return out


def run_mobisense(data) -> np.ndarray:  # noqa: ANN001
    skf = SwitchingKalmanFilter(6, H, Q_STD, "closest", 1.0)
    return np.array([skf.step(*d).state for d in data])


def run_filterpy(data) -> np.ndarray:  # noqa: ANN001
    """The same switching algorithm with one filterpy KalmanFilter per pair."""
    A, Q = random_walk_model(H, Q_STD)
    bank = []
    for _ in range(6):
        kf = KalmanFilter(dim_x=4, dim_z=2)
        kf.F, kf.Q, kf.H = A, Q, C_POSITION
        bank.append(kf)
    was_active = np.zeros(6, bool)
    x = P = None
    out = []
    for active, positions, covariances in data:
        prior = prior_P = None
        if x is not None:
            prior, prior_P = A @ x, A @ P @ A.T + Q
        for j in np.flatnonzero(active):
            kf = bank[j]
            if not was_active[j] and prior is None:
                kf.x = np.r_[positions[j], 0.0, 0.0].reshape(4, 1)
                kf.P = np.zeros((4, 4))
                kf.P[:2, :2], kf.P[2:, 2:] = covariances[j], np.eye(2)
                continue
            if was_active[j]:
                kf.predict()
            else:
                kf.x, kf.P = prior.reshape(4, 1).copy(), prior_P.copy()
            kf.update(positions[j].reshape(2, 1), R=covariances[j])
        was_active = active.copy()
        index = np.flatnonzero(active)
        if index.size:
            states = np.array([bank[j].x[:, 0] for j in index])
            if prior is None:
                pick = int(np.argmin([np.trace(bank[j].P[:2, :2]) for j in index]))
            else:
                pick = int(np.argmin(np.linalg.norm(states[:, :2] - prior[:2], axis=1)))
            x, P = states[pick], bank[index[pick]].P.copy()
        elif prior is not None:
            x, P = prior, prior_P
        out.append(x if x is not None else np.full(4, np.nan))
    return np.array(out)


def main() -> None:
    for fov in (100.0, 300.0):
        data = sweep(fov)
        ours, ref = run_mobisense(data), run_filterpy(data)
        finite = np.isfinite(ours[:, 0])
        # filterpy's update is the textbook (I − KH)P form, ours Joseph's: agreement to round-off accumulation
        difference = np.abs(ours - ref)[finite].max()
        assert difference < 1e-8, difference
        t_ours = best_time(lambda data=data: run_mobisense(data))
        t_ref = best_time(lambda data=data: run_filterpy(data))
        mean_active = np.mean([d[0].sum() for d in data])
        print(f"switching filter, {fov:g}° cones ({mean_active:.1f} active pairs on average), {len(data)} steps:")
        print(f"  max |difference| to filterpy {difference:.1e}")
        print(f"  mobisense {1e6 * t_ours / len(data):.1f} µs/step, filterpy {1e6 * t_ref / len(data):.1f} µs/step")
        print(f"  ratio filterpy/mobisense = {t_ref / t_ours:.2f}x (target >= {0.5 if fov < 200 else 1}x)")
    for name in ("control2", "khepera"):
        scenario = load_config(PROBLEMS / f"leader_follower_{name}.yaml", LeaderFollowerScenario)
        wall = best_time(lambda scenario=scenario: simulate_scenario(scenario), repeats=1)
        runs = len(scenario.runs)
        target = " (target >= 10x)" if name == "khepera" else ""
        print(
            f"scenario {name}: {runs} run(s) x {scenario.duration:g} s simulated in {wall:.2f} s: "
            f"real-time factor {runs * scenario.duration / wall:.1f}x{target}"
        )


if __name__ == "__main__":
    main()
