"""Integrate the sensor + Riccati dynamics for a given control with ``solve_ivp`` (independent of the NLP).

Used for the ε → 0 initial guess (coasting sensors, u ≡ 0: the classical Kalman filter), for the
no-control baseline cost, and to re-simulate an optimised control as an independent check.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Callable
from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.integrate import solve_ivp

from .model import SensorKalmanModel

__all__ = ["Trajectory", "integrate", "coast"]


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
def _coasting_integrator(model: SensorKalmanModel, grid: tuple[float, ...], rtol: float) -> ca.Function:
    """CVODES integrator of the scaled coasting dynamics over normalised time τ ∈ [0, 1] (output at ``grid``)."""
    s = model.structure
    xs = ca.SX.sym("x_scaled", s.nx)
    P = ca.SX.sym("P", model.layout.size)
    b = model.layout.unpack(P)
    horizon = b["tf"] - b["t0"]
    x_scale, _ = model.scales(P)
    u = ca.SX.zeros(s.nu)
    x = xs * x_scale
    dae = {
        "x": xs,
        "p": P,
        "ode": horizon * model.f(x, u, P) / x_scale,
        "quad": horizon * model.running(x, u, P),
    }
    options = {"abstol": rtol, "reltol": rtol, "disable_internal_warnings": True}
    return ca.integrator("coasting", "cvodes", dae, 0.0, list(grid), options)


def coast(model: SensorKalmanModel, P: np.ndarray, t_eval: np.ndarray, rtol: float = 1e-13) -> Trajectory:
    """The coasting (u ≡ 0) solution — the classical Kalman filter — with CasADi's CVODES, at ``t_eval``.

    Same result as ``integrate(model, P, t_eval)`` (BDF at rtol 1e-13: cost within 2e-10 of DOP853 at 1e-13,
    tested) but in compiled code: it runs for every
    solve (initial guess, baseline cost), so it must be cheap. ``t_eval`` must start at t0 and end at tf.
    """
    b = model.layout.unpack(np.asarray(P, float))
    t0, tf = float(b["t0"][0]), float(b["tf"][0])
    grid = tuple(float(v) for v in (np.asarray(t_eval, float)[1:] - t0) / (tf - t0))
    x_scale = np.asarray(model.scales(P)[0]).ravel()
    x0 = np.asarray(model.x0(P)).ravel()
    try:
        out = _coasting_integrator(model, grid, rtol)(x0=x0 / x_scale, p=P)
    except RuntimeError as exc:
        status = re.search(r'CVode returned "(\w+)"', str(exc))
        raise RuntimeError(
            f"integrating the no-control Riccati equation failed (CVODES {status.group(1) if status else 'error'}): "
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
