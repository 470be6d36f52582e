"""A gridded Gaussian-random-field process and its point-measurement (kriging) rows (docs/theory/field.md).

A scalar field f(s, t) over a planar extent is represented by its values at the ``nx × ny`` cell centres
s_j (the process states, n = nx·ny, row-major with x fastest: j = ix + nx·iy). The space–time covariance
is separable, Cov[f(s, t), f(s', t')] = k(s, s') e^(−|t−t'|/τ), so (docs/theory/field.md §1, eq. field.2)

    A = −I/τ,   B = I,   Q = (2/τ) Kₛ,   Σ0 = Kₛ,   Kₛ = [k(s_i, s_j)] + jitter·σ²·I,

and Kₛ is the stationary covariance (A Kₛ + Kₛ A' + Q = 0). A sensor with ``measures: point`` measures
y = c(p)'x + e with the simple-kriging row c(p) = Kₛ⁻¹ k(p) (docs/theory/field.md §2, eq. field.3).

The problem-file block is :class:`FieldSpec` (validated without allocating anything of size n²);
:meth:`FieldSpec.process` builds the numeric :class:`FieldProcess` (cached).
"""

from __future__ import annotations

import functools
import math
import sys
from dataclasses import dataclass, field
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field, model_validator

from ..core.config import MAX_MAGNITUDE, MIN_MAGNITUDE, InvalidValue, PositiveFloat, StrictModel

__all__ = [
    "ShootingOptions",
    "flown_states",
    "RUNNING_COST_SUBSTEPS",
    "substeps_for",
    "FULL_SIGMA_STATES",
    "MAX_FIELD_STATES",
    "MAX_SUBSTEPS",
    "FieldKernel",
    "FieldSpec",
    "FieldProcess",
    "shooting_substeps",
    "shooting_rate",
    "shooting_memory_bytes",
    "shooting_seconds",
    "FINE_ITERATIONS",
    "STEP_ITERATIONS",
    "START_ITERATIONS",
    "COARSE_H_LAMBDA",
    "FIELD_PRIOR_RATIO",
    "check_field_prior",
    "CONSTRAINED_FACTOR",
]

#: The largest grid nx·ny accepted: Kₛ and every Σ are dense n × n (n = 2500: 50 MB per matrix).
MAX_FIELD_STATES = 2500


#: The most RK4 substeps per shooting interval (also the bound of ``solver.shooting.substeps``).
MAX_SUBSTEPS = 1000


def shooting_rate(spec: FieldSpec, noise_variances: list[float]) -> float:
    """λ_max = sqrt(a² + 2a Σ_i σ²/r_i) (1/T, a = 1/τ): a bound of the Hamiltonian system's eigenvalues.

    It holds for every sensor configuration (c̃'c̃ = k'Kₛ⁻¹k ≤ σ²); docs/theory/field.md §3.3.
    """
    a = 1.0 / spec.time_constant
    info = sum(spec.kernel.variance / r for r in noise_variances)
    return math.sqrt(a * a + 2.0 * a * info)


def shooting_substeps(spec: FieldSpec, noise_variances: list[float], duration: float, intervals: int,
                      max_h_lambda: float = 0.25) -> int:  # fmt: skip
    """Möbius-RK4 steps per interval so that h·λ_max ≤ ``max_h_lambda`` (docs/theory/field.md §3.3).

    λ_max is :func:`shooting_rate`. 0.25 is an accuracy target: cost error 9e-8 relative at K = 100 (m = 2)
    against 1.2e-6 at m = 1.
    """
    h = duration / intervals
    return max(1, math.ceil(h * shooting_rate(spec, noise_variances) / max_h_lambda - 1e-9))


#: substeps per interval at least with a running weight K ≠ 0: the endpoint quadrature of ∫Tr KΣ then has a
#: relative error below 1e-6
RUNNING_COST_SUBSTEPS = 4


