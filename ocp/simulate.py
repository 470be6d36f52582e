"""Integrate the sensor + Riccati dynamics for a given control (independent of the NLP).

:func:`integrate` (scipy's DOP853, any control) re-simulates an optimised control as an independent check;
:func:`coast` (u ≡ 0: the classical Kalman filter; the ε → 0 initial guess and the no-control baseline) and
:func:`sine_controlled` (the random smooth controls of multi-start guesses) and :func:`resimulate_plan` (a direct
solution's controls, re-integrated interval by interval: the check of its J) run CasADi's CVODES in compiled
code, one integrator per model and output grid, built once per process.
"""

from __future__ import annotations

import collections
import functools
import re
from collections.abc import Callable
from dataclasses import dataclass

import casadi as ca
import numpy as np

from .model import SensorKalmanModel

__all__ = ["Trajectory", "integrate", "coast", "sine_controlled", "resimulate_plan"]


@dataclass
class Trajectory:
    """States ``x`` (len(t), nx) at times ``t``; cost pieces of J at ε = 1."""

    t: np.ndarray
    x: np.ndarray
    terminal_cost: float
    running_cost: float
    control_energy: float

    @property
    def cost(self) -> float:
        """J = Tr[M Σ(tf)] + ∫ (α/2|u|² + Tr KΣ) dt."""
        return self.terminal_cost + self.running_cost


def integrate(
    model: SensorKalmanModel,
    P: np.ndarray,
    t_eval: np.ndarray,
    control: Callable[[float], np.ndarray] | None = None,
    rtol: float = 1e-11,
) -> Trajectory:
    """Integrate ``x' = f(x, u(t))`` from the initial state in ``P`` over ``[t_eval[0], t_eval[-1]]``.

    Parameters
    ----------
    model : SensorKalmanModel
    P : ndarray, shape (n_parameters,)
        Packed parameters (see :class:`mobisense.ocp.model.ParameterLayout`).
    t_eval : ndarray, shape (T,)
        Output times (T); the first and last define the horizon.
    control : callable, optional
        ``u(t)`` -> (2N,) (L/T²); ``None`` means coasting (u ≡ 0).
    rtol : float
        Relative tolerance of the DOP853 integrator (absolute tolerance scaled per state).

    Returns
    -------
    Trajectory
    """
    from scipy.integrate import solve_ivp

    nx, nu = model.structure.nx, model.structure.nu
    x_scale = np.asarray(model.scales(P)[0]).ravel()
    f = model.f
    running = model.running
    zero = np.zeros(nu)

    def rhs(t: float, y: np.ndarray) -> np.ndarray:
        u = zero if control is None else np.asarray(control(t), float)
        x = y[:nx]
        L = np.asarray(running(x, u, P)).ravel()
        return np.concatenate([np.asarray(f(x, u, P)).ravel(), L])

    y0 = np.concatenate([np.asarray(model.x0(P)).ravel(), [0.0, 0.0]])
    atol = np.concatenate([rtol * x_scale, [rtol, rtol]])
    sol = solve_ivp(rhs, (t_eval[0], t_eval[-1]), y0, method="DOP853", t_eval=t_eval, rtol=rtol, atol=atol)
    if not sol.success:
        raise RuntimeError(f"integration of the sensor/Riccati dynamics failed: {sol.message}")
    x = sol.y[:nx].T
    phi = float(model.terminal(x[-1], P))
    return Trajectory(
        t=np.asarray(t_eval, float),
        x=x,
        terminal_cost=phi,
        running_cost=float(sol.y[nx, -1]),
        control_energy=float(sol.y[nx + 1, -1]),
    )


