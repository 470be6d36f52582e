"""Scenario files of ``mobisense simulate leader-follower``, strict pydantic models (docs/theory/leader_follower.md §9).

The shipped scenarios are those of Karasalo & Hu (2010), §8.

A scenario describes one leader, a chain of followers, the formation reference, the control, the sensing
and the timing; ``runs`` lists named variants overriding ``control``, ``reference`` and/or ``sensing`` (e.g.
Control 1 vs Control 2 on the same initial conditions). Minimal example::

    name: two agents, Control 1
    duration: 10.0          # s
    step: 0.01              # s: output spacing; sample time of filter/reference updates
    gain: 1.0               # k (1/s)
    leader: {pose: [0, 0, 0], speed: 10.0, turn_rate: 1.0471975511965976}
    followers:
      - pose: [-0.97, -0.70, 0.3141592653589793]
    reference: {kind: constant, distance: 1.0, bearing: 0.4487989505128276}
    control: control1
    sensing: {mode: exact}

Angles are in radians except keys ending in ``_deg``. Everything is validated before anything runs; errors
name the key path (``runs[1].reference.constant.bearing: …``).
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

import numpy as np
from pydantic import AfterValidator, Field, field_validator, model_validator

from ...core.config import FiniteFloat, InvalidValue, NonNegativeFloat, PositiveFloat, Seed, StrictModel
from ...estimation.tracking.range_ring import KHEPERA_MOUNT_ANGLES_DEG, KHEPERA_PAIRS
from ...estimation.tracking.switching_filter import MergeName
from .controls import CONTROLS

__all__ = [
    "LeaderConfig",
    "FollowerConfig",
    "ConstantReferenceConfig",
    "RampReferenceConfig",
    "SteppedReferenceConfig",
    "PathReferenceConfig",
    "ExactSensingConfig",
    "RingSensingConfig",
    "IntegrationConfig",
    "RunConfig",
    "LeaderFollowerScenario",
]


def _pose(value: list[float]) -> list[float]:
    if len(value) != 3:
        raise ValueError(f"expected a pose [x, y, phi] of length 3, got length {len(value)}: {value!r}")
    return value


def _bearing(value: float) -> float:
    if not abs(value) < math.pi / 2:
        raise ValueError(f"expected |bearing| < pi/2 = 1.5708 rad (the controls are singular there), got {value!r}")
    return value


Pose = Annotated[list[FiniteFloat], AfterValidator(_pose)]
Bearing = Annotated[FiniteFloat, AfterValidator(_bearing)]


class LeaderConfig(StrictModel):
    """The leader R_1: initial pose and its pre-defined inputs ``v_1``, ``ω_1(t) = ω + a sin(2π t / T)``."""

    pose: Pose
    speed: FiniteFloat
    turn_rate: FiniteFloat = 0.0
    turn_rate_amplitude: NonNegativeFloat = 0.0
    turn_rate_period: PositiveFloat = 1.0


class FollowerConfig(StrictModel):
    """A follower's initial pose ``[x, y, φ]`` (m, m, rad)."""

    pose: Pose


class ConstantReferenceConfig(StrictModel):
    """Constant ``d0`` (m) and ``β0`` (rad).

    ``distance_from_run: NAME`` instead of ``distance`` sets ``d0`` to the mean inter-agent distance measured in
    the earlier run ``NAME`` (the paper's "fair comparison" of constant and dynamic parameters, §8.3).
    """

    kind: Literal["constant"]
    bearing: Bearing
    distance: PositiveFloat | None = None
    distance_from_run: str | None = None

    @model_validator(mode="after")
    def _one_distance(self) -> ConstantReferenceConfig:
        if (self.distance is None) == (self.distance_from_run is None):
            raise InvalidValue("distance", "give exactly one of 'distance' and 'distance_from_run'")
        return self


class RampReferenceConfig(StrictModel):
    """Eq. 55 of Karasalo & Hu (2010), generalised: ``β̇0 = bearing_rate``, ``ḋ0 = a cos(f β0)``.

    ``a, f`` are ``distance_rate_amplitude`` and ``distance_rate_frequency``.
    """

    kind: Literal["ramp"]
    distance: PositiveFloat
    bearing: Bearing
    bearing_rate: FiniteFloat
    distance_rate_amplitude: FiniteFloat = 0.0
    distance_rate_frequency: FiniteFloat = 0.0


