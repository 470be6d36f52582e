"""Level-curve tracking: θ and z dynamics, level functions, Lyapunov decrease on true fields.

Theory: docs/theory/level_curve.md.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from mobisense.estimation.fields.library import OceanTemperatureField, QuadraticField, TwoChargesField
from mobisense.formation.level_curve import (
    LEVEL_FUNCTIONS,
    LevelCurveController,
    LinearLevel,
    ReciprocalLevel,
    curvature_terms,
    heading_error,
    heading_rate,
)
from mobisense.formation.shape_control import perp

FIELDS = {
    "two_charges": (
        TwoChargesField(),
        lambda t: np.stack([2 + np.cos(1.3 * t) + 0.3 * t, 4 + 2 * np.sin(0.7 * t)], -1),
    ),
    "ocean": (
        OceanTemperatureField(),
        lambda t: np.stack([30 + 3 * np.cos(1.3 * t) + 2 * t, 32 + 4 * np.sin(0.7 * t)], -1),
    ),
}


@pytest.mark.parametrize("name", FIELDS)
def test_heading_and_level_dynamics_match_finite_differences(name):
    """θ' = α(κ1 cos θ + κ2 sin θ − u_c) and z' = −α‖∇z‖ sin θ along an arbitrary smooth path.

    This fixes the sign of κ2 (+x1'∇²z y1/‖∇z‖ with the frames of docs/theory/level_curve.md §2); the printed minus
    fails by O(0.1).
    """
    field, path = FIELDS[name]
    t = np.linspace(0.0, 2.0, 20001)
    h = t[1] - t[0]
    r = path(t)
    v, a = np.gradient(r, h, axis=0, edge_order=2), None
    a = np.gradient(v, h, axis=0, edge_order=2)
    g, H = field.gradient(r), field.hessian(r)
    alpha, theta = heading_error(v, g)
    kappa1, kappa2 = curvature_terms(g, H)
    u_c = np.sum(a * perp(v / alpha[:, None]), axis=-1) / alpha**2  # path curvature, eqs. 44-47
    inner = slice(10, -10)
    dtheta = np.gradient(np.unwrap(theta), h)[inner]
    dz = np.gradient(field.value(r), h)[inner]
    # centred differences of smooth O(1)-scale signals with h = 1e-4: truncation ~h² |f'''| ~ 1e-7 (the
    # path curvature itself comes from a second difference: ~1e-6); the wrong sign of κ2 errs by > 0.1
    assert np.abs(dtheta - heading_rate(alpha, theta, kappa1, kappa2, u_c)[inner]).max() < 1e-5
    assert np.abs(dtheta - heading_rate(alpha, theta, kappa1, -kappa2, u_c)[inner]).max() > 0.1
    assert np.abs(dz + (alpha * np.linalg.norm(g, axis=-1) * np.sin(theta))[inner]).max() < 1e-6


def test_kappa1_is_the_level_curve_curvature():
    """z = ‖r‖²: level curves are circles; followed along x1 (clockwise) their signed curvature is −1/ρ."""
    field = QuadraticField(hessian=[[2.0, 0.0], [0.0, 2.0]])
    angles = np.linspace(0, 2 * np.pi, 7)
    rho = 2.5
    r = rho * np.stack([np.cos(angles), np.sin(angles)], -1)
    kappa1, kappa2 = curvature_terms(field.gradient(r), field.hessian(r))
    assert np.allclose(kappa1, -1 / rho, rtol=0, atol=1e-15) and np.allclose(kappa2, 0.0, rtol=0, atol=1e-15)


@pytest.mark.parametrize("kind", sorted(LEVEL_FUNCTIONS))
def test_level_functions(kind):
    level = LEVEL_FUNCTIONS[kind](level=4.0, gain=3.0)
    z = np.linspace(0.5, 12.0, 200)
    dz = 1e-6
    # f = dh/dz: centred difference error ~dz² h''' ≈ 1e-12 relative to O(1) values
    assert np.allclose(level.f(z), (level.h(z + dz) - level.h(z - dz)) / (2 * dz), rtol=1e-7, atol=1e-8)
    assert level.h(np.array(4.0)) == 0.0 and level.f(np.array(4.0)) == 0.0
    assert np.all(level.h(z[np.abs(z - 4.0) > 1e-3]) > 0)


def test_reciprocal_level_needs_a_positive_level():
    with pytest.raises(ValueError, match="C > 0"):
        ReciprocalLevel(level=-1.0)


def fly_particle(controller, field, r0, v0, T):
    """The centre as a unit-mass particle r'' = a_c with exact field knowledge (docs/theory/level_curve.md §1)."""

    def rhs(t, y):
        r, v = y[:2], y[2:]
        return np.concatenate([v, controller(v, field.value(r), field.gradient(r), field.hessian(r))])

    t = np.linspace(0, T, 20001)
    sol = solve_ivp(rhs, (0, T), np.concatenate([r0, v0]), t_eval=t, method="DOP853", rtol=1e-10, atol=1e-10)
    assert sol.success
    return t, sol.y[:2].T, sol.y[2:].T


CASES = {
    # elliptic paraboloid: levels are ellipses; start off the level C = 2 and at 60° heading error
    "quadratic": (
        QuadraticField(hessian=[[1.0, 0.3], [0.3, 2.0]]),
        LinearLevel(2.0, 1.0),
        [2.5, 0.5],
        [0.0, 0.8],
        40.0,
    ),
    # two charges, level 4 (an oval around both), reciprocal f, starting outside at speed 1.5
    "two_charges": (TwoChargesField(), ReciprocalLevel(4.0, 4.0), [0.0, 6.0], [-1.5, 0.8], 60.0),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", CASES)
def test_lyapunov_decreases_and_the_level_is_reached_with_true_derivatives(name):
    field, level, r0, v0, T = CASES[name]
    controller = LevelCurveController(level, speed=1.0, speed_gain=1.0, steering_gain=1.5)
    t, r, v = fly_particle(controller, field, np.array(r0), np.array(v0), T)
    alpha, theta = heading_error(v, field.gradient(r))
    V = controller.lyapunov(theta, field.value(r))
    # V' = −α K4 sin²(θ/2)/cos(θ/2) ≤ 0 exactly; the samples may rise only by integration error
    # (rtol 1e-10 on O(1) states): 1e-8
    assert np.max(np.diff(V)) < 1e-8
    # and V' itself matches the closed form (centred differences on a 2e-3 grid: error ~dt² |V'''| ≲ 1e-4)
    dV = np.gradient(V, t)[5:-5]
    assert np.abs(dV - controller.lyapunov_rate(alpha, theta)[5:-5]).max() < 1e-3
    assert abs(field.value(r[0]) - level.level) > 0.5 and abs(theta[0]) > 0.4  # a non-trivial start
    assert abs(theta[-1]) < 1e-4 and abs(field.value(r[-1]) - level.level) < 1e-4
    assert abs(alpha[-1] - 1.0) < 1e-6  # speed control α' = −K1(α − 1)
