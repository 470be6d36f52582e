"""Formation shape design (docs/theory/steady_state.md §3, §5): minimise the filter covariance over the cross's (a, b).

* :func:`design_cross_formation` — minimise ``tr P∞(a, b)`` (closed form, CasADi derivatives) within
  bounds ``[d_min, d_max]`` or along ``a = b``;
* :func:`adaptive_shape_step` — step (3A) of docs/theory/steady_state.md §5 (eq. steady_state.7): choose ``(a, b)``
  at step k to minimise ``J_k = ½ tr[(I − K C) P(−) (I − K C)' + K (D U D' + R) K']`` with the Kalman gain ``K(C, D)``;
* :func:`minimise_shape` — the bounded two-variable minimiser both use, returning a :class:`ShapeDesign`
  that states whether the optimum is an interior ``minimum``, a ``saddle`` or on a ``boundary``.

The pitfall of docs/theory/steady_state.md §3: ``tr P∞`` often keeps decreasing as one of ``a, b → ∞`` and its symmetric
stationary point is a saddle, so an unbounded search has no answer; :func:`minimise_shape` starts from a
grid (multi-start L-BFGS-B with the exact gradient), polishes the best point by Newton's method on the
free variables with the exact Hessian, and classifies it from the active bounds and the eigenvalues of
the full 2 × 2 Hessian (an ``a = b`` optimum whose 2-D Hessian is indefinite is reported as a saddle).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.optimize import OptimizeResult

from .noise_config import CooperativeNoise
from .steady_state import cross_steady_state, cross_trace_function

__all__ = ["ShapeDesign", "minimise_shape", "design_cross_formation", "adaptive_shape_step", "cross_taylor_symbolic"]

Objective = Callable[[np.ndarray], tuple[float, np.ndarray, np.ndarray]]


class ShapeDesign(OptimizeResult):
    """Result of :func:`minimise_shape` (a ``scipy.optimize.OptimizeResult``).

    Attributes
    ----------
    x : ndarray, shape (2,)
        Optimal ``(a, b)`` (L).
    fun : float
        Objective there.
    jac : ndarray, shape (2,)
        Gradient there.
    hess : ndarray, shape (2, 2)
        Full Hessian there.
    hess_eigenvalues : ndarray, shape (2,)
    on_bound : dict
        ``{"a": "lower" | "upper" | None, "b": …}``, the active bounds.
    stationary_point : {"minimum", "saddle", "boundary"}
    success : bool
    message : str
    """


def _classify(x: np.ndarray, g: np.ndarray, H: np.ndarray, bounds: np.ndarray, equal: bool) -> tuple[dict, str, str]:
    names = ("a", "b")
    scale = np.maximum(1.0, bounds[:, 1] - bounds[:, 0])
    on_bound: dict[str, str | None] = {}
    for i, name in enumerate(names):
        at_lo = x[i] <= bounds[i, 0] + 1e-9 * scale[i]
        at_hi = x[i] >= bounds[i, 1] - 1e-9 * scale[i]
        on_bound[name] = "lower" if at_lo else "upper" if at_hi else None
    eig = np.linalg.eigvalsh(H)
    if any(v is not None for v in on_bound.values()):
        where = ", ".join(f"{k} at its {v} bound" for k, v in on_bound.items() if v)
        return (
            on_bound,
            "boundary",
            f"optimum on the boundary ({where}); the unconstrained problem may decrease beyond it",
        )
    if np.all(eig > 0):
        return on_bound, "minimum", "interior minimum (gradient zero, Hessian positive definite)"
    constraint = " along a = b" if equal else ""
    return (
        on_bound,
        "saddle",
        f"stationary point{constraint} is a saddle of tr P(a, b) (Hessian eigenvalues {eig[0]:.3g}, {eig[1]:.3g}): "
        "free a, b would do better",
    )


def _newton_polish(f: Objective, x: np.ndarray, bounds: np.ndarray, equal: bool, iterations: int = 30) -> np.ndarray:
    """Newton steps on the free variables (active bounds held) until the gradient is at round-off level."""
    for _ in range(iterations):
        value, g, H = f(x)
        if equal:  # along a = b: t ↦ f(t, t)
            g_red, H_red = np.array([g.sum()]), np.array([[H.sum()]])
            free = np.array([bounds[0, 0] < x[0] < bounds[0, 1]])
            expand = np.ones((2, 1))
        else:
            free = (x > bounds[:, 0]) & (x < bounds[:, 1])
            free |= ((x <= bounds[:, 0]) & (g < 0)) | ((x >= bounds[:, 1]) & (g > 0))
            g_red, H_red, expand = g, H, np.eye(2)
        if not free.any():
            break
        idx = np.flatnonzero(free)
        Hf = H_red[np.ix_(idx, idx)]
        if np.any(np.linalg.eigvalsh(Hf) <= 0):
            break  # not locally convex on the free set: keep the L-BFGS-B point
        step = np.zeros(len(g_red))
        step[idx] = -np.linalg.solve(Hf, g_red[idx])
        dx = expand @ step
        t = 1.0
        while t > 1e-6:
            trial = np.clip(x + t * dx, bounds[:, 0], bounds[:, 1])
            if f(trial)[0] <= value:
                break
            t *= 0.5
        if np.max(np.abs(trial - x)) <= 1e-15 * max(1.0, np.max(np.abs(x))):
            x = trial
            break
        x = trial
    return x


def minimise_shape(
    objective: Objective,
    bounds: tuple[tuple[float, float], tuple[float, float]],
    equal_sides: bool = False,
    starts: int = 7,
) -> ShapeDesign:
    """Minimise a smooth function of ``(a, b)`` within bounds, and classify the optimum.

    Parameters
    ----------
    objective : callable
        ``x (2,) → (f, ∇f (2,), ∇²f (2, 2))``.
    bounds : ((a_min, a_max), (b_min, b_max))
        Finite positive bounds (L).
    equal_sides : bool
        Constrain ``a = b`` (uses the intersection of the two bounds).
    starts : int
        Grid points per axis for the multi-start.

    Returns
    -------
    ShapeDesign
    """
    from scipy.optimize import minimize

    B = np.asarray(bounds, dtype=float)
    if B.shape != (2, 2) or np.any(B[:, 0] > B[:, 1]) or not np.all(np.isfinite(B)):
        raise ValueError(f"bounds: expected ((a_min, a_max), (b_min, b_max)) finite with min <= max, got {bounds}")
    if equal_sides:
        lo, hi = max(B[0, 0], B[1, 0]), min(B[0, 1], B[1, 1])
        if lo > hi:
            raise ValueError(f"bounds: a = b needs overlapping ranges, got {bounds}")
        B = np.array([[lo, hi], [lo, hi]])

        def fun1(t: np.ndarray) -> tuple[float, np.ndarray]:
            value, g, _ = objective(np.array([t[0], t[0]]))
            return value, np.array([g.sum()])

        cands = [
            minimize(fun1, [t], jac=True, method="L-BFGS-B", bounds=[(lo, hi)]) for t in np.linspace(lo, hi, starts)
        ]
        cands = [np.array([c.x[0], c.x[0]]) for c in cands]
    else:
        grid = [np.linspace(B[i, 0], B[i, 1], starts) for i in range(2)]

        def fun2(x: np.ndarray) -> tuple[float, np.ndarray]:
            value, g, _ = objective(x)
            return value, g

        cands = [
            minimize(fun2, [a, b], jac=True, method="L-BFGS-B", bounds=list(map(tuple, B))).x
            for a in grid[0]
            for b in grid[1]
        ]
    values = [objective(c)[0] for c in cands]
    x = _newton_polish(objective, cands[int(np.argmin(values))], B, equal_sides)
    f, g, H = objective(x)
    on_bound, kind, message = _classify(x, g, H, B, equal_sides)
    return ShapeDesign(
        x=x, fun=float(f), jac=g, hess=H, hess_eigenvalues=np.linalg.eigvalsh(H), on_bound=on_bound,
        stationary_point=kind, success=True, message=message, bounds=B, equal_sides=equal_sides,
    )  # fmt: skip


def design_cross_formation(
    sigma_process: float,
    sigma_measurement: float,
    sigma_hessian: float,
    bounds: tuple[tuple[float, float], tuple[float, float]],
    equal_sides: bool = False,
) -> ShapeDesign:
    """Cross formation ``(a, b)`` minimising ``tr P∞`` (docs/theory/steady_state.md §2–§3) within bounds.

    The result also carries ``steady_state`` (:class:`~mobisense.estimation.cooperative.steady_state.SteadyState` at the
    optimum: ``P∞`` diagonal, gain ``K∞``).

    Raises
    ------
    RuntimeError
        When ``tr P∞`` or the optimum is not finite: noise levels so far apart (e.g. ``σ1 = 1e-90``,
        ``σ2 = 1e90``) that the closed form over- or underflows.
    """
    f = cross_trace_function()
    sigmas = [sigma_process, sigma_measurement, sigma_hessian]

    def objective(x: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        value, g, H = f(x, sigmas)
        return float(value), np.asarray(g).ravel(), np.asarray(H)

    design = minimise_shape(objective, bounds, equal_sides)
    if not (np.all(np.isfinite(design.x)) and np.isfinite(design.fun)):
        raise RuntimeError(
            f"the steady state is not finite (tr P = {design.fun:g} at a, b = {design.x[0]:g}, {design.x[1]:g}): the "
            "noise levels make the Riccati equation degenerate"
        )
    design.steady_state = cross_steady_state(design.x[0], design.x[1], *sigmas)
    return design


def cross_taylor_symbolic(a: Any, b: Any, orientation: Any) -> tuple[Any, Any]:
    """CasADi ``C (4×3)``, ``D (4×4)`` of the cross rotated by ``orientation`` (eq. cooperative.2).

    Same rows as :func:`mobisense.estimation.cooperative.information_model.taylor_matrices` of
    :func:`~mobisense.estimation.cooperative.information_model.cross_formation` (tested), as expressions of ``a, b``.
    """
    import casadi as ca

    c, s = ca.cos(orientation), ca.sin(orientation)
    body = [(-a, 0), (a, 0), (0, b), (0, -b)]
    rows_C, rows_D = [], []
    for bx, by in body:
        x, y = c * bx - s * by, s * bx + c * by  # r_i − r_c = R(θ) body_i
        rows_C.append(ca.horzcat(1, x, y))  # docs/theory/cooperative.md, eq. cooperative.2
        rows_D.append(0.5 * ca.horzcat(x * x, x * y, y * x, y * y))  # docs/theory/cooperative.md, eq. cooperative.2
    return ca.vertcat(*rows_C), ca.vertcat(*rows_D)


@functools.lru_cache(maxsize=1)
def _adaptive_objective() -> Any:
    import casadi as ca

    x = ca.SX.sym("x", 2)
    P = ca.SX.sym("P", 3, 3)
    R = ca.SX.sym("R", 4, 4)
    U = ca.SX.sym("U", 4, 4)
    theta = ca.SX.sym("theta")
    C, D = cross_taylor_symbolic(x[0], x[1], theta)
    R_total = D @ U @ D.T + R
    K = ca.solve(C @ P @ C.T + R_total, C @ P).T  # K(C, D), docs/theory/cooperative.md, eq. cooperative.7
    I_KC = ca.SX.eye(3) - K @ C
    J = 0.5 * ca.trace(I_KC @ P @ I_KC.T + K @ R_total @ K.T)  # docs/theory/steady_state.md, eq. steady_state.7
    H, g = ca.hessian(J, x)
    return ca.Function("adaptive_J", [x, P, R, U, theta], [J, g, H])


def adaptive_shape_step(
    prior_covariance: np.ndarray,
    noise: CooperativeNoise,
    bounds: tuple[tuple[float, float], tuple[float, float]],
    orientation: float = 0.0,
    equal_sides: bool = False,
) -> ShapeDesign:
    """Step (3A) of docs/theory/steady_state.md §5: the cross shape minimising ``J_k`` given ``P_k(−)``.

    Parameters
    ----------
    prior_covariance : ndarray, shape (3, 3)
        ``P_k(−)`` of the cooperative filter.
    noise : CooperativeNoise
        ``R`` and ``U`` (``M`` does not enter ``J_k``).
    bounds : ((a_min, a_max), (b_min, b_max))
    orientation : float
        Angle of the cross's e1 axis from the lab x axis (rad).
    equal_sides : bool

    Returns
    -------
    ShapeDesign
        ``fun = J_k`` at the optimum (``½ tr P_k(+)``).
    """
    f = _adaptive_objective()
    args = (np.asarray(prior_covariance, float), noise.measurement_matrix(4), noise.hessian_error, float(orientation))

    def objective(x: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        value, g, H = f(x, *args)
        return float(value), np.asarray(g).ravel(), np.asarray(H)

    return minimise_shape(objective, bounds, equal_sides, starts=5)
