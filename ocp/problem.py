"""The mobile-sensor Kalman optimal-control problem (docs/theory/ocp.md) and its YAML schema.

A :class:`Problem` is a validated pydantic model (the YAML file is its serialisation) with numpy
accessors for the matrices. Units are declared by the optional ``units`` block (:class:`Units`):
positions in the length unit L (default metre), times in the time unit T (default second), the process
state and the cost in units of their own (default dimensionless, "1"). Docstrings write L and T for
them; every output file carries the declared units as UDUNITS strings.

Example file (``problems/hussein2008.yaml``)::

    name: hussein2008
    horizon: {t0: 0.0, tf: 10.0}
    process: {A: [[-0.5]], B: [[1.0]], Q: [[1.0]], Sigma0: [[200.0]], locations: [[0.0, 0.0]]}
    sensors:
      - {name: s1, p0: [10, 10], v0: [0, -2], noise: {model: quadratic_range, beta: 5, gamma: 3}}
    cost: {M: [[20.0]], K: [[0.0]], alpha: 0.004}
    solver: {method: direct, collocation: {scheme: radau, degree: 3, intervals: 100},
             homotopy: {mode: fixed, step: 0.05}}
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BeforeValidator, Field, SerializeAsAny, model_validator

from ..core.config import (
    MAX_MAGNITUDE,
    MIN_MAGNITUDE,
    FiniteFloat,
    InvalidValue,
    Matrix,
    PositiveFloat,
    StrictModel,
    Vector2,
    check_psd,
    check_shape,
    check_spd,
    check_square,
    parse_config,
)
from ..core.units import LengthUnit, PhysicalUnit, TimeUnit, UnitSystem
from .field import MAX_SUBSTEPS, FieldSpec, ShootingOptions, check_field_prior, shooting_rate, shooting_substeps
from .noise_models import NoiseModel, parse_noise
from .path_constraints import PathConstraints, check_initial_state, check_terminal_states
from .reachability import check_reachable
from .solver_options import BVPOptions, CollocationOptions, HomotopyOptions, SolverOptions

MAX_DIRECT_FIELD_STATES = 9  #: a larger field is refused by the methods that carry Σ as variables
#: most sensors of a problem (a thousand already exceed the memory budget of every method here; a fuzzer's 2000
#: took 11 s to refuse, in the initial state's pairwise separation check)
MAX_SENSORS = 1000

__all__ = [
    "MAX_SENSORS",
    "Units",
    "Horizon",
    "Process",
    "Terminal",
    "Sensor",
    "Cost",
    "CollocationOptions",
    "HomotopyOptions",
    "BVPOptions",
    "ShootingOptions",
    "SolverOptions",
    "Problem",
    "load_problem",
    "problem_digest",
]


#: shortest horizon relative to the magnitude of its times: below it the grid's times are not distinct
HORIZON_RESOLUTION = 1e-9


class Units(StrictModel):
    """Units of the numbers of a problem file (UDUNITS symbols; ``"1"`` for a dimensionless quantity).

    Only labels: the mathematics is the same in any consistent units. They are written into every
    output file (``solution.nc``: ``p`` in ``length``, ``v`` in ``length time-1``, ``Sigma`` in
    ``state2``, the costates in ``cost`` per unit of their state).
    """

    length: LengthUnit = Field("m", description="unit of positions, locations, distances (L)")
    time: TimeUnit = Field("s", description="unit of times (T)")
    state: PhysicalUnit = Field("1", description="unit of the process state x (Σ is in state²)")
    cost: PhysicalUnit = Field("1", description="unit of the cost J (set by the weights M, K, alpha)")

    def system(self) -> UnitSystem:
        """The :class:`~mobisense.core.units.UnitSystem` that composes the units of derived quantities."""
        return UnitSystem(self.length, self.time, {"state": self.state, "cost": self.cost})


class Horizon(StrictModel):
    """Time horizon [t0, tf] (T)."""

    t0: FiniteFloat = Field(0.0, description="start time (T)")
    tf: FiniteFloat = Field(description="final time (T), > t0")

    @model_validator(mode="after")
    def _ordered(self) -> Horizon:
        if not self.tf > self.t0:
            raise InvalidValue("tf", f"expected tf > t0 = {self.t0:g}, got {self.tf:g}")
        span = self.tf - self.t0
        if not MIN_MAGNITUDE <= span <= MAX_MAGNITUDE:
            raise InvalidValue("tf", f"expected tf − t0 in [{MIN_MAGNITUDE:g}, {MAX_MAGNITUDE:g}], got {span:g}")
        if span < HORIZON_RESOLUTION * max(abs(self.t0), abs(self.tf)):
            raise InvalidValue(
                "tf",
                f"tf − t0 = {span:g} is below the resolution of times near {max(abs(self.t0), abs(self.tf)):g} "
                "(the collocation times would coincide); shift t0 towards 0",
            )
        return self


class Process(StrictModel):
    """The process ``x' = A x + B w``, ``E[w w'] = Q``, its initial error covariance and locations.

    Either the explicit matrices or ``field`` (a gridded random field, :class:`~mobisense.ocp.field.FieldSpec`,
    from which A, B, Q, Σ0 and the locations are derived: docs/theory/field.md §1; ``Sigma0`` may replace the
    derived Σ0 = Kₛ, e.g. with the filter's Σ at a re-plan instant).
    """

    A: Matrix | None = Field(None, description="n×n state matrix of x' = A x + B w (1/T)")
    B: Matrix | None = Field(None, description="n×m noise input matrix")
    Q: Matrix | None = Field(None, description="m×m intensity of the white process noise w (symmetric, PSD)")
    Sigma0: Matrix | None = Field(None, description="n×n initial error covariance (symmetric positive definite); "
                                  "with field: optional, default the field's stationary covariance Kₛ")
    locations: list[Vector2] | None = Field(None, description="one planar location per state (L)")
    field: FieldSpec | None = Field(None, description="a gridded random field instead of the matrices")

    @model_validator(mode="after")
    def _shapes(self) -> Process:
        explicit = [k for k in ("A", "B", "Q", "locations") if getattr(self, k) is not None]
        if self.field is not None:
            if explicit:
                raise InvalidValue(explicit[0], "expected no explicit matrices with process.field (they are derived; "
                                   "only Sigma0 may replace Kₛ as the initial covariance)")  # fmt: skip
            if self.Sigma0 is not None:  # a prior map's covariance, or the filter's Σ at a re-plan instant
                check_field_prior(check_spd("Sigma0", check_shape("Sigma0", self.Sigma0, (self.field.n, self.field.n))),
                                  self.field.kernel.variance)  # fmt: skip
            return self
        for key in ("A", "B", "Q", "Sigma0", "locations"):
            if getattr(self, key) is None:
                raise InvalidValue(key, "expected the matrices A, B, Q, Sigma0, locations, or a field block")
        A = check_square("A", self.A)
        n = A.shape[0]
        m = np.asarray(self.B).shape[1]
        check_shape("B", self.B, (n, m))
        check_psd("Q", check_shape("Q", self.Q, (m, m)))
        check_spd("Sigma0", check_shape("Sigma0", self.Sigma0, (n, n)))
        if len(self.locations) != n:
            raise InvalidValue("locations", f"expected {n} locations (one per state), got {len(self.locations)}")
        return self

    @property
    def n_states(self) -> int:
        """Number of process states n."""
        return self.field.n if self.field is not None else len(self.A)

    def arrays(self) -> dict[str, np.ndarray]:
        """A (n,n), B (n,m), Q (m,m), Sigma0 (n,n), locations (n,2) as float arrays (derived for a field)."""
        if self.field is not None:
            arrays = self.field.process().matrices()
            if self.Sigma0 is not None:
                arrays["Sigma0"] = np.asarray(self.Sigma0, float)
            return arrays
        return {k: np.asarray(getattr(self, k), float) for k in ("A", "B", "Q", "Sigma0", "locations")}


class Terminal(StrictModel):
    """Fixed terminal sensor position and/or velocity (omitted = free)."""

    p: Vector2 | None = Field(None, description="fixed terminal position [x, y] (L)")
    v: Vector2 | None = Field(None, description="fixed terminal velocity [vx, vy] (L/T)")


class Sensor(StrictModel):
    """One mobile sensor: a planar double integrator ``p' = v, v' = u`` with a noise model."""

    name: str = Field(min_length=1, max_length=100, description="sensor name (unique), used in outputs")
    p0: Vector2 = Field(description="initial position [x, y] (L)")
    v0: Vector2 = Field(description="initial velocity [vx, vy] (L/T)")
    noise: Annotated[SerializeAsAny[NoiseModel], BeforeValidator(parse_noise)] = Field(
        description="measurement-noise model {model: NAME, parameters…}: variance as a function of position"
    )
    measures: Matrix | Literal["point"] | None = Field(
        default=None,
        description="rows of C_i (default: every state), or 'point': the field value at the sensor's position "
        "(kriging row c(p), needs process.field; docs/theory/field.md §2)",
    )
    terminal: Terminal | None = Field(None, description="fixed terminal position and/or velocity (default: free)")
    u_max: PositiveFloat | None = Field(default=None, description="bound on |u_i| (L/T^2)")


#: named weight matrices: ``mean`` = I/n (the mean error variance), ``sum`` = I (the trace), ``zero``
WeightName = Literal["mean", "sum", "zero"]


class Cost(StrictModel):
    """Cost weights: ``J = Tr[M Σ(tf)] + ∫ (alpha/2 |u|^2 + Tr[K Σ]) dt``.

    M and K are matrices or names: ``mean`` (I/n), ``sum`` (I), ``zero`` (K only).
    """

    M: Matrix | WeightName = Field(description="n×n terminal weight (SPD), or 'mean' (I/n) / 'sum' (I)")
    K: Matrix | WeightName | None = Field(None, description="n×n running weight (PSD; default 0), or a name")
    alpha: PositiveFloat = Field(description="control weight α of ∫ α/2 |u|² dt")

    def weight(self, key: str, n: int) -> np.ndarray:
        """Weight ``key`` ("M" or "K") as an (n, n) array."""
        value = getattr(self, key)
        if value is None or value == "zero":
            return np.zeros((n, n))
        if value == "mean":
            return np.eye(n) / n
        if value == "sum":
            return np.eye(n)
        return np.asarray(value, float)


class Problem(StrictModel):
    """A mobile-sensor Kalman optimal-control problem (docs/theory/ocp.md §1–§2) plus its solver options."""

    kind: Literal["problem"] | None = Field(None, description="file kind (optional for problem files)")
    name: str = Field(
        pattern=r"^[A-Za-z0-9_][A-Za-z0-9_.\-]{0,127}$", description="problem name: letters, digits, _ . - (no path)"
    )
    units: Units = Field(Units(), description="units of the file's numbers (default metre, second)")
    horizon: Horizon = Field(description="time horizon [t0, tf]")
    process: Process = Field(description="the estimated process and its initial error covariance")
    sensors: list[Sensor] = Field(
        min_length=1, max_length=MAX_SENSORS, description=f"the mobile sensors (1 to {MAX_SENSORS})"
    )
    cost: Cost = Field(description="weights of J = Tr[M Σ(tf)] + ∫ (α/2 |u|² + Tr[K Σ]) dt")
    constraints: PathConstraints | None = Field(
        None, description="path constraints of the sensors (direct and shooting methods; path_constraints.md)"
    )
    solver: SolverOptions = Field(SolverOptions(), description="how to solve (method, grid, homotopy, tolerances)")

    @model_validator(mode="after")
    def _cross_checks(self) -> Problem:
        n = self.process.n_states
        field = self.process.field
        if field is not None and "method" not in self.solver.model_fields_set:
            self.solver.method = "shooting"  # docs/theory/field.md §3.4: the scalable method for a field
        method = self.solver.method
        if method == "shooting" and field is None:
            raise InvalidValue("solver.method", "expected process.field with method 'shooting' (the O(n²N) "
                               "propagation needs the field structure A = −I/τ, Q ∝ Kₛ)")  # fmt: skip
        for key in ("M", "K"):
            if isinstance(getattr(self.cost, key), list):
                check = check_spd if key == "M" else check_psd
                check(f"cost.{key}", check_shape(f"cost.{key}", getattr(self.cost, key), (n, n)))
        if self.cost.M == "zero":
            raise InvalidValue("cost.M", "expected a positive definite terminal weight, not 'zero'")
        scales = self.reference_scales()
        for name, key, unit in (("length", "sensors", "L"), ("velocity", "horizon", "L/T"),
                                ("control", "horizon", "L/T²")):  # fmt: skip
            if not MIN_MAGNITUDE <= scales[name] <= MAX_MAGNITUDE:
                raise InvalidValue(
                    key,
                    f"the {name} scale of the problem is {scales[name]:g} {unit}, outside [{MIN_MAGNITUDE:g}, "
                    f"{MAX_MAGNITUDE:g}] (distances {scales['length']:g} L over tf − t0 = {scales['horizon']:g} T); "
                    "change the length or time units",
                )
        names = [s.name for s in self.sensors]
        if self.constraints is not None:
            if self.solver.method in ("indirect", "both"):
                why = "the indirect method has no state-constrained arcs; remove constraints or use method 'direct'"
                raise InvalidValue(
                    "constraints", f"expected no path constraints with solver.method {self.solver.method!r}: {why}"
                )
            if self.constraints.min_separation is not None and len(self.sensors) < 2:
                raise InvalidValue("constraints.min_separation", "expected at least two sensors to keep apart, "
                                   "got one (remove the key)")  # fmt: skip
            check_initial_state(self.constraints, [s.p0 for s in self.sensors], [s.v0 for s in self.sensors])
            ends = [(None, None) if s.terminal is None else (s.terminal.p, s.terminal.v) for s in self.sensors]
            check_terminal_states(self.constraints, ends)
        for i, sensor in enumerate(self.sensors):
            if names.index(sensor.name) != i:
                raise InvalidValue(f"sensors[{i}].name", f"duplicate sensor name {sensor.name!r}")
            if sensor.u_max is not None and method in ("indirect", "both"):
                raise InvalidValue(
                    f"sensors[{i}].u_max",
                    f"expected no control bound with solver.method {method!r} (got {sensor.u_max:g}): "
                    "the indirect method's control law would be a non-smooth saturation; "
                    "remove u_max or use method 'direct'",
                )
            check_reachable(i, sensor, self.horizon.tf - self.horizon.t0,
                            None if self.constraints is None else self.constraints.max_speed)  # fmt: skip
            if sensor.measures == "point":
                self._check_point_sensor(i, sensor)
            elif sensor.measures is not None and method == "shooting":  # was silently measured as a point sensor
                raise InvalidValue(f"sensors[{i}].measures", "expected 'point' with method 'shooting' (its sensors "
                                   "measure the field where they are), got a matrix; use method 'direct' for fixed "
                                   "rows")  # fmt: skip
            elif sensor.measures is not None:
                rows = np.asarray(sensor.measures, dtype=float)
                if rows.shape[1] != n:
                    raise InvalidValue(
                        f"sensors[{i}].measures", f"expected rows of length n = {n}, got {rows.shape[1]}"
                    )
                if np.any(np.all(rows == 0.0, axis=1)):
                    raise InvalidValue(f"sensors[{i}].measures", "expected no all-zero row")
            elif method == "shooting":
                raise InvalidValue(f"sensors[{i}].measures", "expected 'point' with method 'shooting'")
        if method == "shooting":
            self._check_shooting_size()
        if field is not None and method in ("direct", "indirect", "both") and n > MAX_DIRECT_FIELD_STATES:
            raise InvalidValue(
                "solver.method",
                f"expected method 'shooting' for a field of n = {n} > {MAX_DIRECT_FIELD_STATES} states: "
                f"'{method}' carries the n(n+1)/2 = {n * (n + 1) // 2} entries of Σ as variables "
                "(measured > 10 GB at n = 9; docs/theory/field.md §3.4)",
            )
        return self

    def _check_shooting_size(self) -> None:
        """Refuse a field whose default RK4 substeps (h·λ_max ≤ 0.25) exceed :data:`MAX_SUBSTEPS` per interval.

        Memory and time are the commands' budget (``--max-memory``, ``--max-time``: :mod:`mobisense.ocp.sizes`);
        this bounds the number of steps, whatever the machine. The key named is the one that makes λ_max large:
        the noise variance of the most informative sensor, the kernel's variance σ² when it is the larger factor of
        σ²/r, or the field's time constant.
        """
        o, spec, T = self.solver.shooting, self.process.field, self.horizon.tf - self.horizon.t0
        if o.substeps is not None or not all(s.noise.model == "constant" for s in self.sensors):
            return  # a range-dependent noise is refused per sensor
        noise = [s.noise.parameters()[0] for s in self.sensors]
        m = shooting_substeps(spec, noise, T, o.intervals)
        if m <= MAX_SUBSTEPS:
            return
        a, rate = 1.0 / spec.time_constant, shooting_rate(spec, noise)
        i = min(range(len(noise)), key=noise.__getitem__)
        noise_dominates = rate * rate - a * a > a * a  # λ_max² = a² + 2aΣσ²/r: the measurement term is the larger
        key, cause = (f"sensors[{i}].noise.variance_value", f"noise variance {noise[i]:g}") if noise_dominates else (
            "process.field.time_constant", f"time constant {spec.time_constant:g}")  # fmt: skip
        if noise_dominates and spec.kernel.variance >= sum(1.0 / r for r in noise):  # σ²/r: σ² the larger factor
            key, cause = "process.field.kernel.variance", f"kernel variance {spec.kernel.variance:g}"
        raise InvalidValue(key, f"the {cause} makes the field's fastest rate λ_max = {rate:.3g} per unit time; "
                           f"on intervals h = {T / o.intervals:.3g} the shooting method needs m = {m} RK4 substeps "
                           f"(h·λ_max ≤ 0.25), expected at most {MAX_SUBSTEPS} (more solver.shooting.intervals, "
                           "a larger noise variance or time constant, or solver.shooting.substeps)")  # fmt: skip

    def _check_point_sensor(self, i: int, sensor: Sensor) -> None:
        if self.process.field is None:
            raise InvalidValue(f"sensors[{i}].measures", "expected process.field with 'point' (the kriging rows "
                               "interpolate the field between its states)")  # fmt: skip
        if sensor.noise.model != "constant":
            raise InvalidValue(f"sensors[{i}].noise.model", "expected 'constant' with measures: point (the noise of "
                               "a range-dependent model would be evaluated at distance 0)")  # fmt: skip
        if self.solver.method in ("indirect", "both"):
            raise InvalidValue("solver.method", "expected 'direct' or 'shooting' with point sensors (the indirect "
                               "method has no kriging rows yet)")  # fmt: skip

    # ------------------------------------------------------------------ numeric accessors
    def reference_scales(self) -> dict[str, float]:
        """Sizes the NLP is scaled by: ``horizon`` tf − t0 (T), ``length`` (L), ``velocity`` (L/T), ``control`` (L/T²).

        ``length`` is the largest sensor–state distance at t0 (at least 1), ``velocity`` the larger of
        length / horizon and the initial speeds, ``control`` = velocity / horizon.
        """
        horizon = self.horizon.tf - self.horizon.t0
        field = self.process.field
        locations = field.locations() if field is not None else np.asarray(self.process.locations, float)
        starts = np.asarray([s.p0 for s in self.sensors], float)
        distances = np.linalg.norm(starts[:, None, :] - locations[None, :, :], axis=-1)
        length = max(1.0, float(distances.max()))
        velocity = max(length / horizon, *(float(np.hypot(*s.v0)) for s in self.sensors))
        return {"horizon": horizon, "length": length, "velocity": velocity, "control": velocity / horizon}

    @property
    def n(self) -> int:
        """Number of process states."""
        return self.process.n_states

    @property
    def N(self) -> int:  # noqa: N802  (the papers' symbol)
        """Number of sensors."""
        return len(self.sensors)

    def matrices(self) -> dict[str, np.ndarray]:
        """Numeric problem data: A (n,n), BQB' (n,n), Sigma0 (n,n), M (n,n), K (n,n), locations (n,2)."""
        a = self.process.arrays()
        return {
            "A": a["A"],
            "BQB": a["B"] @ a["Q"] @ a["B"].T,
            "Sigma0": a["Sigma0"],
            "M": self.cost.weight("M", self.n),
            "K": self.cost.weight("K", self.n),
            "locations": a["locations"],
        }

    def is_point(self, i: int) -> bool:
        """Whether sensor ``i`` measures the field at its own position (``measures: point``)."""
        return self.sensors[i].measures == "point"

    def measurement_rows(self, i: int) -> np.ndarray:
        """Rows of C_i for sensor ``i``, shape (m_i, n); default the identity (every state).

        A point sensor's row is the kriging row c(p0)' at its initial position (eq. field.3); the models
        evaluate c(p) along the path.
        """
        if self.is_point(i):
            return self.process.field.process().weights(np.asarray(self.sensors[i].p0, float)[None, :])
        measures = self.sensors[i].measures
        return np.eye(self.n) if measures is None else np.asarray(measures, float)

    def row_locations(self, i: int) -> np.ndarray:
        """Location (m_i, 2) each measurement row of sensor ``i`` refers to.

        A row c measures the states it weights; its location is the |c|-weighted mean of those states'
        locations (for a unit row e_j this is exactly s_j, the paper's case).
        """
        if self.is_point(i):
            return np.asarray(self.sensors[i].p0, float)[None, :]
        rows = np.abs(self.measurement_rows(i))
        return (rows @ self.matrices()["locations"]) / rows.sum(axis=1, keepdims=True)

    def coasting_violations(self) -> list[str]:
        """The constraints the no-control baseline (every sensor coasting, u ≡ 0) violates, one line each.

        Coasting from ``p0, v0`` ends at ``p0 + v0 (tf − t0)`` with velocity ``v0``; a fixed terminal
        position or velocity other than that is violated (to 1e-9 relative). The path constraints are checked
        on the straight coasting paths at 4001 times (their worst violation, beyond 1e-9 of the length scale).
        ``u_max`` always holds.
        """
        duration = self.horizon.tf - self.horizon.t0
        out = []
        if self.constraints is not None:
            from .path_constraints import margins

            t = np.linspace(0.0, duration, 4001)
            v = np.asarray([sensor.v0 for sensor in self.sensors], float)
            p = np.asarray([sensor.p0 for sensor in self.sensors], float)[None] + t[:, None, None] * v[None]
            tolerance = 1e-9 * max(1.0, float(np.abs(p).max()))
            for name, excess in margins(self.constraints, p, np.broadcast_to(v, p.shape)).items():
                worst = int(np.argmax(excess))
                if excess[worst] > tolerance:
                    out.append(f"constraints.{name}: coasting violates it by {excess[worst]:.3g} at "
                               f"t = {self.horizon.t0 + t[worst]:g}")  # fmt: skip
        for i, sensor in enumerate(self.sensors):
            if sensor.terminal is None:
                continue
            p0, v0 = np.asarray(sensor.p0, float), np.asarray(sensor.v0, float)
            for key, end in (("p", p0 + v0 * duration), ("v", v0)):
                target = getattr(sensor.terminal, key)
                if target is not None and np.abs(end - target).max() > 1e-9 * max(1.0, np.abs(target).max()):
                    out.append(f"sensors[{i}].terminal.{key}: coasting ends at ({end[0]:g}, {end[1]:g}), "
                               f"not ({target[0]:g}, {target[1]:g})")  # fmt: skip
        return out

    # ------------------------------------------------------------------ identity
    def normalised(self) -> dict[str, Any]:
        """The problem as a plain dict with every default filled in (what is hashed and stored)."""
        return self.model_dump(mode="json", exclude={"kind"})

    def digest(self) -> str:
        """The first 16 hex digits (64 bits) of the SHA-256 of the normalised problem with its solver options."""
        return problem_digest(self.normalised())

    def with_solver(self, **changes: Any) -> Problem:
        """A copy with solver options changed, e.g. ``with_solver(collocation={"intervals": 50})``."""
        data = self.normalised()
        for key, value in changes.items():
            if isinstance(value, dict):
                data["solver"][key].update(value)
            else:
                data["solver"][key] = value
        return Problem.from_dict(data)

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "<dict>") -> Problem:
        """Validate a dict (e.g. parsed YAML); raises :class:`mobisense.core.config.ConfigError`."""
        return parse_config(data, cls, source=source)


def problem_digest(normalised: dict[str, Any]) -> str:
    """:meth:`Problem.digest` of a problem given as its :meth:`Problem.normalised` dict."""
    text = json.dumps(normalised, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def load_problem(path: str | Path) -> Problem:
    """Read and validate a problem YAML file, or a shipped example by name (``load_problem("hussein2008")``).

    Raises :class:`mobisense.core.config.ConfigError` (one line naming the file and the key path).
    """
    from ..core.examples import resolve_input
    from ..core.kinds import load_as

    return load_as(resolve_input(path), "problem")