class SteppedReferenceConfig(StrictModel):
    """Piecewise-constant ``d0`` (m), ``β0`` (rad) switched at ``switch_times`` (s).

    Theory: docs/theory/leader_follower.md §4.4; source: Karasalo & Hu (2010), §8.1, Fig. 9.

    ``bearing`` lists ``m + 1`` values for ``m`` switch times; ``distance`` is one value (kept throughout) or
    ``m + 1`` values. Example (Fig. 9): ``{kind: steps, distance: 0.12, bearing: [0, 0.5236, 0],
    switch_times: [10, 60]}``.
    """

    kind: Literal["steps"]
    switch_times: Annotated[list[PositiveFloat], Field(min_length=1)]
    bearing: list[Bearing]
    distance: PositiveFloat | list[PositiveFloat]

    @model_validator(mode="after")
    def _pieces(self) -> SteppedReferenceConfig:
        m = len(self.switch_times)
        if any(b <= a for a, b in zip(self.switch_times[:-1], self.switch_times[1:], strict=True)):
            raise InvalidValue("switch_times", f"expected strictly increasing times, got {self.switch_times}")
        if len(self.bearing) != m + 1:
            raise InvalidValue("bearing", f"expected {m + 1} values for {m} switch times, got {len(self.bearing)}")
        if isinstance(self.distance, list) and len(self.distance) != m + 1:
            raise InvalidValue("distance", f"expected one value or {m + 1} values, got {len(self.distance)}")
        return self

    def distances(self) -> list[float]:
        """``d0`` on each piece."""
        return list(self.distance) if isinstance(self.distance, list) else [self.distance] * len(self.bearing)


class PathReferenceConfig(StrictModel):
    """Dynamic path-following parameters (Karasalo & Hu (2010), §8.3, Fig. 13): tolerance ``A_max`` (m²) and bounds."""

    kind: Literal["path"]
    max_area: PositiveFloat
    max_distance: PositiveFloat
    max_bearing: Bearing = math.pi / 3


ReferenceConfig = Annotated[
    ConstantReferenceConfig | RampReferenceConfig | SteppedReferenceConfig | PathReferenceConfig,
    Field(discriminator="kind"),
]


class ExactSensingConfig(StrictModel):
    """True relative states (continuous-time feedback)."""

    mode: Literal["exact"]


class RingSensingConfig(StrictModel):
    """Directional range-sensor ring + switching Kalman filter (default: Khepera II, Karasalo & Hu (2010), Fig. 4)."""

    mode: Literal["ring"]
    max_range: PositiveFloat
    noise_std: PositiveFloat
    acceleration_std: PositiveFloat
    mount_radius: PositiveFloat = 0.25
    mount_angles_deg: list[FiniteFloat] = Field(default_factory=lambda: list(KHEPERA_MOUNT_ANGLES_DEG))
    headings_deg: list[FiniteFloat] | None = None
    field_of_view_deg: PositiveFloat = 100.0
    target_radius: NonNegativeFloat = 0.0
    pairs: list[list[int]] = Field(default_factory=lambda: [list(p) for p in KHEPERA_PAIRS])
    merge: MergeName = "closest"
    initial_velocity_std: PositiveFloat = 1.0

    @model_validator(mode="after")
    def _layout(self) -> RingSensingConfig:
        n = len(self.mount_angles_deg)
        if n < 2:
            raise InvalidValue("mount_angles_deg", f"expected at least 2 sensors, got {n}")
        if self.headings_deg is not None and len(self.headings_deg) != n:
            raise InvalidValue("headings_deg", f"expected {n} headings (one per sensor), got {len(self.headings_deg)}")
        if self.field_of_view_deg > 360:
            raise InvalidValue("field_of_view_deg", f"expected at most 360, got {self.field_of_view_deg}")
        if not self.pairs:
            raise InvalidValue("pairs", "expected at least one sensor pair")
        for j, pair in enumerate(self.pairs):
            if len(pair) != 2 or pair[0] == pair[1] or not all(1 <= q <= n for q in pair):
                raise InvalidValue(f"pairs[{j}]", f"expected two different sensor numbers in 1..{n}, got {pair}")
        return self


SensingConfig = Annotated[ExactSensingConfig | RingSensingConfig, Field(discriminator="mode")]


class IntegrationConfig(StrictModel):
    """``scipy.integrate.solve_ivp`` settings."""

    method: Literal["RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA"] = "DOP853"
    rtol: PositiveFloat = 1e-9
    atol: PositiveFloat = 1e-12


def _control_name(value: str | None) -> str | None:
    if value is not None and value not in CONTROLS:
        raise ValueError(f"expected one of {sorted(CONTROLS)}, got {value!r}")
    return value


ControlName = Annotated[str, AfterValidator(_control_name)]


