"""Formation-parameter schedules ``d0(t), β0(t)`` for leader–follower controls (docs/theory/leader_follower.md §4).

Source: Karasalo & Hu (2010), §6.2, §8.3.

A schedule is a small class registered in :data:`REFERENCES` and evaluated with
:meth:`ReferenceSchedule.at`, which returns a :class:`~mobisense.formation.leader_follower.controls.FormationReference`
(``d0, β0`` and, when known, their rates — Control 3 needs them).

* :class:`ConstantReference` — fixed ``d0, β0`` (Theorems 1 and 2).
* :class:`BearingRampReference` — Karasalo & Hu (2010), eq. 55: ``β̇0 = c``, ``ḋ0 = a cos(f β0)``, in closed form.
* :class:`SteppedReference` — piecewise-constant ``d0, β0`` switched at given times (Karasalo & Hu (2010), §8.1,
  "robustness for switching β0", Fig. 9: β0 = 0 → π/6 at 10 s → 0 at 60 s).
* :class:`PathReference` — dynamic parameters for path following (Karasalo & Hu (2010), §8.3, Fig. 13): the follower
  aims at the furthest point of its predecessor's travelled path whose chord keeps the area between path and chord
  below ``A_max``; needs the predecessor's path history, so it is updated at sample instants.
"""

from __future__ import annotations

import bisect
import math
from abc import ABC, abstractmethod
from collections.abc import Sequence

import numpy as np

from ...core.registry import Registry
from .controls import FormationReference
from .paths import chord_window
from .unicycle import wrap_angle

__all__ = [
    "ReferenceSchedule",
    "ConstantReference",
    "BearingRampReference",
    "SteppedReference",
    "PathReference",
    "REFERENCES",
    "register_reference",
]


class ReferenceSchedule(ABC):
    """Contract of a formation-parameter schedule.

    Subclasses set ``kind`` (registry key), ``provides_rates`` (True if :meth:`at` returns exact ``ḋ0, β̇0``)
    and ``needs_history`` (True if :meth:`at` needs the predecessor's recorded path).
    """

    kind: str = ""
    provides_rates: bool = True
    needs_history: bool = False

    @abstractmethod
    def at(self, t: float, history: np.ndarray | None = None) -> FormationReference | None:
        """Reference at time ``t`` (s); ``history`` is the predecessor's path, shape (m, 2), oldest first.

        Returns ``None`` when the schedule cannot define a reference yet (the caller keeps the previous one).
        """

    def initial_history(self, predecessor_pose: np.ndarray) -> np.ndarray:
        """Path assumed travelled by the predecessor before t = 0, shape (m, 2), oldest first (default: none)."""
        return np.asarray(predecessor_pose, dtype=float)[None, :2]


#: reference kind -> ReferenceSchedule subclass
REFERENCES: Registry[type[ReferenceSchedule]] = Registry("formation-parameter reference")


def register_reference(cls: type[ReferenceSchedule]) -> type[ReferenceSchedule]:
    """Class decorator adding a :class:`ReferenceSchedule` to :data:`REFERENCES` under ``cls.kind``."""
    if not cls.kind:
        raise TypeError(f"{cls.__name__} needs a non-empty 'kind' to be registered")
    return REFERENCES.register(cls.kind, cls)


@register_reference
class ConstantReference(ReferenceSchedule):
    """Constant formation parameters.

    Parameters
    ----------
    distance : float
        ``d0`` (m), > 0.
    bearing : float
        ``β0`` (rad), ``|β0| < π/2``.
    """

    kind = "constant"

    def __init__(self, distance: float, bearing: float) -> None:
        self.distance = float(distance)
        self.bearing = float(bearing)

    def at(self, t: float, history: np.ndarray | None = None) -> FormationReference:
        """The constant reference (rates zero)."""
        return FormationReference(self.distance, self.bearing)


@register_reference
class BearingRampReference(ReferenceSchedule):
    """Bearing ramp with a bearing-dependent distance rate (eq. leader_follower.12).

    Source: Karasalo & Hu (2010), eq. 55, generalised.

    Parameters
    ----------
    distance : float
        ``d0(0)`` (m).
    bearing : float
        ``β0(0)`` (rad).
    bearing_rate : float
        ``β̇0 = c`` (rad/s), constant.
    distance_rate_amplitude : float
        ``a`` (m/s) in ``ḋ0 = a cos(f β0)``.
    distance_rate_frequency : float
        ``f`` (1/rad) in ``ḋ0 = a cos(f β0)``.

    Notes
    -----
    The paper prints eq. 55 as ``d0 = 0.1 cos(45 β0)``, ``β̇0 = 0.001``, ``d0(0) = 0.5``, ``β0(0) = π/7``; taken
    literally ``d0(0) = 0.1 cos(45π/7) ≈ 0.022 ≠ 0.5``, so a dot was lost in print: we read the first line as the
    rate ``ḋ0 = 0.1 cos(45 β0)``. Then (closed form, ``c ≠ 0``)::

        β0(t) = β0(0) + c t
        d0(t) = d0(0) + a/(f c) [sin(f β0(t)) − sin(f β0(0))]

    which over the paper's 10 s window rises from 0.5 to ≈ 0.556 at t ≈ 5 s and falls back, dipping slightly
    below its start to 0.4994 at t = 10 s (a bump, consistent with its Fig. 19).
    """

    kind = "ramp"

    def __init__(
        self,
        distance: float,
        bearing: float,
        bearing_rate: float,
        distance_rate_amplitude: float,
        distance_rate_frequency: float,
    ) -> None:
        self.distance = float(distance)
        self.bearing = float(bearing)
        self.bearing_rate = float(bearing_rate)
        self.amplitude = float(distance_rate_amplitude)
        self.frequency = float(distance_rate_frequency)

    def at(self, t: float, history: np.ndarray | None = None) -> FormationReference:
        """``d0(t), β0(t)`` and their exact rates."""
        a, f, c = self.amplitude, self.frequency, self.bearing_rate
        beta0 = self.bearing + c * t
        if c * f != 0.0:
            d0 = self.distance + a / (f * c) * (math.sin(f * beta0) - math.sin(f * self.bearing))
        else:  # ḋ0 constant
            d0 = self.distance + a * math.cos(f * self.bearing) * t
        return FormationReference(d0, beta0, a * math.cos(f * beta0), c)


