"""A ring of directional range sensors and pairwise triangulation (docs/theory/leader_follower.md §6).

The model and its equation numbers follow Karasalo & Hu (2010), §7.3–7.4, eqs. 41–48.

Sensors sit on a circle of radius ``mount_radius`` around the robot centre at body-frame angles
``mount_angles`` and look along body-frame ``headings`` (Khepera II-like by default: eight IR sensors, six
in front and two at the back). A sensor is *active* (sees the target) when the target centre lies inside its
field of view and within ``max_range`` of it. It reads the distance to the target's surface,
``δ̃ = ‖s − p‖ − r + noise``; the centre distance is ``δ = δ̃ + r`` (eq. 42).

Neighbouring sensors form *pairs*; a pair triangulates the target position by the law of cosines (eqs.
43–46) and passes the activity test (eq. 48) when a triangle with sides ``Δs, δ_q, δ_{q−1}`` exists.

Mirror ambiguity (eq. 45): the two circles ``‖p − s_q‖ = δ_q``, ``‖p − s_{q−1}‖ = δ_{q−1}`` meet in two points
mirrored across the baseline. The paper's ``+Δy'`` picks the side of the baseline to the left of
``s_q − s_{q−1}``, which is the outer side for its clockwise sensor numbering; we pick the outer side (away
from the robot centre) for any numbering, since a sensor only sees outward.

Pair measurement covariance (our choice, the paper does not specify one; docs/theory/leader_follower.md,
eq. leader_follower.19): linearising the two range equations about the triangulated point, ``u_q·dp = dδ_q`` and
``u_{q−1}·dp = dδ_{q−1}`` with ``u`` the unit vectors from the sensors to the target, so ``dp = U⁻¹ dδ`` and
``R = σ² U⁻¹ U⁻ᵀ`` with ``U = [u_q; u_{q−1}]``. It grows without bound as the target approaches the baseline's line,
where triangulation is ill-posed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...core.errors import brief
from ..checks import check_finite_array, check_non_negative, check_positive

__all__ = [
    "KHEPERA_MOUNT_ANGLES_DEG",
    "KHEPERA_PAIRS",
    "RangeSensorRing",
    "PairMeasurements",
    "cosine_ratio",
    "triangulate",
    "triangulation_covariance",
]

#: Khepera II IR sensor placements (deg, counter-clockwise from forward), numbered s1…s8 as in
#: Karasalo & Hu (2010), Fig. 2: s1 left, clockwise over the front to s6 right, then s7 rear right and s8 rear left.
KHEPERA_MOUNT_ANGLES_DEG = (90.0, 45.0, 10.0, -10.0, -45.0, -90.0, -170.0, 170.0)
#: the paper's six neighbouring pairs p1…p6 (eq. 41), 1-based sensor numbers
KHEPERA_PAIRS = ((1, 2), (2, 3), (3, 4), (4, 5), (5, 6), (7, 8))


def cosine_ratio(baseline: np.ndarray, delta_q: np.ndarray, delta_q_prev: np.ndarray) -> np.ndarray:
    """``cos ψ`` of the law of cosines (eq. 43), the quantity tested by eq. 48.

    Parameters
    ----------
    baseline : ndarray, shape (...)
        ``Δs = ‖s_q − s_{q−1}‖`` (m).
    delta_q, delta_q_prev : ndarray, shape (...)
        Centre distances ``δ_q``, ``δ_{q−1}`` (m).

    Returns
    -------
    ndarray, shape (...)
        ``(Δs² + δ_q² − δ_{q−1}²) / (2 Δs δ_q)``; a real triangle needs ``|·| < 1``.
    """
    # docs/theory/leader_follower.md, eq. leader_follower.17 (Karasalo & Hu (2010), eqs. 43, 48):
    # cos ψ = (Δs² + δ_q² − δ_{q−1}²) / (2 Δs δ_q)
    with np.errstate(divide="ignore", invalid="ignore"):
        return (baseline**2 + delta_q**2 - delta_q_prev**2) / (2.0 * baseline * delta_q)


def triangulate(
    s_q: np.ndarray, s_q_prev: np.ndarray, delta_q: np.ndarray, delta_q_prev: np.ndarray, centre: np.ndarray
) -> np.ndarray:
    """Target position from two range readings (eqs. 43–46), on the side of the baseline away from ``centre``.

    Parameters
    ----------
    s_q, s_q_prev : ndarray, shape (..., 2)
        World positions of the two sensors (m).
    delta_q, delta_q_prev : ndarray, shape (...)
        Centre distances from each sensor to the target (m).
    centre : ndarray, shape (2,)
        Robot centre (m), which fixes the outward side.

    Returns
    -------
    ndarray, shape (..., 2)
        Target positions (m); NaN where eq. 48 fails (no real triangle).
    """
    baseline_vec = s_q - s_q_prev
    baseline = np.hypot(baseline_vec[..., 0], baseline_vec[..., 1])
    e = baseline_vec / baseline[..., None]  # x axis of the local frame O'
    n = np.stack([-e[..., 1], e[..., 0]], axis=-1)  # y axis of O'
    outward = np.sign(np.einsum("...i,...i->...", n, 0.5 * (s_q + s_q_prev) - centre))
    n = n * np.where(outward == 0, 1.0, outward)[..., None]
    cos_psi = cosine_ratio(baseline, delta_q, delta_q_prev)
    with np.errstate(invalid="ignore"):
        sin_psi = np.sqrt(1.0 - cos_psi**2)  # eq. 47 (NaN when eq. 48 fails)
    # docs/theory/leader_follower.md, eq. leader_follower.18 (Karasalo & Hu (2010), eqs. 44–46):
    # p = s_q − δ_q cos ψ e + δ_q sin ψ n, in world coordinates
    return s_q + delta_q[..., None] * (-cos_psi[..., None] * e + sin_psi[..., None] * n)


def triangulation_covariance(
    s_q: np.ndarray, s_q_prev: np.ndarray, target: np.ndarray, noise_std: float
) -> np.ndarray:
    """Covariance of a triangulated position for independent range noise ``σ`` (first order).

    Parameters
    ----------
    s_q, s_q_prev : ndarray, shape (..., 2)
        Sensor positions (m).
    target : ndarray, shape (..., 2)
        Triangulated position (m).
    noise_std : float
        Range noise standard deviation ``σ`` (m).

    Returns
    -------
    ndarray, shape (..., 2, 2)
        ``σ² U⁻¹ U⁻ᵀ`` with ``U`` the stacked unit vectors from the sensors to the target.
    """
    u_q = target - s_q
    u_p = target - s_q_prev
    U = np.stack(
        [u_q / np.linalg.norm(u_q, axis=-1, keepdims=True), u_p / np.linalg.norm(u_p, axis=-1, keepdims=True)],
        axis=-2,
    )
    U_inv = np.linalg.inv(U)
    return noise_std**2 * U_inv @ np.swapaxes(U_inv, -1, -2)


@dataclass(frozen=True)
class PairMeasurements:
    """Triangulated positions from all sensor pairs at one instant.

    Attributes
    ----------
    active : ndarray of bool, shape (P,)
        Pair passes Definition 1 (both sensors read, eq. 48 holds).
    positions : ndarray, shape (P, 2)
        Triangulated target positions (m, world frame); NaN for inactive pairs.
    covariances : ndarray, shape (P, 2, 2)
        Their covariances (m²); NaN for inactive pairs.
    """

    active: np.ndarray
    positions: np.ndarray
    covariances: np.ndarray


@dataclass(frozen=True)
class RangeSensorRing:
    """Directional range sensors on a circle around a unicycle robot.

    Attributes
    ----------
    mount_radius : float
        Radius of the sensor circle (m).
    mount_angles : ndarray, shape (S,)
        Body-frame angular positions of the sensors (rad, counter-clockwise from forward).
    headings : ndarray, shape (S,)
        Body-frame look directions (rad).
    field_of_view : float
        Full opening angle of each sensor's cone (rad).
    max_range : float
        Largest surface distance a sensor reads (m).
    noise_std : float
        Standard deviation of the range noise (m).
    target_radius : float
        Radius ``r`` of the target robot (m), eq. 42.
    pairs : ndarray of int, shape (P, 2)
        0-based sensor indices ``(q−1, q)`` of each pair.

    Raises
    ------
    ValueError
        Unless ``mount_radius`` and ``max_range`` are finite and > 0, ``field_of_view`` is in (0, 2π],
        ``noise_std`` and ``target_radius`` are finite and >= 0, ``mount_angles`` and ``headings`` are finite
        and of the same length S >= 2, and ``pairs`` has P >= 1 rows of two different indices in 0 … S−1 (the
        rules of the ``sensing: {mode: ring}`` block of a scenario file).
    """

    mount_radius: float
    mount_angles: np.ndarray
    headings: np.ndarray
    field_of_view: float
    max_range: float
    noise_std: float
    target_radius: float = 0.0
    pairs: np.ndarray = field(default_factory=lambda: np.asarray(KHEPERA_PAIRS) - 1)

    def __post_init__(self) -> None:
        for name in ("mount_radius", "max_range"):
            object.__setattr__(self, name, check_positive(name, getattr(self, name)))
        for name in ("noise_std", "target_radius"):
            object.__setattr__(self, name, check_non_negative(name, getattr(self, name)))
        fov = check_positive("field_of_view", self.field_of_view)
        if fov > 2 * np.pi:
            raise ValueError(f"field_of_view: expected a full opening angle in (0, 2π] rad, got {fov:g}")
        angles = check_finite_array("mount_angles", self.mount_angles, "(S,) with S >= 2",
                                    lambda s: len(s) == 1 and s[0] >= 2)  # fmt: skip
        S = angles.shape[0]
        headings = check_finite_array("headings", self.headings, f"({S},), one per sensor", lambda s: s == (S,))
        pairs = np.asarray(self.pairs)
        if (pairs.ndim != 2 or pairs.shape[0] < 1 or pairs.shape[1] != 2 or pairs.dtype.kind not in "iu"
                or np.any((pairs < 0) | (pairs >= S)) or np.any(pairs[:, 0] == pairs[:, 1])):  # fmt: skip
            raise ValueError(
                f"pairs: expected P >= 1 rows of two different integer sensor indices in 0 … {S - 1}, "
                f"got {brief(pairs)}"
            )
        object.__setattr__(self, "field_of_view", fov)
        for name, value in (("mount_angles", angles), ("headings", headings), ("pairs", pairs)):
            object.__setattr__(self, name, value)

    @property
    def n_pairs(self) -> int:
        """Number of sensor pairs P."""
        return len(self.pairs)

    def sensor_positions(self, pose: np.ndarray) -> np.ndarray:
        """World positions of the sensors, shape (S, 2), for robot pose ``(x, y, φ)``."""
        angle = pose[2] + self.mount_angles
        return pose[:2] + self.mount_radius * np.stack([np.cos(angle), np.sin(angle)], axis=-1)

    def centre_distances(self, pose: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Sensor positions (S, 2) and noise-free centre distances ``δ`` (S,) to ``target`` (2,)."""
        sensors = self.sensor_positions(pose)
        return sensors, np.hypot(*(target - sensors).T)

    def visible(self, pose: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Which sensors see the target centre (inside the cone, surface within ``max_range``), shape (S,)."""
        sensors, delta = self.centre_distances(pose, target)
        direction = np.arctan2(target[1] - sensors[:, 1], target[0] - sensors[:, 0])
        off_axis = np.abs(np.angle(np.exp(1j * (direction - (pose[2] + self.headings)))))
        return (off_axis <= 0.5 * self.field_of_view) & (delta - self.target_radius <= self.max_range)

    def read(self, pose: np.ndarray, target: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        """Surface-distance readings ``δ̃`` (S,) in m; NaN for sensors that do not see the target.

        Noise ``N(0, σ²)`` is added when ``rng`` is given; readings are clipped at 0.
        """
        _, delta = self.centre_distances(pose, target)
        reading = delta - self.target_radius
        if rng is not None and self.noise_std > 0:
            reading = reading + self.noise_std * rng.standard_normal(reading.shape)
        return np.where(self.visible(pose, target), np.maximum(reading, 0.0), np.nan)

    def fix_bearing_std(self, pose: np.ndarray, target: np.ndarray) -> np.ndarray:
        """Bearing standard deviation of one triangulated fix by each pair (docs/theory/leader_follower.md §6).

        For a target at ``target`` seen from ``pose``, noise-free geometry: the component of each active pair's
        triangulation covariance (eq. leader_follower.19) across the line of sight from the robot centre,
        divided by the centre distance (eq. leader_follower.23).

        Parameters
        ----------
        pose : ndarray, shape (3,)
            Robot pose ``(x, y, φ)`` (m, m, rad).
        target : ndarray, shape (2,)
            Target centre (m).

        Returns
        -------
        ndarray, shape (P,)
            Bearing std (rad) per pair; NaN for pairs that are not active (a sensor does not see the target).
        """
        pose = np.asarray(pose, dtype=float)
        target = np.asarray(target, dtype=float)
        pairs = self.pair_measurements(pose, self.read(pose, target))
        los = target - pose[:2]
        distance = float(np.hypot(*los))
        across = np.array([-los[1], los[0]]) / distance
        out = np.full(self.n_pairs, np.nan)
        if np.any(pairs.active):
            sensors = self.sensor_positions(pose)
            q_prev, q = self.pairs[pairs.active, 0], self.pairs[pairs.active, 1]
            targets = np.broadcast_to(target, (len(q), 2))
            cov = triangulation_covariance(sensors[q], sensors[q_prev], targets, self.noise_std)
            out[pairs.active] = np.sqrt(np.einsum("i,pij,j->p", across, cov, across)) / distance
        return out

    def pair_measurements(self, pose: np.ndarray, readings: np.ndarray) -> PairMeasurements:
        """Activity test and triangulation for every pair (Algorithm 7.1, steps 2–4).

        Parameters
        ----------
        pose : ndarray, shape (3,)
            The measuring robot's pose (odometry).
        readings : ndarray, shape (S,)
            Surface distances ``δ̃`` (m), NaN where a sensor has no reading.

        Returns
        -------
        PairMeasurements
        """
        sensors = self.sensor_positions(pose)
        delta = readings + self.target_radius  # docs/theory/leader_follower.md, eq. leader_follower.16: δ = δ̃ + r
        q_prev, q = self.pairs[:, 0], self.pairs[:, 1]
        baseline = np.hypot(*(sensors[q] - sensors[q_prev]).T)
        ratio = cosine_ratio(baseline, delta[q], delta[q_prev])
        # Definition 1: both sensors read (finite) and eq. 48, (cos ψ)² < 1
        active = np.isfinite(ratio) & (ratio**2 < 1.0)
        positions = np.full((self.n_pairs, 2), np.nan)
        covariances = np.full((self.n_pairs, 2, 2), np.nan)
        if np.any(active):
            positions[active] = triangulate(
                sensors[q[active]], sensors[q_prev[active]], delta[q[active]], delta[q_prev[active]], pose[:2]
            )
            covariances[active] = triangulation_covariance(
                sensors[q[active]], sensors[q_prev[active]], positions[active], self.noise_std
            )
        return PairMeasurements(active, positions, covariances)
