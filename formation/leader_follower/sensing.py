"""What a follower knows about its predecessor: exact relative states, or a sensor ring + switching filter.

Two sensing modes (``sensing: {mode: …}`` in scenario files), both returning a :class:`Sensed` record:

* :class:`ExactSensing` — the true ``(d, β, γ, v_{i−1})`` (for analysis; the closed loop is then continuous);
* :class:`RingSensing` — a :class:`~mobisense.estimation.tracking.range_ring.RangeSensorRing` read at the sample
  instants, fed to a :class:`~mobisense.estimation.tracking.switching_filter.SwitchingKalmanFilter`
  (Karasalo & Hu (2010), Algorithm 7.1), whose estimate gives ``d, β, φ_{i−1}, γ, v_{i−1}`` by eqs. 49–53
  (:func:`relative_from_estimate`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...estimation.tracking.range_ring import RangeSensorRing
from ...estimation.tracking.switching_filter import SwitchingKalmanFilter
from .controls import RelativeMeasurement

__all__ = ["Sensed", "ExactSensing", "RingSensing", "RingSpec", "exact_measurement", "relative_from_estimate"]


@dataclass(frozen=True)
class Sensed:
    """One follower's knowledge of its predecessor at one instant.

    Attributes
    ----------
    measurement : RelativeMeasurement or None
        ``(d, β, γ, v_{i−1})``; None before the first detection.
    predecessor_state : ndarray, shape (4,)
        ``(x, y, ẋ, ẏ)`` of the predecessor (m, m/s), estimated or true; NaN before the first detection.
    active : ndarray of bool, shape (P,) or None
        Active sensor pairs (ring mode only).
    selected : int
        Sub-filter chosen by the merge (−1: none, a combination, or exact mode).
    """

    measurement: RelativeMeasurement | None
    predecessor_state: np.ndarray
    active: np.ndarray | None = None
    selected: int = -1


def exact_measurement(follower: np.ndarray, predecessor: np.ndarray, predecessor_speed: float) -> RelativeMeasurement:
    """True relative state of a follower, from the two poses ``(x, y, φ)`` and the predecessor's speed.

    Scalar arithmetic (this runs inside the ODE right-hand side); angles are left unwrapped, the controls
    only use their sines and cosines.
    """
    dx = predecessor[0] - follower[0]
    dy = predecessor[1] - follower[1]
    return RelativeMeasurement(
        distance=math.hypot(dx, dy),
        bearing=math.atan2(dy, dx) - follower[2],
        heading_difference=follower[2] - predecessor[2],
        predecessor_speed=predecessor_speed,
    )


def relative_from_estimate(pose: np.ndarray, state: np.ndarray) -> RelativeMeasurement:
    """Relative state from a follower's own pose and the estimated predecessor state (eq. leader_follower.22).

    Source: Karasalo & Hu (2010), eqs. 49–53.

    Parameters
    ----------
    pose : ndarray, shape (3,)
        The follower's pose from odometry.
    state : ndarray, shape (4,)
        Estimated predecessor ``(x, y, ẋ, ẏ)``.

    Returns
    -------
    RelativeMeasurement

    Notes
    -----
    ``atan2`` replaces the paper's ``tan⁻¹`` (quadrant-correct). The predecessor's heading is taken from the
    estimated velocity, ``φ_{i−1} = atan2(ẏ, ẋ)``, instead of the difference of consecutive position estimates
    (eq. 52): the two agree for the constant-velocity model, the former without the measurement noise
    that the difference of two filtered positions carries.
    """
    dx, dy = state[0] - pose[0], state[1] - pose[1]
    phi_prev = math.atan2(state[3], state[2])  # eq. 52 (velocity form)
    return RelativeMeasurement(
        distance=math.hypot(dx, dy),  # eq. 50
        bearing=math.remainder(math.atan2(dy, dx) - pose[2], 2 * math.pi),  # eq. 51
        heading_difference=math.remainder(pose[2] - phi_prev, 2 * math.pi),  # eq. 53
        predecessor_speed=math.hypot(state[2], state[3]),  # eq. 49
    )


class ExactSensing:
    """True relative states (continuous-time feedback)."""

    continuous = True

    def measure(
        self, follower: np.ndarray, predecessor: np.ndarray, predecessor_speed: float
    ) -> Sensed:
        """Exact relative state and predecessor state."""
        velocity = predecessor_speed * np.array([math.cos(predecessor[2]), math.sin(predecessor[2])])
        return Sensed(
            exact_measurement(follower, predecessor, predecessor_speed),
            np.concatenate([predecessor[:2], velocity]),
        )


class RingSensing:
    """Directional range-sensor ring and switching Kalman filter, sampled every ``h`` (Algorithm 7.1).

    Parameters
    ----------
    ring : RangeSensorRing
        The follower's sensors.
    filter : SwitchingKalmanFilter
        The follower's filter (one per follower; it keeps state between calls).
    rng : numpy.random.Generator
        Source of the range noise.
    """

    continuous = False

    def __init__(self, ring: RangeSensorRing, filter: SwitchingKalmanFilter, rng: np.random.Generator) -> None:
        self.ring = ring
        self.filter = filter
        self.rng = rng

    def measure(
        self, follower: np.ndarray, predecessor: np.ndarray, predecessor_speed: float
    ) -> Sensed:
        """Read the ring at the true predecessor position, run one filter step, form eqs. 49–53."""
        readings = self.ring.read(follower, predecessor[:2], self.rng)  # steps 1–2
        pairs = self.ring.pair_measurements(follower, readings)  # steps 2–4
        step = self.filter.step(pairs.active, pairs.positions, pairs.covariances)  # steps 5–6
        measurement = relative_from_estimate(follower, step.state) if self.filter.initialised else None
        return Sensed(measurement, step.state, step.active, step.selected)


@dataclass(frozen=True)
class RingSpec:
    """Everything needed to equip each follower with a sensor ring and a switching filter.

    Attributes
    ----------
    ring : RangeSensorRing
        Sensor layout and noise.
    acceleration_std : float
        Random-walk process noise of the target model (m/s²).
    merge : str
        Merge strategy (key of :data:`mobisense.estimation.tracking.switching_filter.MERGES`).
    initial_velocity_std : float
        Prior velocity standard deviation at first detection (m/s).
    """

    ring: RangeSensorRing
    acceleration_std: float
    merge: str = "closest"
    initial_velocity_std: float = 1.0

    def sensing(self, sample_time: float, rng: np.random.Generator) -> RingSensing:
        """A fresh :class:`RingSensing` (new filter state) sampled every ``sample_time`` seconds."""
        skf = SwitchingKalmanFilter(
            self.ring.n_pairs, sample_time, self.acceleration_std, self.merge, self.initial_velocity_std
        )
        return RingSensing(self.ring, skf, rng)