class RunConfig(StrictModel):
    """A named variant of the scenario; unset keys inherit the scenario's."""

    name: Annotated[str, Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")]
    control: ControlName | None = None
    reference: ReferenceConfig | None = None
    sensing: SensingConfig | None = None


class LeaderFollowerScenario(StrictModel):
    """A leader–follower simulation scenario (see the module docstring)."""

    kind: Literal["leader_follower"] | None = Field(None, description="file kind (optional: 'leader' tells it)")
    name: str
    description: str = ""
    duration: PositiveFloat
    step: PositiveFloat
    gain: PositiveFloat = 1.0
    seed: Seed = 0
    leader: LeaderConfig
    followers: Annotated[list[FollowerConfig], Field(min_length=1)]
    reference: ReferenceConfig
    control: ControlName = "control1"
    sensing: SensingConfig = Field(default_factory=lambda: ExactSensingConfig(mode="exact"))
    integration: IntegrationConfig = Field(default_factory=IntegrationConfig)
    runs: Annotated[list[RunConfig], Field(min_length=1)] = Field(default_factory=lambda: [RunConfig(name="main")])

    @field_validator("name")
    @classmethod
    def _nonempty(cls, value: str) -> str:
        if not value.strip():
            raise ValueError("expected a non-empty name")
        return value

    @model_validator(mode="after")
    def _consistent(self) -> LeaderFollowerScenario:
        n_steps = self.duration / self.step
        if self.step > self.duration:  # no step would be taken (was an internal error)
            raise InvalidValue("step", f"expected at most duration = {self.duration}, got {self.step}")
        if abs(n_steps - round(n_steps)) > 1e-9 * max(1.0, n_steps):
            raise InvalidValue("step", f"expected a divisor of duration = {self.duration}, got {self.step}")
        if isinstance(self.reference, ConstantReferenceConfig) and self.reference.distance_from_run is not None:
            raise InvalidValue("reference.distance_from_run", "only allowed in runs[…].reference")
        seen: list[str] = []
        for i, run in enumerate(self.runs):
            if run.name in seen:
                raise InvalidValue(f"runs[{i}].name", f"duplicate run name {run.name!r}")
            control = run.control or self.control
            reference = run.reference or self.reference
            where = f"runs[{i}].reference" if run.reference is not None else "reference"
            if CONTROLS[control].uses_reference_rates and isinstance(
                reference, PathReferenceConfig | SteppedReferenceConfig
            ):
                raise InvalidValue(
                    f"runs[{i}].control",
                    f"{control} needs the rates of d0 and beta0; use a 'constant' or 'ramp' reference, or control1",
                )
            if isinstance(reference, ConstantReferenceConfig) and reference.distance_from_run is not None:
                if reference.distance_from_run not in seen:
                    raise InvalidValue(
                        f"{where}.distance_from_run",
                        f"expected the name of an earlier run {seen}, got {reference.distance_from_run!r}",
                    )
            if isinstance(reference, RampReferenceConfig):
                _check_ramp(reference, self.duration, where)
            seen.append(run.name)
        return self

    def resolved_runs(self) -> list[tuple[str, str, ReferenceConfig, SensingConfig]]:
        """``(name, control, reference, sensing)`` of every run, with the scenario's values filled in."""
        return [
            (run.name, run.control or self.control, run.reference or self.reference, run.sensing or self.sensing)
            for run in self.runs
        ]


def _check_ramp(reference: RampReferenceConfig, duration: float, where: str) -> None:
    """Reject a ramp whose ``β0(t)`` leaves (−π/2, π/2) or whose ``d0(t)`` reaches 0 within the run."""
    from .references import BearingRampReference

    schedule = BearingRampReference(
        reference.distance,
        reference.bearing,
        reference.bearing_rate,
        reference.distance_rate_amplitude,
        reference.distance_rate_frequency,
    )
    # ḋ0 is bounded by |a| and β0 is linear: a grid finer than the fastest oscillation of d0 catches any crossing
    n = int(min(1e5, 200 + 20 * duration * abs(reference.bearing_rate * reference.distance_rate_frequency)))
    for t in np.linspace(0.0, duration, n):
        ref = schedule.at(float(t))
        if not abs(ref.bearing) < math.pi / 2:
            raise InvalidValue(
                where, f"beta0(t) reaches {ref.bearing:.4g} rad at t = {t:.4g} s; expected |beta0| < pi/2"
            )
        if not ref.distance > 0:
            raise InvalidValue(where, f"d0(t) reaches {ref.distance:.4g} m at t = {t:.4g} s; expected d0 > 0")