@register_reference
class SteppedReference(ReferenceSchedule):
    """Piecewise-constant formation parameters switched at given instants (docs/theory/leader_follower.md §4.4).

    Source: Karasalo & Hu (2010), §8.1, Fig. 9.

    Parameters
    ----------
    switch_times : sequence of float
        Strictly increasing switching instants ``t_1 < … < t_m`` (s).
    distances, bearings : sequence of float
        ``d0`` (m) and ``β0`` (rad) on ``[0, t_1), [t_1, t_2), …, [t_m, ∞)`` (``m + 1`` values each).

    Notes
    -----
    Between switches the parameters are constant, so Control 1 is Theorem 1's control on each piece (its
    reference-point error decays as ``e^{−kt}`` after each switch, starting from the jump the switch causes).
    The rates are Dirac impulses at the switches, so ``provides_rates = False``: Control 3's feed-forward is
    undefined and scenarios reject it with this schedule.
    """

    kind = "steps"
    provides_rates = False

    def __init__(self, switch_times: Sequence[float], distances: Sequence[float], bearings: Sequence[float]) -> None:
        self.switch_times = [float(t) for t in switch_times]
        self.distances = [float(d) for d in distances]
        self.bearings = [float(b) for b in bearings]
        m = len(self.switch_times)
        if len(self.distances) != m + 1 or len(self.bearings) != m + 1:
            raise ValueError(f"expected {m + 1} distances and bearings for {m} switch times")
        if any(b <= a for a, b in zip(self.switch_times[:-1], self.switch_times[1:], strict=True)):
            raise ValueError(f"expected strictly increasing switch times, got {self.switch_times}")

    def at(self, t: float, history: np.ndarray | None = None) -> FormationReference:
        """The piece containing ``t`` (a switch instant belongs to the piece it starts)."""
        k = bisect.bisect_right(self.switch_times, t)
        return FormationReference(self.distances[k], self.bearings[k])


@register_reference
class PathReference(ReferenceSchedule):
    """Dynamic parameters keeping the follower on its predecessor's path (docs/theory/leader_follower.md §4.3).

    Source: Karasalo & Hu (2010), §8.3, Fig. 13.

    Parameters
    ----------
    max_area : float
        ``A_max`` (m²): tolerance on the area between the predecessor's path and the chord.
    max_distance : float
        Upper bound on ``d0`` (m) — on straight stretches the area is zero and the chord would grow without
        bound.
    max_bearing : float
        Bound on ``|β0|`` (rad), ``< π/2`` (keeps Control 1 away from its singularity in sharp turns).

    Notes
    -----
    The paper defines the parameters only in words ("steer toward a position on the path of R_{i−1} such that
    d0 is maximised while the area of Fig. 13 is below A_max"). Our reading: walk back along the
    predecessor's recorded path from its current position ``P_m`` to the furthest point ``P`` with area ≤
    ``A_max`` and chord ≤ ``max_distance`` (see :func:`~mobisense.formation.leader_follower.paths.chord_window`). A
    follower sitting at ``P`` and heading along the path's tangent there sees its predecessor at::

        d0 = ‖P_m − P‖,   β0 = angle(P_m − P) − tangent heading at P,

    which are the parameters returned. Their rates are unknown (``provides_rates = False``): the paper uses
    Control 1 with them, whose error is then bounded by ``M/k`` (eq. 23).
    """

    kind = "path"
    provides_rates = False
    needs_history = True

    def __init__(self, max_area: float, max_distance: float, max_bearing: float) -> None:
        self.max_area = float(max_area)
        self.max_distance = float(max_distance)
        self.max_bearing = float(max_bearing)

    def initial_history(self, predecessor_pose: np.ndarray) -> np.ndarray:
        """A straight run of length ``1.5 max_distance`` behind the predecessor's initial pose.

        The formation is assumed to start from a column on a straight path, so that the reference is defined
        (and equal to the straight-path value ``d0 = max_distance, β0 = 0``) from t = 0 on.
        """
        x, y, phi = np.asarray(predecessor_pose, dtype=float)
        back = np.linspace(1.5 * self.max_distance, 0.0, 31)
        return np.stack([x - back * np.cos(phi), y - back * np.sin(phi)], axis=-1)

    def at(self, t: float, history: np.ndarray | None = None) -> FormationReference | None:
        """Reference from the predecessor's path ``history`` (m, 2); ``None`` if it is too short."""
        if history is None:
            raise ValueError("PathReference needs the predecessor's path history")
        point = chord_window(history, self.max_area, self.max_distance)
        if point is None:
            return None
        bearing = float(wrap_angle(point.chord_heading - point.tangent_heading))
        return FormationReference(point.chord, float(np.clip(bearing, -self.max_bearing, self.max_bearing)))
