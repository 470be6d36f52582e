"""Shape controllers: errors follow the analytic solution of the linear second-order system.

Theory: docs/theory/formation_control.md §2–§3.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from mobisense.estimation.cooperative.information_model import rotation
from mobisense.formation.jacobi import JacobiTransform
from mobisense.formation.platforms import PlatformLimits
from mobisense.formation.shape_control import FixedShapeController, RotatingShapeController, perp, rotating_frame_state

# Integrations use rtol = atol = 1e-11 on O(1) states over a few time units: global errors ~1e-9;
# every comparison with a closed form below allows 1e-8.
TOL = 1e-8


def error_system(
    stiffness: float, damping: float, t: np.ndarray, e0: np.ndarray, de0: np.ndarray
) -> np.ndarray:
    """e(t) of e'' + K3 e' + K2 e = 0 by the matrix exponential (independent of the controller code)."""
    A = np.array([[0.0, 1.0], [-stiffness, -damping]])
    return np.array([np.tensordot(expm(A * tk), np.stack([e0, de0]), axes=1)[0] for tk in t])


def integrate_platforms(N, forces_of, y0, t, extra=0):
    def rhs(time, y):
        r, v = y[: 2 * N].reshape(N, 2), y[2 * N : 4 * N].reshape(N, 2)
        f, extra_rates = forces_of(time, r, v, y[4 * N :])
        return np.concatenate([v.ravel(), f.ravel(), extra_rates])

    sol = solve_ivp(rhs, (t[0], t[-1]), y0, t_eval=t, method="DOP853", rtol=1e-11, atol=1e-11)
    assert sol.success
    return sol.y.T


@pytest.mark.parametrize("stiffness,damping", [(4.0, 1.0), (1.0, 5.0)], ids=["underdamped", "overdamped"])
def test_fixed_shape_error_is_the_linear_second_order_solution(stiffness, damping):
    N, rng = 4, np.random.default_rng(1)
    jt = JacobiTransform(N)
    control = FixedShapeController(stiffness, damping)
    q_desired = np.array([[np.sqrt(2) * 1.5, 0.0], [0.0, np.sqrt(2) * 0.8], [0.0, 0.0]])  # the cross, eq. 41
    r0, v0 = rng.normal(size=(N, 2)), rng.normal(size=(N, 2))

    def forces(t, r, v, _):
        (_, q), (_, dq) = jt.to_jacobi(r), jt.to_jacobi(v)
        return jt.forces_from_jacobi(np.zeros(2), control(q, dq, q_desired)), np.empty(0)

    t = np.linspace(0.0, 6.0, 61)
    y = integrate_platforms(N, forces, np.concatenate([r0.ravel(), v0.ravel()]), t)
    q = jt.to_jacobi(y[:, : 2 * N].reshape(-1, N, 2))[1]
    e0, de0 = jt.to_jacobi(r0)[1] - q_desired, jt.to_jacobi(v0)[1]
    assert np.abs(q - q_desired - error_system(stiffness, damping, t, e0, de0)).max() < TOL


def test_feed_forward_tracks_a_turning_shape_with_the_same_error_dynamics():
    """q^d(t) = g(ω t) p^d with exact q^d', q^d'': the error still obeys e'' + K3 e' + K2 e = 0."""
    N, omega, rng = 3, 0.7, np.random.default_rng(2)
    jt, control = JacobiTransform(N), FixedShapeController(6.0, 3.0)
    p_d = rng.normal(size=(N - 1, 2))

    def desired(t):
        q_d = (rotation(omega * t) @ p_d[..., None])[..., 0]
        return q_d, omega * perp(q_d), -(omega**2) * q_d

    def forces(t, r, v, _):
        (_, q), (_, dq) = jt.to_jacobi(r), jt.to_jacobi(v)
        return jt.forces_from_jacobi(np.zeros(2), control(q, dq, *desired(t))), np.empty(0)

    r0, v0 = rng.normal(size=(N, 2)), rng.normal(size=(N, 2))
    t = np.linspace(0.0, 5.0, 51)
    y = integrate_platforms(N, forces, np.concatenate([r0.ravel(), v0.ravel()]), t)
    q = jt.to_jacobi(y[:, : 2 * N].reshape(-1, N, 2))[1]
    q_d = np.array([desired(tk)[0] for tk in t])
    e0 = jt.to_jacobi(r0)[1] - desired(0)[0]
    de0 = jt.to_jacobi(v0)[1] - desired(0)[1]
    assert np.abs(q - q_d - error_system(6.0, 3.0, t, e0, de0)).max() < TOL


@pytest.mark.parametrize("N", [2, 3])
def test_rotating_formation_follows_the_analytic_frame_and_shape(N):
    """Eqs. 42-43: Ω(t) − Ω^d = (Ω0 − Ω^d) e^{−K6 t}, body-frame error linear, q = g(ψ) p."""
    rng = np.random.default_rng(20 + N)
    jt = JacobiTransform(N)
    K4, K5, K6, omega_d = 5.0, 2.0, 1.5, 1.2
    p_d = rng.normal(size=(N - 1, 2))
    control = RotatingShapeController(p_d, omega_d, K4, K5, K6)
    r0, v0 = rng.normal(size=(N, 2)), rng.normal(size=(N, 2))
    psi0, omega0 = 0.3, -0.4

    def forces(t, r, v, extra):
        (_, q), (_, dq) = jt.to_jacobi(r), jt.to_jacobi(v)
        u, dpsi, domega = control(t, q, dq, extra[0], extra[1])
        return jt.forces_from_jacobi(np.zeros(2), u), np.array([dpsi, domega])

    t = np.linspace(0.0, 6.0, 61)
    y = integrate_platforms(N, forces, np.concatenate([r0.ravel(), v0.ravel(), [psi0, omega0]]), t)
    psi, omega = y[:, 4 * N], y[:, 4 * N + 1]
    decay = np.exp(-K6 * t)
    assert np.abs(omega - (omega_d + (omega0 - omega_d) * decay)).max() < TOL
    assert np.abs(psi - (psi0 + omega_d * t + (omega0 - omega_d) * (1 - decay) / K6)).max() < TOL
    q = jt.to_jacobi(y[:, : 2 * N].reshape(-1, N, 2))[1]
    p0, dp0 = rotating_frame_state(jt.to_jacobi(r0)[1], jt.to_jacobi(v0)[1], psi0, omega0)
    p_expected = p_d + error_system(K4, K5, t, p0 - p_d, dp0)
    q_expected = (rotation(psi)[:, None] @ p_expected[..., None])[..., 0]
    assert np.abs(q - q_expected).max() < TOL


def test_platform_limits():
    limits = PlatformLimits(max_force=2.0, max_speed=1.0)
    f = np.array([[3.0, 4.0], [0.5, 0.0], [1.0, 1.0]])
    v = np.array([[0.0, 0.0], [1.5, 0.0], [0.0, 1.0]])
    applied = limits.apply(f, v)
    assert np.allclose(applied[0], [1.2, 1.6], rtol=0, atol=1e-15)  # saturated, direction kept
    assert np.allclose(applied[1], [0.0, 0.0], rtol=0, atol=1e-15)  # at the speed limit: no speeding up
    assert np.allclose(applied[2], [1.0, 0.0], rtol=0, atol=1e-15)  # only the along-velocity part removed
    assert np.allclose(PlatformLimits().apply(f, v), f, rtol=0, atol=0)