def substeps_for(problem: Any, intervals: int, max_h_lambda: float = 0.25) -> int:
    """Substeps a shooting solve of ``problem`` (a :class:`~mobisense.ocp.problem.Problem`) takes on ``intervals``.

    :func:`shooting_substeps` of its field and sensors, at least :data:`RUNNING_COST_SUBSTEPS` with a running
    weight K ≠ 0 (told by its name or its numbers: no n × n matrix is built for a name). The solver
    (:class:`~mobisense.ocp.shooting.FieldShooting`) and its time estimate (:mod:`mobisense.ocp.sizes`) both
    take it from here; the estimate had counted 1 where the solver took 4 (random-problem audit).
    """
    m = shooting_substeps(problem.process.field, [s.noise.parameters()[0] for s in problem.sensors],
                          problem.horizon.tf - problem.horizon.t0, intervals, max_h_lambda)  # fmt: skip
    K = problem.cost.K
    running = K in ("mean", "sum") or (isinstance(K, list) and bool(np.any(np.asarray(K) != 0)))
    return max(m, RUNNING_COST_SUBSTEPS) if running else m


#: memory per shooting interval beyond its matrices (the expression graph's nodes and Ipopt's per-variable
#: vectors): the 5 × 5 field with N = 4 on K = 10 000 intervals (m = 1) peaked at 1.27 GB against 763 MiB estimated
#: without it (field audit, one measurement), 51 kB an interval
BYTES_PER_INTERVAL = 52_000


def shooting_memory_bytes(n: int, intervals: int, substeps: int, sensors: int = 1) -> int:
    """Estimated peak memory (bytes) of a shooting solve with N = ``sensors``.

    For the NLP 8 ((K+1)(n² (4m+2) + m (3N² + 4Nn)) + 3n²), 24 n² (K+1) for Σ(t), and
    :data:`BYTES_PER_INTERVAL` K.

    The adjoint sweep keeps every interval's whitened Z and, per substep, about four n × n temporaries
    (measured at n = 100, K = 100, m = 2: 85 MB above the interpreter's 95 MB; the NLP term gives 81 MB) and the
    sensors' N × n rows and N × N Gram and Woodbury blocks (measured at n = 25, K = 20: 73 kB a substep for
    N = 40, 0.30 MB for N = 100; the term gives 70 kB and 0.32 MB); the solution holds Σ(t), its copy in the
    dataset and the baseline's. K·m, and so the memory, grows with the horizon times λ_max
    (:func:`shooting_rate`), not with K: m falls as K grows.
    """
    per_substep = n * n * 4 + 3 * sensors * sensors + 4 * sensors * n
    nlp = 8 * ((intervals + 1) * (substeps * per_substep + 2 * n * n) + 3 * n * n) + 24 * n * n * (intervals + 1)
    return nlp + BYTES_PER_INTERVAL * intervals


#: lower bounds of a shooting iteration's cost per RK4 substep: a fixed part (s), the flops of ~4 n × n products,
#: and a part per pair of sensors (their N × N Gram and Woodbury blocks: 2.7e-6 s N² measured at N = 40 and 100).
#: Measured per substep and iteration: 2.7e-4 s at n = 25 (these give 2.3e-4), 3.5e-3 s at n = 100 (2.2e-3)
SECONDS_PER_SUBSTEP = 2e-4
FLOPS_PER_SECOND = 2e9
SECONDS_PER_SENSOR_PAIR = 2e-6
#: h·λ_max of the coarse phase's substeps (the ε-homotopy and random starts: a guide for the fine solve, not J)
COARSE_H_LAMBDA = 2.0
#: output files hold the full Σ(t) up to this many states by default, the variances diag Σ(t) beyond
FULL_SIGMA_STATES = 25
#: least Ipopt iterations of the fine solve, of a coarse ε step and of a random coarse start (measured on the 5 × 5,
#: 7 × 4 and 10 × 10 fields: 25–31, 21–49 and 42–107)
FINE_ITERATIONS, STEP_ITERATIONS, START_ITERATIONS = 20, 20, 40
#: a shooting solve with path constraints costs at least this many times one without: the lifted node states
#: and the rows make each iteration dearer and the homotopy's steps longer (field_mapping_island.yaml, the 5 × 5
#: field of field_mapping_5x5.yaml with a disc, a separation and a workspace: 21.7 s against 3.7 s; its coarse
#: steps 683 iterations of 27 ms against 190 of 10 ms, its fine solve 87 ms an iteration against 55 ms)
CONSTRAINED_FACTOR = 3.0


