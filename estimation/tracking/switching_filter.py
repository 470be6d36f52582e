"""Switching Kalman filter for target tracking with sensor pairs (docs/theory/leader_follower.md §7).

The algorithm and its equation numbers follow Karasalo & Hu (2010), §7, Algorithm 7.1.

One Kalman sub-filter ``F_j`` per sensor pair runs on the random-walk (constant-velocity) target model of
eq. 40 with state ``x = (x, y, ẋ, ẏ)`` (m, m, m/s, m/s) and measurement the triangulated position. At every
step the *active* sub-filters (Definition 1) predict and update with their pair's position; their
estimates are merged by a strategy registered in :data:`MERGES`:

* ``closest`` — the paper's §8.1 choice: the active sub-filter whose position is closest to the merged
  prediction (the previous estimate propagated one step);
* ``information`` — information-weighted mean ``x = P Σ w_j P_j⁻¹ x_j`` with ``P⁻¹ = Σ w_j P_j⁻¹`` and uniform
  weights ``w_j = 1/m`` (covariance intersection). The sub-filters share the process noise and, for
  neighbouring pairs, a sensor, so they are correlated; the plain information sum (``w_j = 1``) would be
  overconfident, covariance intersection is consistent whatever the correlation.

With no active pair, the merged estimate coasts on the model. Choices the paper leaves open (ours;
docs/theory/departures.md):

* an inactive sub-filter is idle; when it becomes active again it is restarted from the merged prediction,
  so a stale extrapolation never enters the merge (only sub-filters active now are merged);
* the discrete process-noise covariance is ``G q G'`` with the ``G`` of eq. 40 (the paper's eq. 36 prints
  ``BᵀQB``, a misprint for ``B Q Bᵀ``);
* predict/update are the shared kernels of :mod:`mobisense.estimation.kalman` (Joseph-form update), batched over
  the active sub-filters.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ...core.errors import brief
from ...core.registry import Registry
from ..checks import check_non_negative, check_positive
from ..kalman import predict, symmetrize, update

__all__ = [
    "C_POSITION",
    "random_walk_model",
    "merge_closest",
    "merge_information",
    "MERGES",
    "MergeName",
    "SwitchingStep",
    "SwitchingKalmanFilter",
]

#: measurement matrix of eq. 39/40: the position is observed
C_POSITION = np.hstack([np.eye(2), np.zeros((2, 2))])


def random_walk_model(sample_time: float, acceleration_std: float) -> tuple[np.ndarray, np.ndarray]:
    """Discrete random-walk target model (docs/theory/leader_follower.md, eq. leader_follower.20).

    Source: Karasalo & Hu (2010), eq. 40.

    Parameters
    ----------
    sample_time : float
        ``h`` (s).
    acceleration_std : float
        Standard deviation ``q^{1/2}`` of each acceleration component (m/s²).

    Returns
    -------
    A : ndarray, shape (4, 4)
        State transition.
    Q : ndarray, shape (4, 4)
        Process-noise covariance ``G q G'``.

    Raises
    ------
    ValueError
        Unless ``sample_time`` is finite and > 0 and ``acceleration_std`` finite and >= 0 (0: a target at
        constant velocity).
    """
    h = check_positive("sample_time", sample_time)
    acceleration_std = check_non_negative("acceleration_std", acceleration_std)
    # docs/theory/leader_follower.md, eq. leader_follower.20: x_{t+1} = A x_t + G w_t
    A = np.eye(4)
    A[0, 2] = A[1, 3] = h
    G = np.vstack([0.5 * h**2 * np.eye(2), h * np.eye(2)])
    Q = acceleration_std**2 * G @ G.T
    return A, Q


def merge_closest(
    states: np.ndarray, covariances: np.ndarray, prior: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, int]:
    """Pick the estimate whose position is closest to ``prior`` (smallest position variance if ``prior`` is None).

    Parameters
    ----------
    states : ndarray, shape (m, 4)
    covariances : ndarray, shape (m, 4, 4)
        Active sub-filter estimates.
    prior : ndarray, shape (4,) or None
        Merged prediction.

    Returns
    -------
    x, P, index
        The chosen estimate and its index among the ``m`` given.
    """
    if prior is None:
        index = int(np.argmin(np.trace(covariances[:, :2, :2], axis1=1, axis2=2)))
    else:
        gap = states[:, :2] - prior[:2]
        index = int(np.argmin(np.einsum("ij,ij->i", gap, gap)))
    return states[index], covariances[index], index


def merge_information(
    states: np.ndarray, covariances: np.ndarray, prior: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, int]:
    """Information-weighted combination with uniform covariance-intersection weights (index −1)."""
    weight = 1.0 / len(states)
    information = np.linalg.inv(covariances)
    Y = weight * information.sum(axis=0)
    P = np.linalg.inv(Y)
    x = P @ (weight * np.einsum("jab,jb->a", information, states))
    return x, symmetrize(P), -1


#: merge strategy name -> function(states, covariances, prior) -> (x, P, chosen index or −1)
MERGES: Registry[Callable[[np.ndarray, np.ndarray, np.ndarray | None], tuple[np.ndarray, np.ndarray, int]]] = Registry(
    "merge strategy", {"closest": merge_closest, "information": merge_information}
)
#: the schema type of a field naming a merge strategy
MergeName = MERGES.choice()


@dataclass(frozen=True)
class SwitchingStep:
    """Output of one switching-filter step.

    Attributes
    ----------
    state : ndarray, shape (4,)
        Merged estimate ``(x, y, ẋ, ẏ)``; NaN before the first detection.
    covariance : ndarray, shape (4, 4)
        Its covariance.
    active : ndarray of bool, shape (P,)
        Active pairs at this step.
    selected : int
        Pair index chosen by ``closest`` merging; −1 for none or for a combination.
    """

    state: np.ndarray
    covariance: np.ndarray
    active: np.ndarray
    selected: int


class SwitchingKalmanFilter:
    """Bank of per-pair Kalman sub-filters with switching/merging (Karasalo & Hu (2010), Algorithm 7.1, steps 4–6).

    Parameters
    ----------
    n_pairs : int
        Number of sensor pairs P (one sub-filter each).
    sample_time : float
        ``h`` (s).
    acceleration_std : float
        Process-noise standard deviation of the random-walk model (m/s²).
    merge : str
        Key of :data:`MERGES`.
    initial_velocity_std : float
        Prior standard deviation of each velocity component at the first detection (m/s); the prior
        velocity mean is zero.

    Raises
    ------
    ValueError
        Unless ``n_pairs`` is an integer >= 1, ``sample_time`` finite and > 0, and ``acceleration_std`` and
        ``initial_velocity_std`` finite and >= 0 (zero is a deterministic model or a known velocity).
    """

    def __init__(
        self,
        n_pairs: int,
        sample_time: float,
        acceleration_std: float,
        merge: str = "closest",
        initial_velocity_std: float = 1.0,
    ) -> None:
        if merge not in MERGES:
            raise ValueError(MERGES.unknown(merge))
        if isinstance(n_pairs, bool) or not isinstance(n_pairs, (int, np.integer)) or n_pairs < 1:
            raise ValueError(
                f"n_pairs: expected an integer >= 1 (one sub-filter per sensor pair), got {brief(n_pairs)}"
            )
        self.A, self.Q = random_walk_model(sample_time, acceleration_std)
        self.merge = MERGES[merge]
        self.initial_velocity_std = check_non_negative("initial_velocity_std", initial_velocity_std)
        self.states = np.full((n_pairs, 4), np.nan)
        self.covariances = np.full((n_pairs, 4, 4), np.nan)
        self.was_active = np.zeros(n_pairs, dtype=bool)
        self.state: np.ndarray | None = None
        self.covariance: np.ndarray | None = None

    @property
    def initialised(self) -> bool:
        """True once the target has been detected at least once."""
        return self.state is not None

    def step(self, active: np.ndarray, positions: np.ndarray, position_covariances: np.ndarray) -> SwitchingStep:
        """Advance one sample: predict and update the active sub-filters, merge their estimates.

        Parameters
        ----------
        active : ndarray of bool, shape (P,)
        positions : ndarray, shape (P, 2)
        position_covariances : ndarray, shape (P, 2, 2)
            Pair measurements (see :class:`mobisense.estimation.tracking.range_ring.PairMeasurements`).

        Returns
        -------
        SwitchingStep

        Raises
        ------
        ValueError
            For arrays of other shapes, or an active pair whose position is not finite or whose covariance is
            not symmetric positive semidefinite (inactive pairs are not read: NaN there is fine).
        """
        active = np.asarray(active, dtype=bool)
        positions = np.asarray(positions, dtype=float)
        position_covariances = np.asarray(position_covariances, dtype=float)
        _check_pairs(self.states.shape[0], active, positions, position_covariances)
        prior = prior_P = None
        if self.state is not None:
            x, prior_P = predict(self.state[:, None], self.covariance, self.A, self.Q)
            prior = x[:, 0]
        running = active & self.was_active
        starting = active & ~self.was_active
        self.was_active = active.copy()
        if prior is None:  # first detection: initialise from the pairs' measurements, zero-mean velocity prior
            for j in np.flatnonzero(starting):
                self.states[j] = (*positions[j], 0.0, 0.0)
                self.covariances[j] = 0.0
                self.covariances[j, :2, :2] = position_covariances[j]
                self.covariances[j, 2:, 2:] = self.initial_velocity_std**2 * np.eye(2)
            starting[:] = False
        elif starting.any():  # (re)start from the merged prediction
            self.states[starting], self.covariances[starting] = prior, prior_P
        if running.any():  # Karasalo & Hu (2010), eq. 36 (time update), batched over sub-filters
            x, P = predict(self.states[running][..., None], self.covariances[running], self.A, self.Q)
            self.states[running], self.covariances[running] = x[..., 0], P
        updated = running | starting
        if updated.any():  # Karasalo & Hu (2010), eq. 36 (measurement update), batched
            x, P, _, _ = update(
                self.states[updated][..., None],
                self.covariances[updated],
                positions[updated][..., None],
                C_POSITION,
                position_covariances[updated],
            )
            self.states[updated], self.covariances[updated] = x[..., 0], P
        selected = -1
        if active.any():
            index = np.flatnonzero(active)
            self.state, self.covariance, chosen = self.merge(self.states[index], self.covariances[index], prior)
            selected = int(index[chosen]) if chosen >= 0 else -1
        elif prior is not None:
            self.state, self.covariance = prior, prior_P
        state = self.state if self.state is not None else np.full(4, np.nan)
        covariance = self.covariance if self.covariance is not None else np.full((4, 4), np.nan)
        return SwitchingStep(state.copy(), covariance.copy(), active, selected)


def _check_pairs(n_pairs: int, active: np.ndarray, positions: np.ndarray, covariances: np.ndarray) -> None:
    """Raise ``ValueError`` unless the pair measurements of one step have the filter's shapes and usable values.

    Called every step, so the active pairs (a handful) are judged by scalar arithmetic, ~0.5 µs each (numpy's
    per-call overhead would cost 4x more): finite positions and 2 × 2 covariances whose symmetric part has
    smallest eigenvalue ``(a + d)/2 − √(((a − d)/2)² + b²)`` >= 0, with the tolerance of
    :func:`mobisense.core.config.check_psd`.
    """
    P = n_pairs
    if active.shape != (P,) or positions.shape != (P, 2) or covariances.shape != (P, 2, 2):
        raise ValueError(
            f"active, positions, position_covariances: expected shapes ({P},), ({P}, 2), ({P}, 2, 2) for {P} pairs, "
            f"got {active.shape}, {positions.shape}, {covariances.shape}"
        )
    rows = zip(active.tolist(), positions.tolist(), covariances.reshape(P, 4).tolist(), strict=True)
    for j, (on, (x, y), (a, b, c, d)) in enumerate(rows):
        if not on:
            continue
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ValueError(f"positions: expected a finite position for the active pair {j}, got {[x, y]}")
        tol = 1e-12 * max(1.0, abs(a), abs(d))
        if not (abs(b - c) <= tol and 0.5 * (a + d) - math.hypot(0.5 * (a - d), b) >= -tol):  # False for NaN
            raise ValueError(
                "position_covariances: expected a symmetric positive semidefinite (2, 2) matrix for the active "
                f"pair {j}, got {brief([[a, b], [c, d]])}"
            )
