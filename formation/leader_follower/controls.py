"""Leader–follower formation controls for unicycles: Controls 1, 2 and 3 (docs/theory/leader_follower.md §3).

Equation and theorem numbers are those of Karasalo & Hu (2010): Controls 1–3 are its eqs. 9, 17 and 24–25.

Each control is a small class registered by name in :data:`CONTROLS` (so scenario files can say
``control: control2``) and implements :meth:`FormationControl.command`, mapping what follower ``i`` knows —
a :class:`RelativeMeasurement` ``(d, β, γ, v_{i−1})`` — and the formation reference ``(d0, β0, ḋ0, β̇0)`` to its
inputs ``(v_i, ω_i)``. A new control subclasses :class:`FormationControl`, sets ``name`` and is decorated with
:func:`register_control`.

Singularities (all are errors, :class:`FormationSingularityError`, a ``ValueError``):

* Controls 1 and 3 divide by ``cos β0`` (and ``d0``): the reference bearing must satisfy ``|β0| < π/2``;
* Control 2 divides by ``d cos β``: it needs ``|β| < π/2`` and ``d > 0`` (Theorem 2's domain).

Controls 1 and 3 are regular at ``d = 0``: they use ``d cos(β − β0)`` and ``d sin β``, smooth functions of
the relative position (only the measurement of ``β`` degrades there). A divisor whose magnitude falls below
:data:`SINGULAR_COS` (for a cosine) or to ``d ≤ 0`` raises. Near the
singular set the gains grow like ``1/cos``; :func:`warn_near_singular` issues a :class:`SingularityWarning`
once the cosine drops below :data:`WARN_COS` (|angle| > 84.3°).
"""

from __future__ import annotations

import math
import warnings
from abc import ABC, abstractmethod
from dataclasses import dataclass

from ...core.registry import Registry

__all__ = [
    "RelativeMeasurement",
    "FormationReference",
    "FormationControl",
    "Control1",
    "Control2",
    "Control3",
    "CONTROLS",
    "register_control",
    "make_control",
    "FormationSingularityError",
    "SingularityWarning",
    "SINGULAR_COS",
    "WARN_COS",
    "warn_near_singular",
]

#: a cosine divisor at or below this magnitude is treated as singular (gains would exceed 1000 × nominal)
SINGULAR_COS = 1e-3
#: a cosine divisor below this magnitude triggers a :class:`SingularityWarning` (gains above 10 × nominal)
WARN_COS = 0.1


class FormationSingularityError(ValueError):
    """A formation control was evaluated on (or numerically at) its singular set."""


class SingularityWarning(UserWarning):
    """A formation control operates close to its singular set; its gains are large."""


@dataclass(frozen=True)
class RelativeMeasurement:
    """What follower ``i`` measures or estimates about its predecessor ``i − 1``.

    Attributes
    ----------
    distance : float
        ``d_i`` (m).
    bearing : float
        ``β_i`` (rad), predecessor's direction relative to the follower's heading.
    heading_difference : float
        ``γ_i = φ_i − φ_{i−1}`` (rad).
    predecessor_speed : float
        ``v_{i−1}`` (m/s).
    """

    distance: float
    bearing: float
    heading_difference: float
    predecessor_speed: float


@dataclass(frozen=True)
class FormationReference:
    """Formation parameters of one follower at one instant.

    Attributes
    ----------
    distance, bearing : float
        ``d0`` (m) and ``β0`` (rad).
    distance_rate, bearing_rate : float
        ``ḋ0`` (m/s) and ``β̇0`` (rad/s); zero for constant parameters (used by Control 3 only).
    """

    distance: float
    bearing: float
    distance_rate: float = 0.0
    bearing_rate: float = 0.0


def _guard_cos(value: float, what: str) -> float:
    if not abs(value) > SINGULAR_COS:
        raise FormationSingularityError(
            f"{what} = {value:.3g} is within {SINGULAR_COS:g} of 0: the control is singular at |angle| = π/2; "
            "keep the angle inside (−π/2, π/2)"
        )
    return value


def _guard_positive(value: float, what: str) -> float:
    if not value > 0:
        raise FormationSingularityError(f"{what} = {value:.3g}: expected > 0 (the control divides by it)")
    return value


def warn_near_singular(cosine: float, what: str) -> None:
    """Warn with :class:`SingularityWarning` if ``|cosine| < WARN_COS`` (gains scale as ``1/cosine``)."""
    if abs(cosine) < WARN_COS:
        warnings.warn(
            f"{what} = {cosine:.3g} < {WARN_COS}: control gains scale with 1/{what} "
            f"(here {1 / max(abs(cosine), 1e-300):.3g}×); consider a smaller |bearing|",
            SingularityWarning,
            stacklevel=2,
        )


class FormationControl(ABC):
    """Contract of a leader–follower control: ``command(measurement, reference, gain) -> (v, ω)``."""

    #: registry key used in scenario files
    name: str = ""
    #: True if the control uses the reference rates ``ḋ0, β̇0`` (references must provide them)
    uses_reference_rates: bool = False

    @abstractmethod
    def command(
        self, measurement: RelativeMeasurement, reference: FormationReference, gain: float
    ) -> tuple[float, float]:
        """Follower inputs ``(v_i, ω_i)`` in m/s and rad/s for gain ``k`` (1/s)."""


#: control name -> FormationControl subclass
CONTROLS: Registry[type[FormationControl]] = Registry("control")


def register_control(cls: type[FormationControl]) -> type[FormationControl]:
    """Class decorator adding a :class:`FormationControl` to :data:`CONTROLS` under ``cls.name``."""
    if not cls.name:
        raise TypeError(f"{cls.__name__} needs a non-empty 'name' to be registered")
    return CONTROLS.register(cls.name, cls)


