"""The check of a field (shooting) solution: its controls re-integrated by scipy, independently of the shooting.

The shooting method's J comes from ``m`` Möbius-RK4 substeps per interval in whitened coordinates
(:mod:`mobisense.ocp.shooting`, order 4). :func:`check_field_plan` integrates the same plan — the
piecewise-linear controls at the solution's nodes, the sensors' double integrators and the Riccati equation
``Σ' = AΣ + ΣA' + BQB' − Σ W(p)' R⁻¹ W(p) Σ`` with the kriging rows ``W(p)`` of the point sensors
(docs/theory/field.md, eqs. field.2–field.4) — in numpy with scipy's DOP853, interval by interval (the
controls have a kink at every node), and returns the J it finds: what ``plan_check`` of ``summary.json``
reports for every ``solve``, as for a direct solution (:mod:`mobisense.ocp.direct.plan_check`).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

__all__ = ["check_field_plan", "plan_covariances", "FIELD_CHECK_RTOL"]

#: relative tolerance of DOP853 (absolute: this times the largest prior variance); its own error on the
#: 5 × 5 example is below 1e-11 relative (the same plan at rtol 1e-12 changes J by less)
FIELD_CHECK_RTOL = 1e-10


def check_field_plan(solution: Any, rtol: float = FIELD_CHECK_RTOL) -> dict[str, Any]:
    """Re-integrate a shooting solution's controls; ``{cost, relative_difference, integrator, time_s}``.

    ``relative_difference`` = (shooting J − re-integrated J) / |re-integrated J|; ``cost`` None (and
    ``integrator`` the reason) when the integration failed.
    """
    report, _ = _integrate(solution, rtol)
    return report


def plan_covariances(solution: Any, rtol: float = FIELD_CHECK_RTOL) -> np.ndarray:
    """Σ(t) of a shooting solution's plan at its nodes ``solution.t``, re-integrated, shape (T, n, n) (state²).

    For a solution that keeps diag Σ only (a field of more than 25 states, ``solver.shooting.full_sigma``):
    the same integration as :func:`check_field_plan`. ``RuntimeError`` with the integrator's message when it fails.
    """
    report, Sigma = _integrate(solution, rtol, keep=True)
    if report["cost"] is None:
        raise RuntimeError(report["integrator"])
    return Sigma


def _integrate(solution: Any, rtol: float, keep: bool = False) -> tuple[dict[str, Any], np.ndarray | None]:
    """The plan check's report, and Σ at every node when ``keep`` (else None)."""
    from scipy.integrate import solve_ivp

    problem = solution.problem
    field = problem.process.field.process()
    mats = problem.matrices()
    A, BQB, M, Kw = mats["A"], mats["BQB"], mats["M"], mats["K"]
    n, N, alpha = problem.n, problem.N, problem.cost.alpha
    inverse_r = np.array([1.0 / s.noise.parameters()[0] for s in problem.sensors])  # point sensors: constant
    t_u = np.asarray(solution.t_u, float)
    u_nodes = np.asarray(solution.u, float).reshape(len(t_u), N, 2)
    nn = n * n

    def rhs(t: float, y: np.ndarray, k: int) -> np.ndarray:
        Sigma = y[:nn].reshape(n, n)
        p = y[nn : nn + 2 * N].reshape(N, 2)
        v = y[nn + 2 * N : nn + 4 * N]
        s = (t - t_u[k]) / (t_u[k + 1] - t_u[k])
        u = (1.0 - s) * u_nodes[k] + s * u_nodes[k + 1]  # piecewise linear, as the shooting's controls
        SW = Sigma @ field.weights(p).T  # (n, N)
        dSigma = A @ Sigma + Sigma @ A.T + BQB - (SW * inverse_r) @ SW.T  # docs/theory/field.md, eq. field.4
        running = 0.5 * alpha * float(np.sum(u * u)) + float(np.sum(Kw * Sigma))
        return np.concatenate([dSigma.ravel(), v, u.ravel(), [running]])

    y = np.concatenate([mats["Sigma0"].ravel(), np.ravel([s.p0 for s in problem.sensors]),
                        np.ravel([s.v0 for s in problem.sensors]), [0.0]])  # fmt: skip
    atol = np.concatenate([np.full(nn, rtol * float(np.max(np.diag(mats["Sigma0"])))), np.full(4 * N + 1, rtol)])
    t0 = time.perf_counter()
    Sigma = np.empty((len(t_u), n, n)) if keep else None
    if Sigma is not None:
        Sigma[0] = mats["Sigma0"]
    for k in range(len(t_u) - 1):
        step = solve_ivp(rhs, (t_u[k], t_u[k + 1]), y, method="DOP853", rtol=rtol, atol=atol, args=(k,))
        if not step.success or not np.all(np.isfinite(step.y[:, -1])):
            failure = f"DOP853 failed on [{t_u[k]:.4g}, {t_u[k + 1]:.4g}]: {step.message}"
            return {"cost": None, "relative_difference": None, "time_s": time.perf_counter() - t0,
                    "integrator": failure}, None  # fmt: skip
        y = step.y[:, -1]
        if Sigma is not None:
            Sigma[k + 1] = 0.5 * (y[:nn].reshape(n, n) + y[:nn].reshape(n, n).T)
    cost = float(np.sum(M * y[:nn].reshape(n, n))) + float(y[-1])
    difference = (solution.cost - cost) / abs(cost) if cost else None
    return {"cost": cost, "relative_difference": difference, "integrator": f"DOP853 (scipy, rtol {rtol:g})",
            "time_s": time.perf_counter() - t0}, Sigma  # fmt: skip
