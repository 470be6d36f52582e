"""Replay an optimised sensor plan and validate its promised estimation quality by Monte Carlo.

``mobisense replay`` on a scenario naming a ``solution.nc`` (:class:`OcpReplayScenario`):

1. **Control.** Every sensor is a Newtonian platform (:mod:`mobisense.formation.platforms`) tracking its optimised
   path with :class:`~mobisense.formation.replay.reference.TrackingController` (feed-forward of the optimiser's
   ``u``), integrated by ``solve_ivp`` (DOP853) from the planned initial state, optionally offset.
2. **Estimation.** Along the *flown* paths the actual Kalman filter of the problem's process runs at the
   sampling period ``Δt``, on ``runs`` independent realisations at once (batched; the covariance recursion
   is shared): truth ``x_k = F x_{k−1} + w_k`` with ``F = e^{AΔt}`` and ``w_k ~ N(0, Q_d)``,
   ``Q_d = ∫_0^Δt e^{As} BQB' e^{A's} ds`` (Van Loan), ``x_0 ~ N(0, Σ0)``, estimate started at 0; samples
   ``y_k = C x_k + ν_k`` with ``ν_k ~ N(0, R(p_k)/Δt)`` — the discrete equivalent of continuous measurements with
   spectral density ``R`` (docs/theory/ocp.md §1.2, eq. ocp.2), whose filter covariance tends to the Riccati solution as
   ``Δt → 0`` (first order in Δt, tested). ``R(p)`` comes from the noise models' symbolic ``variance(p, s, θ)`` (one
   measurement model for the optimiser and the replay).
3. **Comparison.** Errors ``e_k`` against the optimiser's ``Σ(t_k)``: empirical covariance, the average
   NEES ``ε̄_k = mean_b e_k' Σ(t_k)⁻¹ e_k`` with its two-sided χ² band (``B ε̄_k ~ χ²_{nB}`` if Σ is right),
   the same against the filter's own ``P_k``, and the delivered ``Tr[M E(tf)]`` against the promised
   ``Tr[M Σ(tf)]``.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from pydantic import Field

from ...core.config import PositiveFloat, Seed, StrictModel, Vector2
from ...core.interrupts import raise_if_interrupted
from ...estimation import kalman
from ...ocp.discretisation import discretise_process
from ..platforms import PlatformLimits, PlatformLimitsConfig, newton_rates
from .reference import ReferenceTrajectory, TrackingController

if TYPE_CHECKING:
    from ...ocp.problem import Problem
    from ...ocp.solution import Solution

__all__ = [
    "MAX_TRACKING_TIME_CONSTANTS",
    "TrackingGains",
    "MonteCarloOptions",
    "OcpReplayScenario",
    "simulate_tracking",
    "discretise_process",
    "measurement_variances",
    "measurement_matrices",
    "MonteCarloResult",
    "monte_carlo_filter",
    "replay_solution",
]


#: the most time constants of the tracking loop over a plan's horizon (:meth:`TrackingGains.check_horizon`)
MAX_TRACKING_TIME_CONSTANTS = 1e5


class TrackingGains(StrictModel):
    """PD gains of the reference tracking: ``stiffness`` Kp (1/T²), ``damping`` Kd (1/T)."""

    stiffness: PositiveFloat = 100.0
    damping: PositiveFloat = 20.0

    def build(self) -> TrackingController:
        """The :class:`TrackingController`."""
        return TrackingController(self.stiffness, self.damping)

    def check_horizon(self, span: float, source: str = "") -> None:
        """Refuse (``ConfigError``, prefixed by ``source``) gains whose loop is too fast to integrate over ``span`` (T).

        The tracking error obeys ``e'' + Kd e' + Kp e = 0`` (or slides along the force limit): its fastest rate is
        about ``max(Kd, √Kp)`` per T, and the explicit integrator (DOP853) needs steps shorter than its inverse.
        Over the plan's horizon that is :data:`MAX_TRACKING_TIME_CONSTANTS` time constants at most (10⁵: ≈ 17 s
        for the default problem, measured; 1e4: 4.8 s; a damping of 1e12 ran for minutes, found by a fuzzer).
        """
        from ...core.errors import ConfigError

        rate = max(self.damping, math.sqrt(self.stiffness))
        if rate * span > MAX_TRACKING_TIME_CONSTANTS:
            key = "damping" if self.damping >= math.sqrt(self.stiffness) else "stiffness"
            prefix = f"{source}: " if source else ""
            raise ConfigError(
                f"{prefix}tracking.{key}: the closed loop's fastest rate max(damping, √stiffness) = {rate:g} per "
                f"time unit over the plan's {span:g} is {rate * span:.3g} time constants, more than the "
                f"{MAX_TRACKING_TIME_CONSTANTS:g} an integration can resolve in reasonable time; lower the gains"
            )


class MonteCarloOptions(StrictModel):
    """Monte Carlo validation: ``runs`` realisations, filter period ``time_step`` (T), band ``confidence``."""

    runs: int = Field(1000, ge=2, le=1_000_000)
    time_step: PositiveFloat = 0.01
    confidence: float = Field(0.95, gt=0.0, lt=1.0)


class OcpReplayScenario(StrictModel):
    """A replay of a ``mobisense solve`` solution (paths relative to the scenario file)."""

    kind: Literal["plan_replay"] | None = Field(None, description="file kind (optional: 'solution' tells it)")
    name: str = Field(pattern=r"^[A-Za-z0-9_.\-]+$")
    solution: str = Field(description="solution.nc written by mobisense solve (or a sweep's tasks/part-NNNNNN.nc)")
    task: int | None = Field(
        None, ge=0, description="the sweep index of the task to replay, when 'solution' is a sweep's part file"
    )
    problem: str | None = Field(
        None, description="problem YAML solved first when the solution file is missing"
    )
    tracking: TrackingGains = TrackingGains()
    platforms: PlatformLimitsConfig = PlatformLimitsConfig()
    initial_offset: list[Vector2] | None = Field(
        None, description="start offset of each sensor from its plan (L)"
    )
    monte_carlo: MonteCarloOptions = MonteCarloOptions()
    seed: Seed = 0


# ------------------------------------------------------------------------------------------- control
def simulate_tracking(
    reference: ReferenceTrajectory,
    controller: TrackingController,
    times: np.ndarray,
    limits: PlatformLimits | None = None,
    initial_offset: np.ndarray | None = None,
    rtol: float = 1e-10,
) -> tuple[np.ndarray, np.ndarray]:
    """Fly Newtonian platforms along the reference with ``solve_ivp`` (DOP853).

    Parameters
    ----------
    reference : ReferenceTrajectory
    controller : TrackingController
    times : ndarray, shape (K,)
        Output times (T); the first is the start.
    limits : PlatformLimits, optional
    initial_offset : ndarray, shape (N, 2), optional
        Start at ``p_ref(t0) + offset`` with the reference velocity (L).
    rtol : float
        Relative tolerance (absolute: ``rtol`` × the path's length scale).

    Returns
    -------
    positions, velocities : ndarray, shape (K, N, 2)
    """
    from scipy.integrate import solve_ivp

    N = reference.n_sensors
    p0, v0, _ = reference(times[0])
    if initial_offset is not None:
        p0 = p0 + np.asarray(initial_offset, dtype=float)

    def rhs(t: float, y: np.ndarray) -> np.ndarray:
        r, v = y[: 2 * N].reshape(N, 2), y[2 * N :].reshape(N, 2)
        return newton_rates(v, controller(r, v, reference(t)), limits)

    scale = max(1.0, float(np.abs(p0).max()))
    sol = solve_ivp(rhs, (times[0], times[-1]), np.concatenate([p0.ravel(), v0.ravel()]), method="DOP853",
                    t_eval=times, rtol=rtol, atol=rtol * scale)  # fmt: skip
    if not sol.success:
        raise RuntimeError(f"integration of the tracking loop failed: {sol.message}")
    y = sol.y.T
    return y[:, : 2 * N].reshape(-1, N, 2), y[:, 2 * N :].reshape(-1, N, 2)


# ---------------------------------------------------------------------------------------- estimation
def measurement_variances(problem: Problem, positions: np.ndarray) -> np.ndarray:
    """Variances ``r`` of every measurement row at the sensor positions, by the noise models (docs/theory/ocp.md §1.3).

    Parameters
    ----------
    problem : Problem
    positions : ndarray, shape (K, N, 2)

    Returns
    -------
    ndarray, shape (K, m)
        Rows stacked sensor by sensor (``m = Σ_i m_i``), as in :func:`measurement_matrices`.
    """
    import casadi as ca

    K = positions.shape[0]
    p, s = ca.SX.sym("p", 2), ca.SX.sym("s", 2)
    columns = []
    for i, sensor in enumerate(problem.sensors):
        theta_values = np.asarray(sensor.noise.parameters(), dtype=float)
        theta = ca.SX.sym("theta", theta_values.size)
        variance = ca.Function("variance", [p, s, theta], [type(sensor.noise).variance(p, s, theta)]).map(K)
        for location in problem.row_locations(i):
            r = variance(
                positions[:, i, :].T, np.tile(location[:, None], K), np.tile(theta_values[:, None], K)
            )
            columns.append(np.asarray(r).ravel())
    return np.stack(columns, axis=-1)


def measurement_matrices(problem: Problem, positions: np.ndarray) -> np.ndarray:
    """``C_k`` with every sensor's rows stacked at each of the positions ``(K, N, 2)``, shape ``(K, m, n)``.

    A point sensor (``measures: point``) measures the field where it is: its kriging row c(p_k)' follows the
    flown position (eq. field.3); fixed rows are the same at every step.
    """
    K = positions.shape[0]
    blocks = []
    for i in range(problem.N):
        if problem.is_point(i):
            blocks.append(problem.process.field.process().weights(positions[:, i, :])[:, None, :])  # (K, 1, n)
        else:
            rows = problem.measurement_rows(i)
            blocks.append(np.broadcast_to(rows, (K, *rows.shape)))
    return np.concatenate(blocks, axis=1)


@dataclass
class MonteCarloResult:
    """Errors of the sampled Kalman filter against the optimiser's prediction (time axis first).

    Attributes
    ----------
    t : ndarray, shape (K,)
    predicted : ndarray, shape (K, n, n)
        The optimiser's ``Σ(t_k)``.
    filter_covariance : ndarray, shape (K, n, n)
        ``P_k(+)`` of the discrete filter along the flown paths.
    empirical : ndarray, shape (K, n, n)
        ``mean_b e e'`` over the runs.
    nees_predicted, nees_filter : ndarray, shape (K,)
        Average NEES against ``Σ(t_k)`` and against ``P_k``.
    band : tuple of float
        Two-sided χ² band of the average NEES at the requested confidence.
    runs : int
    """

    t: np.ndarray
    predicted: np.ndarray
    filter_covariance: np.ndarray
    empirical: np.ndarray
    nees_predicted: np.ndarray
    nees_filter: np.ndarray
    band: tuple[float, float]
    runs: int

    def fraction_inside(self, which: str = "predicted") -> float:
        """Fraction of the steps after ``t0`` whose average NEES lies inside the band."""
        nees = (self.nees_predicted if which == "predicted" else self.nees_filter)[1:]
        return float(np.mean((nees >= self.band[0]) & (nees <= self.band[1])))


def _nees(errors: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """``mean_b e' S⁻¹ e`` per step for errors ``(B, K, n)`` and covariances ``(K, n, n)``."""
    solved = np.linalg.solve(covariance[None], errors[..., None])[..., 0]
    return np.mean(np.sum(errors * solved, axis=-1), axis=0)


def monte_carlo_filter(
    problem: Problem,
    times: np.ndarray,
    positions: np.ndarray,
    predicted: np.ndarray,
    runs: int,
    rng: np.random.Generator,
    confidence: float = 0.95,
) -> MonteCarloResult:
    """Run the sampled Kalman filter on ``runs`` realisations along ``positions`` (module notes, step 2-3).

    Parameters
    ----------
    problem : Problem
    times : ndarray, shape (K,)
        Uniform sample times (T), ``times[0] = t0`` where ``P = Σ0``.
    positions : ndarray, shape (K, N, 2)
        Flown sensor positions at those times (L).
    predicted : ndarray, shape (K, n, n)
        The optimiser's ``Σ(t_k)``.
    runs : int
    rng : numpy.random.Generator
    confidence : float

    Returns
    -------
    MonteCarloResult
    """
    from scipy.stats import chi2

    mats = problem.matrices()
    n, dt = problem.n, float(times[1] - times[0])
    F, Qd = discretise_process(mats["A"], mats["BQB"], dt)
    C = measurement_matrices(problem, positions)  # (K, m, n): a point sensor's row follows its flown position
    R = measurement_variances(problem, positions) / dt  # ν_k ~ N(0, R(p_k)/Δt)
    L_Q, L_0 = np.linalg.cholesky(Qd + 1e-300 * np.eye(n)), np.linalg.cholesky(mats["Sigma0"])
    x_true = L_0 @ rng.standard_normal((runs, n, 1))  # x_0 ~ N(0, Σ0)
    x_hat, P = np.zeros((runs, n, 1)), mats["Sigma0"]
    errors, covariances = [x_hat - x_true], [P]
    for k in range(1, len(times)):
        raise_if_interrupted()  # a Ctrl-C that arrived inside CasADi code was only recorded
        x_true = F @ x_true + L_Q @ rng.standard_normal((runs, n, 1))
        y = C[k] @ x_true + np.sqrt(R[k])[:, None] * rng.standard_normal((runs, len(R[k]), 1))
        x_hat, P = kalman.predict(x_hat, P, F, Qd)  # docs/theory/cooperative.md, eq. cooperative.6 (same kernels)
        x_hat, P, _, _ = kalman.update(x_hat, P, y, C[k], np.diag(R[k]))  # Joseph form
        P = kalman.symmetrize(P)
        errors.append(x_hat - x_true)
        covariances.append(P)
    e = np.stack(errors, axis=1)[..., 0]  # (B, K, n)
    P_all = np.stack(covariances)
    dof = n * runs
    band = (
        float(chi2.ppf((1 - confidence) / 2, dof) / runs),
        float(chi2.ppf((1 + confidence) / 2, dof) / runs),
    )
    return MonteCarloResult(
        t=np.asarray(times, float), predicted=predicted, filter_covariance=P_all,
        empirical=np.einsum("bki,bkj->kij", e, e) / runs, nees_predicted=_nees(e, predicted),
        nees_filter=_nees(e, P_all), band=band, runs=runs,
    )  # fmt: skip


def predicted_covariance(solution: Solution, times: np.ndarray) -> np.ndarray:
    """The optimiser's ``Σ(t)`` at ``times`` (PCHIP through its state grid: no overshoot), ``(K, n, n)``."""
    from scipy.interpolate import PchipInterpolator

    Sigma = PchipInterpolator(solution.t, solution.Sigma, axis=0)(times)
    return 0.5 * (Sigma + np.swapaxes(Sigma, -1, -2))


# ------------------------------------------------------------------------------------------ together
def replay_solution(
    scenario: OcpReplayScenario, solution: Solution, seed: int | None = None, source: str = ""
) -> tuple[Any, dict[str, Any]]:
    """Track the solution's paths and validate its covariance by Monte Carlo.

    Gains too fast to integrate over the plan raise ``ConfigError`` naming ``source`` (the scenario file)
    before anything runs (:meth:`TrackingGains.check_horizon`).

    Returns
    -------
    dataset : xarray.Dataset
        ``r, v, r_ref, v_ref (time, sensor, xy)``, ``tracking_error (time, sensor)``,
        ``Sigma_predicted, P_filter, covariance_empirical (time, row, col)``,
        ``nees_predicted, nees_filter (time)``; the band and options as attributes.
    summary : dict
        Tracking errors, NEES statistics, promised vs delivered terminal cost.
    """
    import xarray as xr

    from ...core.errors import ConfigError

    problem = solution.problem
    if solution.Sigma is None:  # a field solution written with solver.shooting.full_sigma: false
        raise ConfigError(
            f"solution of {problem.name!r}: Sigma: expected the full error covariance Σ(t), which the Monte Carlo "
            "validation compares against, got a solution written without it (solve it again with "
            "solver.shooting.full_sigma: true)"
        )
    t0, tf = problem.horizon.t0, problem.horizon.tf
    mc = scenario.monte_carlo
    steps = max(1, int(round((tf - t0) / mc.time_step)))
    times = np.linspace(t0, tf, steps + 1)
    scenario.tracking.check_horizon(tf - t0, source)
    reference = ReferenceTrajectory.from_solution(solution)
    offset = None if scenario.initial_offset is None else np.asarray(scenario.initial_offset, float)
    r, v = simulate_tracking(reference, scenario.tracking.build(), times, scenario.platforms.build(), offset)
    p_ref, v_ref, _ = reference(times)
    error = np.linalg.norm(r - p_ref, axis=-1)
    rng = np.random.default_rng(scenario.seed if seed is None else seed)
    result = monte_carlo_filter(
        problem, times, r, predicted_covariance(solution, times), mc.runs, rng, mc.confidence
    )
    M = problem.matrices()["M"]
    promised, delivered = float(np.trace(M @ result.predicted[-1])), float(np.trace(M @ result.empirical[-1]))
    names = [s.name for s in problem.sensors]
    pos, cov = ("time", "sensor", "xy"), ("time", "row", "col")
    us = problem.units.system()
    L, LT, X2 = us.of(length=1), us.of(length=1, time=-1), us.of(state=2)
    ds = xr.Dataset(
        {
            "r": (pos, r, {"long_name": "flown sensor position", "units": L}),
            "v": (pos, v, {"long_name": "flown sensor velocity", "units": LT}),
            "r_ref": (pos, p_ref, {"long_name": "optimised (planned) sensor position", "units": L}),
            "v_ref": (pos, v_ref, {"long_name": "optimised (planned) sensor velocity", "units": LT}),
            "tracking_error": (("time", "sensor"), error,
                               {"long_name": "distance of the flown from the planned position", "units": L}),
            "Sigma_predicted": (cov, result.predicted,
                                {"long_name": "error covariance promised by the optimiser, Σ(t)", "units": X2}),
            "P_filter": (cov, result.filter_covariance,
                         {"long_name": "covariance P(+) of the sampled Kalman filter", "units": X2}),
            "covariance_empirical": (cov, result.empirical,
                                     {"long_name": "Monte Carlo error covariance E[e e']", "units": X2}),
            "nees_predicted": ("time", result.nees_predicted,
                               {"long_name": "NEES against Σ(t), averaged over the runs", "units": "1"}),
            "nees_filter": ("time", result.nees_filter,
                            {"long_name": "NEES against the filter's P, averaged over the runs", "units": "1"}),
        },
        coords={"time": ("time", times, {"long_name": "time of the filter samples", "units": us.of(time=1)}),
                "sensor": ("sensor", names, {"long_name": "sensor name"}),
                "xy": ("xy", ["x", "y"], {"long_name": "planar component"}),
                "row": ("row", np.arange(problem.n), {"long_name": "row index (process state)", "units": "1"}),
                "col": ("col", np.arange(problem.n), {"long_name": "column index (process state)", "units": "1"})},
        attrs={"title": f"mobisense: plan replay of problem '{problem.name}'",
               "band_low": result.band[0], "band_high": result.band[1], "runs": mc.runs,
               "confidence": mc.confidence, "time_step": float(times[1] - times[0]), "problem": problem.name,
               "length_unit": problem.units.length, "time_unit": problem.units.time},
    )  # fmt: skip
    relative = np.abs(
        np.trace(result.filter_covariance, axis1=1, axis2=2) / np.trace(result.predicted, axis1=1, axis2=2)
        - 1
    )
    summary = {
        "kind": "ocp",
        "problem": problem.name,
        "tracking_error_max": float(error.max()),
        "tracking_error_rms": float(np.sqrt(np.mean(error**2))),
        "tracking_error_final": float(error[-1].max()),
        "monte_carlo": {
            "runs": mc.runs,
            "time_step": float(times[1] - times[0]),
            "confidence": mc.confidence,
            "nees_band": list(result.band),
            "nees_predicted_mean": float(result.nees_predicted[1:].mean()),
            "nees_filter_mean": float(result.nees_filter[1:].mean()),
            "fraction_inside_band_predicted": result.fraction_inside("predicted"),
            "fraction_inside_band_filter": result.fraction_inside("filter"),
            "max_relative_trace_difference_filter_vs_predicted": float(relative.max()),
            "terminal_cost_promised": promised,
            "terminal_cost_delivered": delivered,
            "terminal_cost_filter": float(np.trace(M @ result.filter_covariance[-1])),
        },
    }
    return ds, summary


def resolve(scenario_path: Path, relative: str | None) -> Path | None:
    """A path of the scenario file, relative to the scenario's folder.

    A shipped example run by name (``mobisense replay replay_hussein2008``) lives in the installed package, where
    its ``solution: ../out/hussein2008/solution.nc`` never is: when that path does not exist, the same path taken
    as if the example were in ``./problems/`` (where ``mobisense examples --copy problems`` puts it) is used if it
    exists — ``out/hussein2008/solution.nc``, where ``mobisense solve hussein2008`` writes by default.
    """
    if relative is None:
        return None
    path = scenario_path.parent / relative
    if path.exists() or Path(relative).is_absolute():
        return path
    from ...core.examples import examples_folder

    try:
        shipped = scenario_path.resolve().parent == examples_folder().resolve()
    except OSError:
        shipped = False
    mirrored = Path(os.path.normpath(Path("problems") / relative))
    return mirrored if shipped and mirrored.exists() else path
