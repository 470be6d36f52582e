"""Scenario files of ``mobisense replay`` on a field (docs/theory/replay.md §2): validated pydantic models.

A field replay names the field and its spatial noise, the platforms, the formation (shape controller and
its gains), the motion of the centre (level-curve tracking or an optimised reference), the cooperative
filter, the duration and the filter period, e.g. ``problems/replay_isotherm13.yaml``::

    name: replay_isotherm13
    field: {kind: ocean_temperature}
    platforms: {count: 4, max_speed: 3.0, initial: {center: [5, 27], velocity: [1, 0]}}
    formation: {kind: cross, shape: {adaptive: {bounds: {a: [0.5, 4], b: [0.5, 4]}, every: 20}}}
    motion: {kind: level_curve, level: 13.0, speed: 1.0, steering_gain: 1.0}
    filter: {noise: {sigma_process: 0.01, sigma_measurement: 0.05, sigma_hessian: 0.02}}
    duration: 48.0
    time_step: 0.05

Formations (``kind``): ``cross`` (four platforms, docs/theory/steady_state.md §2 shape ``a, b`` fixed, from the
steady-state design, from a ``mobisense steady-state`` summary, or adapted online by step 3A), ``rigid`` (any offsets)
and ``rotating`` (offsets turning at ``angular_speed``, eqs. 42-43). Motions: ``level_curve`` (eq. 48;
``derivatives: true_field`` feeds the true field to the controller, for testing) and ``reference`` (the centre tracks
sensor ``sensor`` of a ``solution.nc``). Every error is reported as ``FILE: key.path: …`` before anything is written.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BeforeValidator, Field, SerializeAsAny, model_validator

from ...core.config import (
    ConfigError,
    FiniteFloat,
    InvalidValue,
    NonNegativeFloat,
    PositiveFloat,
    Seed,
    StrictModel,
    Vector2,
    parse_config,
)
from ...core.errors import brief
from ...core.units import LengthUnit, PhysicalUnit, TimeUnit
from ...estimation.cooperative.information_model import cross_formation
from ...estimation.cooperative.noise_config import NoiseConfig
from ...estimation.cooperative.spatial_noise import SpatialNoiseConfig
from ...estimation.fields.library import FieldSpec
from ..level_curve import LEVEL_FUNCTIONS, LevelFunctionName
from .plan import TrackingGains

__all__ = [
    "InitialState",
    "PlatformsConfig",
    "ShapeConfig",
    "CrossFormation",
    "RigidFormation",
    "RotatingFormation",
    "LevelCurveMotion",
    "ReferenceMotion",
    "FilterConfig",
    "FieldReplayScenario",
]


def _parse_kind(value: Any, registry: dict[str, type[StrictModel]], what: str) -> StrictModel:
    """Validate a ``{kind: …}`` mapping against the model registered under its kind (precise key paths)."""
    if isinstance(value, tuple(registry.values())):
        return value
    if not isinstance(value, dict) or "kind" not in value:
        raise ValueError(f"expected a mapping with 'kind' one of {sorted(registry)} ({what})")
    if not isinstance(value["kind"], str) or value["kind"] not in registry:  # a list or mapping is unhashable
        raise InvalidValue("kind", f"unknown {what} {brief(value['kind'])}; expected one of {sorted(registry)}")
    try:
        return parse_config(value, registry[value["kind"]], source="@")
    except ConfigError as err:  # re-raise relative to this key, keeping the message and suggestion
        path, _, message = str(err)[len("@: ") :].partition(": ")
        raise InvalidValue(path, message) from None


class InitialState(StrictModel):
    """Initial centre position (L) and velocity (L/T, nonzero), formation angle, random placement error."""

    center: Vector2
    velocity: Vector2
    angle: FiniteFloat | None = Field(None, description="formation angle (rad); default: velocity direction")
    perturbation: NonNegativeFloat = Field(0.0, description="std of each platform's start offset (L)")

    @model_validator(mode="after")
    def _moving(self) -> InitialState:
        if np.hypot(*self.velocity) == 0.0:
            raise InvalidValue(
                "velocity", "expected a nonzero centre velocity (the steering law needs a heading)"
            )
        return self


class PlatformsConfig(StrictModel):
    """Number of platforms, their limits (:mod:`mobisense.formation.platforms`) and initial state."""

    count: int = Field(ge=2, le=64)
    max_force: PositiveFloat | None = None
    max_speed: PositiveFloat | None = None
    initial: InitialState

    @model_validator(mode="after")
    def _initial_speed(self) -> PlatformsConfig:
        """A start faster than ``max_speed`` (1e12 L/T: the integrator crawled through the saturation for minutes)."""
        speed = float(np.hypot(*self.initial.velocity))
        if self.max_speed is not None and speed > self.max_speed:
            raise InvalidValue("initial.velocity", f"expected a speed at most max_speed = {self.max_speed:g}, got "
                               f"{speed:.6g}")  # fmt: skip
        return self


class ShapeGains(StrictModel):
    """``u_j = q_j^d'' − K2 (q_j − q_j^d) − K3 (q_j' − q_j^d')``: ``stiffness`` K2 (1/T²), ``damping`` K3."""

    stiffness: PositiveFloat = 4.0
    damping: PositiveFloat = 4.0


class ShapeBoundsConfig(StrictModel):
    """Bounds ``[min, max]`` (L) of the cross's half-distances a and b."""

    a: list[PositiveFloat]
    b: list[PositiveFloat]

    @model_validator(mode="after")
    def _ordered(self) -> ShapeBoundsConfig:
        for name in ("a", "b"):
            pair = getattr(self, name)
            if len(pair) != 2 or pair[0] > pair[1]:
                raise InvalidValue(name, f"expected [min, max] with 0 < min <= max, got {pair}")
        return self

    def pairs(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """``((a_min, a_max), (b_min, b_max))``."""
        return (self.a[0], self.a[1]), (self.b[0], self.b[1])


class SteadyStateShape(StrictModel):
    """Design ``(a, b)`` minimising ``tr P∞`` for the filter's noise within bounds (docs/theory/steady_state.md §3)."""

    bounds: ShapeBoundsConfig
    equal_sides: bool = False


class AdaptiveShape(StrictModel):
    """Step 3A every ``every`` filter steps, each change of a and b at most ``max_change`` (L).

    Step 3A is that of docs/theory/steady_state.md §5.

    The rate limit makes the assumption of Zhang & Leonard (2010), §III-E, that "the optimal formation will not change
    very fast" hold: without it the minimiser of ``J_k`` can jump between distant local minima (the covariance it
    depends on responds to the shape), and the formation would chase them.
    """

    bounds: ShapeBoundsConfig
    every: int = Field(10, ge=1)
    max_change: PositiveFloat = 0.25
    equal_sides: bool = False


class ShapeConfig(StrictModel):
    """Exactly one of ``{a, b}``, ``steady_state``, ``summary`` (mobisense steady-state), ``adaptive``."""

    a: PositiveFloat | None = None
    b: PositiveFloat | None = None
    steady_state: SteadyStateShape | None = None
    summary: str | None = Field(None, description="summary.json of mobisense steady-state (relative path)")
    adaptive: AdaptiveShape | None = None

    @model_validator(mode="after")
    def _one(self) -> ShapeConfig:
        given = [k for k in ("steady_state", "summary", "adaptive") if getattr(self, k) is not None]
        fixed = self.a is not None or self.b is not None
        if fixed and (self.a is None or self.b is None):
            raise InvalidValue("b" if self.b is None else "a", "a fixed shape needs both a and b")
        if len(given) + fixed != 1:
            raise InvalidValue(
                "(shape)",
                f"expected exactly one of {{a, b}}, steady_state, summary, adaptive; got {given or 'none'}",
            )
        return self


class _Oriented(StrictModel):
    orientation: Literal["velocity", "fixed"] = Field("velocity", description="e1 along the centre velocity")
    angle: FiniteFloat = Field(0.0, description="formation angle (rad) when orientation is fixed")
    gains: ShapeGains = ShapeGains()


class CrossFormation(_Oriented):
    """The four-platform cross of docs/theory/steady_state.md §2 (1, 2 at ∓a on e1; 3, 4 at ±b on e2)."""

    kind: Literal["cross"] = "cross"
    shape: ShapeConfig


class RigidFormation(_Oriented):
    """Any formation of fixed body-frame ``offsets`` (L, one per platform, centred by the tool)."""

    kind: Literal["rigid"] = "rigid"
    offsets: list[Vector2]


class RotatingGains(StrictModel):
    """Eq. 43: ``shape_stiffness`` K4 (1/T²), ``shape_damping`` K5 (1/T), ``angular_gain`` K6 (1/T)."""

    shape_stiffness: PositiveFloat = 4.0
    shape_damping: PositiveFloat = 4.0
    angular_gain: PositiveFloat = 2.0


class RotatingFormation(StrictModel):
    """Body-frame ``offsets`` turning about the centre at ``angular_speed`` (rad/T).

    Theory: docs/theory/formation_control.md §3.
    """

    kind: Literal["rotating"] = "rotating"
    offsets: list[Vector2]
    angular_speed: FiniteFloat
    gains: RotatingGains = RotatingGains()


FORMATIONS: dict[str, type[StrictModel]] = {"cross": CrossFormation, "rigid": RigidFormation,
                                            "rotating": RotatingFormation}  # fmt: skip


class LevelFunctionConfig(StrictModel):
    """``f = dh/dz`` of eq. 48: ``linear`` (``gain (z − C)``) or ``reciprocal`` (``gain (1/C − 1/z)``)."""

    kind: LevelFunctionName = "linear"
    gain: PositiveFloat = 1.0


class LevelCurveMotion(StrictModel):
    """Level-curve tracking of the centre (docs/theory/level_curve.md)."""

    kind: Literal["level_curve"] = "level_curve"
    level: FiniteFloat
    speed: PositiveFloat = 1.0
    speed_gain: PositiveFloat = 1.0
    steering_gain: PositiveFloat = 1.0
    level_function: LevelFunctionConfig = LevelFunctionConfig()
    derivatives: Literal["estimated", "true_field"] = "estimated"

    @model_validator(mode="after")
    def _positive_level(self) -> LevelCurveMotion:
        try:
            LEVEL_FUNCTIONS[self.level_function.kind](self.level, self.level_function.gain)
        except ValueError as err:
            raise InvalidValue("level", str(err)) from None
        return self


class ReferenceMotion(TrackingGains):
    """The centre tracks sensor ``sensor`` of an optimised ``solution`` (``problem`` solved if missing)."""

    kind: Literal["reference"] = "reference"
    solution: str
    problem: str | None = None
    sensor: int = Field(0, ge=0)


MOTIONS: dict[str, type[StrictModel]] = {"level_curve": LevelCurveMotion, "reference": ReferenceMotion}


class FilterConfig(StrictModel):
    """The cooperative Kalman filter in the loop and its Hessian source.

    Theory: docs/theory/replay.md §2.2 and docs/theory/hessian.md §5.

    ``hessian``: ``curvature`` (four-platform cross, s.1-s.8), ``least_squares`` (formations whose
    ``[x²/2, xy, y²/2]`` design has rank 3), ``window`` (joint quadratic fit to the last ``window`` steps'
    measurements: any formation that moves, e.g. a rotating pair), ``true_field`` (for testing) or
    ``fixed`` (the initial Hessian throughout). ``initial_std`` = prior standard deviations of ``z`` (F)
    and of each gradient component (F/L); the first estimate is drawn from that prior around the truth.
    """

    noise: NoiseConfig
    initial_std: list[PositiveFloat] = Field(default_factory=lambda: [1.0, 1.0])
    hessian: Literal["curvature", "least_squares", "window", "true_field", "fixed"] = "curvature"
    window: int = Field(10, ge=2, le=1000)
    initial_hessian: Literal["true_field", "zero"] = "true_field"
    hessian_smoothing: float = Field(1.0, gt=0.0, le=1.0, description="β of Ĥ ← Ĥ + β (Ĥ_raw − Ĥ)")
    hessian_warmup: int = Field(0, ge=0, description="samples before the Hessian source is first used")
    estimator: Literal["kalman", "window_fit"] = Field(
        "kalman",
        description="what the controllers see: the cooperative Kalman filter, or (no filter, for comparison, "
        "Zhang & Leonard (2010), Fig. 3) a joint quadratic least-squares fit to the last fit_window samples, "
        "moved to the centre",
    )
    fit_window: int = Field(6, ge=3, le=1000, description="samples of the window_fit estimator")
    hessian_relative_error: NonNegativeFloat = Field(
        0.0,
        description="ρ of U_k = σ3² I + ρ² diag(vec(Ĥ_F)²) in the level-curve frame F (0: constant U = σ3² I)",
    )

    @model_validator(mode="after")
    def _two(self) -> FilterConfig:
        if len(self.initial_std) != 2:
            raise InvalidValue("initial_std", f"expected [z_std, gradient_std], got {self.initial_std}")
        return self


class UnitsConfig(StrictModel):
    """Units of the file's numbers (UDUNITS; default metre, second, dimensionless field), written to result.nc."""

    length: LengthUnit = "m"
    time: TimeUnit = "s"
    field: PhysicalUnit = "1"


class PlotConfig(StrictModel):
    """Figure options: the map's ``extent`` [[x_min, x_max], [y_min, y_max]] (default: around the paths)."""

    extent: list[Vector2] | None = None
    snapshots: int = Field(8, ge=0, le=100)

    @model_validator(mode="after")
    def _box(self) -> PlotConfig:
        if self.extent is not None and (len(self.extent) != 2 or any(lo >= hi for lo, hi in self.extent)):
            raise InvalidValue(
                "extent", f"expected [[x_min, x_max], [y_min, y_max]], min < max; got {self.extent}"
            )
        return self


class FieldReplayScenario(StrictModel):
    """A closed-loop replay on a field: formation control + level-curve tracking + cooperative filter."""

    kind: Literal["field_replay"] | None = Field(None, description="file kind (optional: a 'field' key tells it)")
    name: str = Field(pattern=r"^[A-Za-z0-9_.\-]+$")
    field: FieldSpec
    spatial_noise: SpatialNoiseConfig | None = None
    platforms: PlatformsConfig
    formation: Annotated[
        SerializeAsAny[StrictModel], BeforeValidator(lambda v: _parse_kind(v, FORMATIONS, "formation"))
    ]
    motion: Annotated[
        SerializeAsAny[StrictModel], BeforeValidator(lambda v: _parse_kind(v, MOTIONS, "motion"))
    ]
    filter: FilterConfig
    duration: PositiveFloat
    time_step: PositiveFloat
    seed: Seed = 0
    units: UnitsConfig = UnitsConfig()
    plot: PlotConfig = PlotConfig()

    @model_validator(mode="after")
    def _consistent(self) -> FieldReplayScenario:
        N = self.platforms.count
        steps = self.duration / self.time_step
        if not 1 <= steps <= 1_000_000:
            raise InvalidValue("time_step", f"expected 1 … 1e6 steps in the duration, got {steps:g}")
        formation = self.formation
        if isinstance(formation, CrossFormation) and N != 4:
            raise InvalidValue("formation.kind", f"the cross needs platforms.count = 4, got {N}")
        if isinstance(formation, (RigidFormation, RotatingFormation)):
            if len(formation.offsets) != N:
                raise InvalidValue(
                    "formation.offsets",
                    f"expected {N} offsets (platforms.count), got {len(formation.offsets)}",
                )
            spread = np.asarray(formation.offsets, float)
            spread = spread - spread.mean(axis=0)
            gaps = np.linalg.norm(spread[:, None] - spread[None], axis=-1) + np.eye(N)
            if gaps.min() == 0.0:
                raise InvalidValue("formation.offsets", "expected the platforms at distinct positions")
            if (
                isinstance(formation, RigidFormation)
                and np.linalg.matrix_rank(spread, tol=1e-9 * spread.max()) < 2
            ):
                raise InvalidValue(
                    "formation.offsets", "a collinear rigid formation never observes the gradient across it "
                    "(docs/theory/cooperative.md §4, Cd5): use kind: rotating"
                )  # fmt: skip
        if self.filter.hessian == "curvature" and not isinstance(formation, CrossFormation):
            raise InvalidValue(
                "filter.hessian", "curvature needs the four-platform cross; use window or least_squares"
            )
        if self.filter.hessian == "least_squares":
            offsets = cross_formation(1.0, 1.0) if isinstance(formation, CrossFormation) else spread
            x, y = offsets[:, 0], offsets[:, 1]
            if np.linalg.matrix_rank(np.stack([x**2 / 2, x * y, y**2 / 2], -1), tol=1e-9) < 3:
                raise InvalidValue(
                    "filter.hessian", "least_squares needs offsets whose [x²/2, xy, y²/2] design has rank 3 "
                    "(not the cross, not a pair): use curvature or window"
                )  # fmt: skip
        return self