@functools.lru_cache(maxsize=32)
def _integrator(model: SensorKalmanModel, grid: tuple[float, ...], rtol: float, modes: int) -> ca.Function:
    """CVODES integrator of the scaled dynamics over normalised time τ ∈ [0, 1] (output at ``grid``).

    The control is ``u(τ) = Σ_m a_m sin(mπτ + φ_m)``, m = 1 … ``modes`` (none: coasting); the integrator's
    parameter is ``[P; vec(a); vec(φ)]`` with a, φ of shape (modes, nu) flattened row-major.
    """
    s = model.structure
    xs = ca.SX.sym("x_scaled", s.nx)
    tau = ca.SX.sym("tau")
    P = ca.SX.sym("P", model.layout.size)
    a = ca.SX.sym("a", modes * s.nu)
    phase = ca.SX.sym("phase", modes * s.nu)
    b = model.layout.unpack(P)
    horizon = b["tf"] - b["t0"]
    x_scale, _ = model.scales(P)
    u = ca.SX.zeros(s.nu)
    for m in range(modes):
        u += a[m * s.nu : (m + 1) * s.nu] * ca.sin((m + 1) * np.pi * tau + phase[m * s.nu : (m + 1) * s.nu])
    x = xs * x_scale
    dae = {
        "x": xs,
        "t": tau,
        "p": ca.vertcat(P, a, phase),
        "ode": horizon * model.f(x, u, P) / x_scale,
        "quad": horizon * model.running(x, u, P),
    }
    options = {"abstol": rtol, "reltol": rtol, "disable_internal_warnings": True}
    return ca.integrator("sensor_riccati", "cvodes", dae, 0.0, list(grid), options)


def _run(
    model: SensorKalmanModel, P: np.ndarray, t_eval: np.ndarray, rtol: float, a: np.ndarray, phase: np.ndarray
) -> Trajectory:
    b = model.layout.unpack(np.asarray(P, float))
    t0, tf = float(b["t0"][0]), float(b["tf"][0])
    grid = tuple(float(v) for v in (np.asarray(t_eval, float)[1:] - t0) / (tf - t0))
    x_scale = np.asarray(model.scales(P)[0]).ravel()
    x0 = np.asarray(model.x0(P)).ravel()
    F = _integrator(model, grid, rtol, a.shape[0])
    try:
        out = F(x0=x0 / x_scale, p=np.concatenate([P, a.ravel(), phase.ravel()]))
    except RuntimeError as exc:
        raise RuntimeError(
            f"integrating the Riccati equation failed (CVODES {_cvodes_status(exc)}): "
            "the covariance dynamics are too stiff or their numbers too extreme; rescale the problem"
        ) from None
    x = np.vstack([x0, np.asarray(out["xf"]).T * x_scale])
    q = np.asarray(out["qf"])[:, -1]
    return Trajectory(
        t=np.asarray(t_eval, float),
        x=x,
        terminal_cost=float(model.terminal(x[-1], P)),
        running_cost=float(q[0]),
        control_energy=float(q[1]),
    )


#: coasting solutions kept per process (a sweep over α re-solves the same coasting problem for every task)
COAST_CACHE_SIZE = 16
_coasted: collections.OrderedDict[tuple, Trajectory] = collections.OrderedDict()


def coast(model: SensorKalmanModel, P: np.ndarray, t_eval: np.ndarray, rtol: float = 1e-13) -> Trajectory:
    """The coasting (u ≡ 0) solution — the classical Kalman filter — with CasADi's CVODES, at ``t_eval``.

    Same result as ``integrate(model, P, t_eval)`` (BDF at rtol 1e-13: cost within 2e-10 of DOP853 at 1e-13,
    tested) but in compiled code: it runs for every
    solve (initial guess, baseline cost), so it must be cheap. ``t_eval`` must start at t0 and end at tf.

    The last :data:`COAST_CACHE_SIZE` results are kept, keyed by the model, ``P`` without α, ``t_eval`` and
    ``rtol``: with u ≡ 0 the control weight α multiplies an exact zero, so tasks that differ only in α have
    bit-identical coasting solutions (tested), and a sweep over α integrates each once (≈ 4 ms of a 21 ms warm
    task on the default problem at K = 60). The returned arrays are read-only, as they are shared.
    """
    P = np.asarray(P, float)
    t_eval = np.asarray(t_eval, float)
    offset, _ = model.layout.offsets["alpha"]
    without_alpha = P.copy()
    without_alpha[offset] = 0.0
    key = (model, without_alpha.tobytes(), t_eval.tobytes(), float(rtol))
    if key in _coasted:
        _coasted.move_to_end(key)
        return _coasted[key]
    nu = model.structure.nu
    trajectory = _run(model, P, t_eval, rtol, np.zeros((0, nu)), np.zeros((0, nu)))
    trajectory.t = np.array(t_eval)  # its own copy: _run keeps the caller's array
    for array in (trajectory.t, trajectory.x):
        array.setflags(write=False)
    _coasted[key] = trajectory
    if len(_coasted) > COAST_CACHE_SIZE:
        _coasted.popitem(last=False)
    return trajectory