def shooting_seconds(
    n: int, intervals: int, substeps: int, sensors: int = 1, iterations: int = FINE_ITERATIONS
) -> float:
    """A lower estimate of a shooting solve's time (s): ``iterations`` iterations of K·m RK4 substeps.

    Each substep of an iteration (evaluations and the adjoint) costs at least :data:`SECONDS_PER_SUBSTEP` plus
    ~4 n³ flops at :data:`FLOPS_PER_SECOND` (more than one core sustains) plus
    :data:`SECONDS_PER_SENSOR_PAIR` N². Measured: the 5 × 5 field's fine solve (n = 25, K = 100, m = 2) took
    2.7e-4 s per substep and iteration over its 31 iterations; the 10 × 10 field 31 s against 0.5 s estimated;
    one gradient of the 5 × 5 field with N = 100 sensors (K = 20, m = 41) 22 s, 27 ms a substep: a bound that
    refuses only what cannot finish in the time allowed.
    """
    per_substep = SECONDS_PER_SUBSTEP + 4.0 * float(n) ** 3 / FLOPS_PER_SECOND + SECONDS_PER_SENSOR_PAIR * sensors**2
    return float(iterations) * intervals * substeps * per_substep


#: the largest eigenvalue of a field's process.Sigma0, in units of its variance σ²: the measurement update
#: Σ − ΣC'(CΣC' + r)⁻¹CΣ of a prior of size s ends O(σ²) with a rounding error of s·1e-16, so beyond 1e8 σ² it
#: keeps fewer than 8 digits (1e20 σ²: CasADi's evaluation failed; 1e10–1e13 σ²: the shooting's J 0.8–49 % off
#: its own re-integration on K = 10)
FIELD_PRIOR_RATIO = 1e8


def check_field_prior(Sigma0: np.ndarray, variance: float) -> np.ndarray:
    """``process.Sigma0`` of a field (symmetric positive definite, checked) within :data:`FIELD_PRIOR_RATIO` σ²."""
    largest = float(np.linalg.eigvalsh(Sigma0)[-1])
    if largest > FIELD_PRIOR_RATIO * variance:
        raise InvalidValue("Sigma0", f"expected variances at most {FIELD_PRIOR_RATIO:g} × the field's variance σ² = "
                           f"{variance:g} (a first measurement's update would cancel more than 8 of the 16 digits of "
                           f"the map's variance), got an eigenvalue {largest:.3g}")  # fmt: skip
    return Sigma0


class FieldKernel(StrictModel):
    """A stationary isotropic covariance kernel k(r) = σ² ρ(r/ℓ) (docs/theory/field.md, eq. field.1)."""

    type: Literal["matern32", "squared_exponential", "exponential"] = Field(
        "matern32",
        description="matern32: σ²(1+√3r/ℓ)e^(−√3r/ℓ); squared_exponential: σ²e^(−r²/2ℓ²); exponential: σ²e^(−r/ℓ)",
    )
    length_scale: PositiveFloat = Field(description="correlation length ℓ (L)")
    variance: PositiveFloat = Field(1.0, description="marginal variance σ² (state²)")

    def of_distance(self, r: Any) -> Any:
        """K at distance ``r`` (L): numpy array or CasADi expression, the same type back (state²)."""
        ca = sys.modules.get("casadi")  # a CasADi expression implies CasADi is loaded (validating needs none)
        lib = ca if ca is not None and isinstance(r, (ca.SX, ca.MX, ca.DM)) else np
        ell, var = self.length_scale, self.variance
        if self.type == "matern32":
            a = np.sqrt(3.0) * r / ell
            return var * (1.0 + a) * lib.exp(-a)
        if self.type == "squared_exponential":
            return var * lib.exp(-0.5 * (r / ell) ** 2)
        return var * lib.exp(-r / ell)

    @property
    def cutoff_distance(self) -> float:
        """Distance (L) beyond which the symbolic kernel is held at k(r_c) ≈ 1e-20 σ² (no underflow).

        Products of kernel values far below 1e-150 made a small LU/QR solve return NaN during trial
        steps; the cut-off changes c(p) by less than 1e-20.
        """
        ell = self.length_scale
        if self.type == "squared_exponential":
            return float(np.sqrt(2.0 * 46.0) * ell)
        if self.type == "exponential":
            return 46.0 * ell
        return float(50.8 / np.sqrt(3.0) * ell)  # (1 + a) e^(−a) ≈ 4.5e-21 at a = 50.8 (1e-20 at a ≈ 50.0)