def make_control(name: str) -> FormationControl:
    """Instantiate the registered control ``name``."""
    if name not in CONTROLS:
        raise ValueError(CONTROLS.unknown(name))
    return CONTROLS[name]()


@register_control
class Control1(FormationControl):
    """Reference-point tracking (docs/theory/leader_follower.md §3.1): ``x_e' = −k x_e``, ``y_e' = −k y_e`` exactly.

    Source: Karasalo & Hu (2010), Theorem 1, eq. 9.

    Notes
    -----
    Solving eq. 12 for ``(v, ω)`` gives (the factor ``k`` of eq. 9 is multiplied out, so ``k = 0`` is allowed)::

        v = [k (d cos(β − β0) − d0) + v_{i−1} cos(γ + β0)] / cos β0
        ω = [k (d sin β − d0 sin β0) − v_{i−1} sin γ] / (d0 cos β0)
    """

    name = "control1"

    def command(
        self, measurement: RelativeMeasurement, reference: FormationReference, gain: float
    ) -> tuple[float, float]:
        """Inputs ``(v, ω)`` of Control 1."""
        d, beta, gamma, v_p = (
            measurement.distance,
            measurement.bearing,
            measurement.heading_difference,
            measurement.predecessor_speed,
        )
        d0, beta0, k = reference.distance, reference.bearing, gain
        cos_b0 = _guard_cos(math.cos(beta0), "cos β0")
        _guard_positive(d0, "d0")
        # eq. leader_follower.5 (v): v = k/cos β0 (d cos(β − β0) − d0 + (v_{i−1}/k) cos(γ + β0))
        v = (k * (d * math.cos(beta - beta0) - d0) + v_p * math.cos(gamma + beta0)) / cos_b0
        # eq. leader_follower.5 (ω): ω = k/(d0 cos β0) (d sin β − d0 sin β0 − (v_{i−1}/k) sin γ)
        w = (k * (d * math.sin(beta) - d0 * math.sin(beta0)) - v_p * math.sin(gamma)) / (d0 * cos_b0)
        return v, w


@register_control
class Control2(FormationControl):
    """Monotone bearing convergence: ``d̂ = d cos β − d0 cos β0`` decays as ``e^{−kt}``.

    Theory: docs/theory/leader_follower.md §3.2; source: Karasalo & Hu (2010), Theorem 2, eq. 17.

    Notes
    -----
    ::

        v = [k (d − d0 cos(β − β0)) + v_{i−1} cos(γ + β)] / cos β
        ω = [k (d sin β − d0 sin β0) − v_{i−1} sin γ] / (d cos β)

    and ``(β − β0)' = −k (d0/d) sin(β − β0)`` (eq. 19), so ``|β − β0|`` decreases monotonically while
    ``|β| < π/2``.
    """

    name = "control2"

    def command(
        self, measurement: RelativeMeasurement, reference: FormationReference, gain: float
    ) -> tuple[float, float]:
        """Inputs ``(v, ω)`` of Control 2."""
        d, beta, gamma, v_p = (
            measurement.distance,
            measurement.bearing,
            measurement.heading_difference,
            measurement.predecessor_speed,
        )
        d0, beta0, k = reference.distance, reference.bearing, gain
        cos_b = _guard_cos(math.cos(beta), "cos β")
        _guard_positive(d, "d")
        # eq. leader_follower.7 (v): v = k/cos β (d − d0 cos(β − β0) + (v_{i−1}/k) cos(γ + β))
        v = (k * (d - d0 * math.cos(beta - beta0)) + v_p * math.cos(gamma + beta)) / cos_b
        # eq. leader_follower.7 (ω): ω = k/(d cos β) (d sin β − d0 sin β0 − (v_{i−1}/k) sin γ)
        w = (k * (d * math.sin(beta) - d0 * math.sin(beta0)) - v_p * math.sin(gamma)) / (d * cos_b)
        return v, w


@register_control
class Control3(Control1):
    """Control 1 plus feed-forward of time-varying ``d0(t), β0(t)`` (docs/theory/leader_follower.md §3.4).

    Source: Karasalo & Hu (2010), Theorem 3, eqs. 24–25.

    Notes
    -----
    ::

        Δv = −ḋ0 / cos β0
        Δω = −(ḋ0 sin β0 + β̇0 d0 cos β0) / (d0 cos β0)

    cancel the term ``Φ(t)`` of eq. 20, restoring ``x_e' = −k x_e``, ``y_e' = −k y_e``.
    """

    name = "control3"
    uses_reference_rates = True

    def command(
        self, measurement: RelativeMeasurement, reference: FormationReference, gain: float
    ) -> tuple[float, float]:
        """Inputs ``(v, ω)`` of Control 3."""
        v, w = super().command(measurement, reference, gain)
        d0, beta0 = reference.distance, reference.bearing
        d0_dot, beta0_dot = reference.distance_rate, reference.bearing_rate
        cos_b0 = math.cos(beta0)
        # eq. leader_follower.11: [Δv, Δω] = −1/(d0 cos β0) [ḋ0 d0, ḋ0 sin β0 + β̇0 d0 cos β0]
        dv = -d0_dot * d0 / (d0 * cos_b0)
        dw = -(d0_dot * math.sin(beta0) + beta0_dot * d0 * cos_b0) / (d0 * cos_b0)
        # eq. leader_follower.11: ṽ = v + Δv, ω̃ = ω + Δω
        return v + dv, w + dw