def sine_controlled(
    model: SensorKalmanModel,
    P: np.ndarray,
    t_eval: np.ndarray,
    amplitudes: np.ndarray,
    phases: np.ndarray,
    rtol: float = 1e-10,
) -> Trajectory:
    """The trajectory of ``u(t) = Σ_m a_m sin(mπτ + φ_m)``, τ = (t − t0)/(tf − t0), with CVODES, at ``t_eval``.

    Parameters
    ----------
    amplitudes, phases : ndarray, shape (modes, nu)
        a_m (L/T²) and φ_m (rad) of each mode m = 1 … modes.
    """
    return _run(model, P, t_eval, rtol, np.asarray(amplitudes, float), np.asarray(phases, float))


@functools.lru_cache(maxsize=16)
def _plan_integrator(model: SensorKalmanModel, nodes: tuple[float, ...], intervals: int, steps: int) -> ca.Function:
    """The K intervals of a plan in one call (``mapaccum``): ``steps`` RK4 steps per interval, or CVODES (0).

    On an interval of length h, τ ∈ [0, 1], ``u(τ) = Σ_j ℓ_j(τ) U_j`` (ℓ_j the Lagrange basis through the d
    collocation ``nodes``); the parameter of interval k is ``[P; h; vec(U_k)]`` (U_k of shape (d, nu), row-major).
    Outputs: the scaled state at each interval's end (nx, K) and the two quadratures (running cost, control
    energy) of each interval (2, K).
    """
    s = model.structure
    d = len(nodes)
    xs = ca.SX.sym("x_scaled", s.nx)
    tau = ca.SX.sym("tau")
    P = ca.SX.sym("P", model.layout.size)
    h = ca.SX.sym("h")
    U = ca.SX.sym("U", d * s.nu)
    u = ca.SX.zeros(s.nu)
    for j in range(d):
        basis = 1.0
        for r in range(d):
            if r != j:
                basis = basis * (tau - nodes[r]) / (nodes[j] - nodes[r])
        u += basis * U[j * s.nu : (j + 1) * s.nu]
    x_scale, _ = model.scales(P)
    x = xs * x_scale
    dae = {"x": xs, "t": tau, "p": ca.vertcat(P, h, U), "ode": h * model.f(x, u, P) / x_scale,
           "quad": h * model.running(x, u, P)}  # fmt: skip
    quiet = {"show_eval_warnings": False}
    if steps:
        F = ca.integrator("plan_interval", "rk", dae, 0.0, 1.0, {**quiet, "number_of_finite_elements": steps})
    else:
        options = {**quiet, "abstol": 1e-11, "reltol": 1e-11, "disable_internal_warnings": True,
                   "quad_err_con": True}  # J is a quadrature: its error controls the steps too
        F = ca.integrator("plan_interval", "cvodes", dae, 0.0, 1.0, options)
    x0 = ca.MX.sym("x0", s.nx)
    pk = ca.MX.sym("p", model.layout.size + 1 + d * s.nu)
    out = F(x0=x0, p=pk)
    step = ca.Function("plan_step", [x0, pk], [out["xf"], out["qf"]])
    return step.mapaccum("plan", intervals)