class FieldSpec(StrictModel):
    """``process.field``: the gridded field whose A, B, Q, Σ0 and state locations are derived."""

    grid: list[int] = Field(min_length=2, max_length=2, description="[nx, ny] cells; n = nx·ny states")
    extent: list[Annotated[list[float], Field(min_length=2, max_length=2)]] = Field(
        min_length=2, max_length=2, description="[[x_min, x_max], [y_min, y_max]] (L)"
    )
    kernel: FieldKernel = Field(description="spatial covariance kernel {type, length_scale, variance}")
    time_constant: PositiveFloat = Field(description="τ (T): A = −I/τ, Q = 2Kₛ/τ")
    jitter: float = Field(1e-8, ge=1e-12, le=1e-4, description="relative nugget, raised ×10 until cond(Kₛ) ≤ 1e8")

    @model_validator(mode="after")
    def _checks(self) -> FieldSpec:
        nx, ny = self.grid
        if nx < 1 or ny < 1:
            raise InvalidValue("grid", f"expected two integers >= 1, got [{nx}, {ny}]")
        if nx * ny > MAX_FIELD_STATES:
            raise InvalidValue(
                "grid",
                f"expected nx·ny <= {MAX_FIELD_STATES} states (dense n×n covariances), got {nx}×{ny} = {nx * ny}",
            )
        for axis, (lo, hi) in zip("xy", self.extent, strict=True):
            if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
                raise InvalidValue("extent", f"expected finite {axis}_max > {axis}_min, got [{lo:g}, {hi:g}]")
            if not MIN_MAGNITUDE <= hi - lo <= MAX_MAGNITUDE or max(abs(lo), abs(hi)) > MAX_MAGNITUDE:
                raise InvalidValue("extent", f"expected {axis} bounds and a width within [{MIN_MAGNITUDE:g}, "
                                   f"{MAX_MAGNITUDE:g}], got [{lo:g}, {hi:g}] (distances would overflow; change "
                                   "the length unit)")  # fmt: skip
        return self

    @property
    def n(self) -> int:
        """Number of states nx·ny."""
        return self.grid[0] * self.grid[1]

    def locations(self) -> np.ndarray:
        """Cell centres (n, 2) (L), row-major with x fastest (no n × n allocation)."""
        (nx, ny), ((x0, x1), (y0, y1)) = self.grid, self.extent
        X, Y = np.meshgrid(x0 + (np.arange(nx) + 0.5) * (x1 - x0) / nx, y0 + (np.arange(ny) + 0.5) * (y1 - y0) / ny)
        return np.column_stack([X.ravel(), Y.ravel()])

    def process(self) -> FieldProcess:
        """The numeric field (Kₛ, its inverse, the locations), built once per distinct spec."""
        return _build(self.model_dump_json())

    def unresolved_fraction(self) -> float:
        """The mean kriging residual variance inside a cell, as a fraction of σ² (docs/theory/field.md §1).

        What the grid leaves unresolved between its nodes: σ² − k(p)'Kₛ⁻¹k(p) averaged over a 9 × 9 lattice of
        the cell at the centre of a block of at most 7 × 7 cells of this grid's spacing (nodes further away
        hardly change it: the kriging weights are screened). 0.011 at a spacing of ℓ/3 (Matérn-3/2), 0.08 at
        2ℓ/3 (field_mapping_5x5.yaml), 0.9 at 6.7 ℓ.
        """
        (nx, ny), ((x0, x1), (y0, y1)) = self.grid, self.extent
        hx, hy = (x1 - x0) / nx, (y1 - y0) / ny
        bx, by = min(nx, 7), min(ny, 7)
        block = self.model_copy(update={"grid": [bx, by], "extent": [[0.0, bx * hx], [0.0, by * hy]]}).process()
        cx, cy = (bx // 2 + 0.5) * hx, (by // 2 + 0.5) * hy
        offsets = np.linspace(-0.5, 0.5, 9)
        points = np.array([[cx + a * hx, cy + b * hy] for a in offsets for b in offsets])
        k = block.cross_covariance(points)
        residual = self.kernel.variance - np.einsum("ij,ij->i", k @ block.Ks_inv, k)
        return float(np.mean(residual) / self.kernel.variance)


class ShootingOptions(StrictModel):
    """Reduced-space shooting for field problems (docs/theory/field.md §3): only the controls are NLP variables.

    The ε-homotopy runs on ``coarse_intervals``, then one ε = 1 solve on ``intervals`` from its controls.
    """

    intervals: int = Field(100, ge=2, le=10_000, description="K control intervals of the final solve")
    coarse_intervals: int = Field(25, ge=2, le=10_000, description="intervals of the ε-homotopy")
    substeps: int | None = Field(
        None, ge=1, le=MAX_SUBSTEPS, description="RK4 steps per interval (default: h·λ ≤ 0.25)"
    )
    memory: int = Field(30, ge=2, le=500, description="L-BFGS history length")
    homotopy: list[float] = Field([0.03, 0.1, 0.2, 0.4, 0.7, 1.0], min_length=1, max_length=1000,
                                  description="coarse ε schedule")  # fmt: skip
    homotopy_tolerance: float = Field(1e-5, gt=0.0, lt=1.0, description="Ipopt tol of the coarse steps")
    coarse_max_iterations: int = Field(300, ge=1, le=1_000_000, description="Ipopt iterations per coarse step")
    full_sigma: bool | None = Field(
        None, description=f"write the full Σ(t) to solution.nc (default: n <= {FULL_SIGMA_STATES})"
    )
    starts: int = Field(0, ge=0, le=100, description="random coarse ε = 1 starts beside the ε-homotopy; the lowest "
                        "coarse J starts the fine solve (docs/theory/field.md §3.4)")  # fmt: skip

    @model_validator(mode="after")
    def _schedule(self) -> ShootingOptions:
        eps = self.homotopy
        increasing = all(b > a for a, b in zip(eps, eps[1:], strict=False))
        if any(not 0 < e <= 1 for e in eps) or not increasing or eps[-1] != 1.0:
            raise InvalidValue("homotopy", f"expected increasing ε in (0, 1] ending at 1, got {eps}")
        return self


@functools.lru_cache(maxsize=8)
def _build(spec_json: str) -> FieldProcess:
    return FieldProcess(FieldSpec.model_validate_json(spec_json))


@dataclass
class FieldProcess:
    """The numbers of a :class:`FieldSpec`: locations (n, 2), Kₛ (n, n) and Kₛ⁻¹, the jitter used.

    The jitter starts at ``spec.jitter``·σ² and is multiplied by 10 (up to 1e-4) until the Cholesky
    factorisation succeeds and cond(Kₛ) ≤ 1e8, so the kriging weights keep about 8 digits
    (docs/theory/field.md §1). The smoothing δ (L) of the distances r = sqrt(|p − s|² + δ²) keeps c(p)
    differentiable at a node: 1e-6·ℓ (Matérn, squared exponential), 1e-2·h_min (exponential: a cusp).
    """

    spec: FieldSpec
    locations: np.ndarray = field(init=False, repr=False)
    Ks: np.ndarray = field(init=False, repr=False)
    Ks_inv: np.ndarray = field(init=False, repr=False)
    chol: np.ndarray = field(init=False, repr=False)
    jitter_used: float = field(init=False)
    smoothing: float = field(init=False)

    def __post_init__(self) -> None:
        s = self.spec
        (nx, ny), ((x0, x1), (y0, y1)) = s.grid, s.extent
        self.locations = s.locations()
        h_min = min((x1 - x0) / nx, (y1 - y0) / ny)
        ell = s.kernel.length_scale
        self.smoothing = 1e-2 * h_min if s.kernel.type == "exponential" else 1e-6 * ell
        d = np.sqrt(((self.locations[:, None, :] - self.locations[None, :, :]) ** 2).sum(-1))
        K = s.kernel.of_distance(d)
        var, jitter = s.kernel.variance, s.jitter
        while True:
            Ks = K + jitter * var * np.eye(self.n)
            lam = np.linalg.eigvalsh(Ks)
            if lam[0] > 0 and lam[-1] / lam[0] <= 1e8:
                break
            if jitter >= 1e-4:
                raise InvalidValue("process.field.kernel", f"kernel matrix is singular even with jitter {jitter:g}·σ²")
            jitter *= 10.0
        self.jitter_used, self.Ks = jitter, Ks
        self.chol = np.linalg.cholesky(Ks)
        import scipy.linalg  # here, not at import: validating a problem file needs no scipy

        inv = scipy.linalg.cho_solve((self.chol, True), np.eye(self.n))
        self.Ks_inv = 0.5 * (inv + inv.T)

    @property
    def n(self) -> int:
        """Number of states."""
        return self.spec.n

    def matrices(self) -> dict[str, np.ndarray]:
        """A = −I/τ, B = I, Q = 2Kₛ/τ, Sigma0 = Kₛ (all n × n) and locations (n, 2) — eq. field.2."""
        tau, n = self.spec.time_constant, self.n
        return {"A": -np.eye(n) / tau, "B": np.eye(n), "Q": 2.0 * self.Ks / tau, "Sigma0": self.Ks.copy(),
                "locations": self.locations.copy()}  # fmt: skip

    def cross_covariance(self, p: np.ndarray) -> np.ndarray:
        """k(p) = [k(p, s_j)]_j for points p (m, 2) → (m, n), with the smoothing of the symbolic form."""
        d2 = ((np.atleast_2d(p)[:, None, :] - self.locations[None, :, :]) ** 2).sum(-1)
        return self.spec.kernel.of_distance(np.sqrt(d2 + self.smoothing**2))

    def weights(self, p: np.ndarray) -> np.ndarray:
        """Simple-kriging rows c(p)' = (Kₛ⁻¹ k(p))' for points p (m, 2) → (m, n) — eq. field.3."""
        return self.cross_covariance(p) @ self.Ks_inv

    def symbolic_cross_covariance(self, px: Any, py: Any, loc: Any) -> Any:
        """k(p_i, s_j) as a CasADi (n, N) matrix for position rows px, py (1, N) and locations ``loc`` (n, 2)."""
        import casadi as ca

        n = loc.size1() if hasattr(loc, "size1") else len(loc)
        ones = ca.DM.ones(n, 1)
        dx = ca.repmat(loc[:, 0], 1, px.size2()) - ca.mtimes(ones, px)
        dy = ca.repmat(loc[:, 1], 1, py.size2()) - ca.mtimes(ones, py)
        r = ca.fmin(ca.sqrt(dx**2 + dy**2 + self.smoothing**2), self.spec.kernel.cutoff_distance)
        return self.spec.kernel.of_distance(r)

    def symbolic_weights(self, p: Any, Ks_inv: Any, loc: Any) -> Any:
        """The kriging column c(p) = Kₛ⁻¹ k(p) (n, 1) for a symbolic position ``p`` (2, 1)."""
        import casadi as ca

        return ca.mtimes(Ks_inv, self.symbolic_cross_covariance(p[0], p[1], loc))

    def to_grid(self, values: np.ndarray) -> np.ndarray:
        """Per-state values (..., n) as (..., ny, nx) for maps."""
        nx, ny = self.spec.grid
        return np.asarray(values).reshape(*np.shape(values)[:-1], ny, nx)


def flown_states(t: np.ndarray, p: np.ndarray, v: np.ndarray, u: np.ndarray,
                 times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """The sensors under controls linear between the nodes, exactly (eq. field.7): p, v, u at ``times``.

    Parameters
    ----------
    t : ndarray, shape (K + 1,)
        Node times (T), increasing.
    p, v, u : ndarray, shape (K + 1, N, 2)
        Positions (L), velocities (L/T) and controls (L/T²) at the nodes.
    times : ndarray, shape (S,)
        Times (T) in [t[0], t[-1]].

    Returns
    -------
    p, v, u : ndarray, shape (S, N, 2)
    """
    k = np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 2)
    h = (t[k + 1] - t[k])[:, None, None]
    s = (times - t[k])[:, None, None]
    tau = s / h
    u0, du = u[k], u[k + 1] - u[k]
    return (p[k] + s * v[k] + h**2 * (u0 * tau**2 / 2 + du * tau**3 / 6), v[k] + h * (u0 * tau + du * tau**2 / 2),
            u0 + du * tau)  # fmt: skip