#: RK4 steps per interval of the two explicit re-simulations (their Richardson extrapolation is the result) …
PLAN_STEPS = (4, 8)
#: … when they agree to this relative tolerance in J; else CVODES (rtol 1e-11: stiff or fast Σ within an interval)
PLAN_AGREEMENT = 1e-7


@dataclass
class PlanCheck:
    """A plan's J re-integrated independently of the collocation (:func:`resimulate_plan`).

    Attributes
    ----------
    trajectory : Trajectory
        States at the K + 1 interval boundaries and J's parts.
    integrator : str
        ``"RK4 (4, 8 steps per interval, extrapolated)"`` or ``"CVODES"`` (when the explicit steps disagreed).
    """

    trajectory: Trajectory
    integrator: str


def resimulate_plan(
    model: SensorKalmanModel, P: np.ndarray, u: np.ndarray, nodes: np.ndarray, t0: float, tf: float
) -> PlanCheck:
    """The trajectory and J of a direct solution's controls, integrated independently of the collocation.

    Two explicit RK4 re-simulations (:data:`PLAN_STEPS` steps per interval), Richardson-extrapolated when they
    agree to :data:`PLAN_AGREEMENT` (error ≈ 1e-13 relative on the default problem, 6 ms at K = 100); else
    (a covariance that changes fast within an interval) CVODES at rtol 1e-11.

    Parameters
    ----------
    model : SensorKalmanModel
    P : ndarray, shape (n_parameters,)
        Packed parameters at ε = 1.
    u : ndarray, shape (K, d, nu)
        The control at each interval's d collocation points (L/T²); between them the Lagrange polynomials through
        them (what :meth:`mobisense.ocp.solution.Solution.sample` returns, and a replay flies).
    nodes : ndarray, shape (d,)
        The collocation points in (0, 1].
    t0, tf : float
        The horizon (T), cut into K equal intervals.

    Raises
    ------
    RuntimeError
        CVODES failed (the dynamics are too extreme to integrate).
    """
    K, d, nu = u.shape
    P = np.asarray(P, float)
    h = (tf - t0) / K
    x_scale = np.asarray(model.scales(P)[0]).ravel()
    x0 = np.asarray(model.x0(P)).ravel()
    parameters = np.vstack([np.repeat(P[:, None], K, axis=1), np.full((1, K), h), u.reshape(K, d * nu).T])
    key = tuple(float(v) for v in nodes)

    def run(steps: int) -> Trajectory:
        xf, q = _plan_integrator(model, key, K, steps)(x0 / x_scale, parameters)
        x = np.vstack([x0, np.asarray(xf).T * x_scale])
        q = np.asarray(q).sum(axis=1)
        return Trajectory(t0 + h * np.arange(K + 1), x, float(model.terminal(x[-1], P)), float(q[0]), float(q[1]))

    coarse, fine = (run(m) for m in PLAN_STEPS)
    if np.isfinite(fine.cost) and abs(fine.cost - coarse.cost) <= PLAN_AGREEMENT * abs(fine.cost):
        w = (PLAN_STEPS[1] / PLAN_STEPS[0]) ** 4  # RK4: error ∝ step⁴
        fine.terminal_cost = (w * fine.terminal_cost - coarse.terminal_cost) / (w - 1)
        fine.running_cost = (w * fine.running_cost - coarse.running_cost) / (w - 1)
        return PlanCheck(fine, f"RK4 ({PLAN_STEPS[0]} and {PLAN_STEPS[1]} steps per interval, extrapolated)")
    try:
        return PlanCheck(run(0), "CVODES")
    except RuntimeError as exc:
        raise RuntimeError(f"re-integrating the plan failed (CVODES {_cvodes_status(exc)})") from None


def _cvodes_status(exc: RuntimeError) -> str:
    """The CVODES return flag named in a CasADi integrator error (``CV_TOO_MUCH_WORK``, …), or ``error``."""
    status = re.search(r'CVode returned "(\w+)"', str(exc))
    return status.group(1) if status else "error"
