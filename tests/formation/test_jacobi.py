"""Jacobi transform: orthonormal construction, the paper's N = 4 vectors, exact energy split.

Theory: docs/theory/formation_control.md §1; source: Zhang & Leonard (2010), §V-A, eq. 38.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from mobisense.formation.jacobi import JacobiTransform, default_tree, jacobi_matrix
from mobisense.formation.shape_control import FixedShapeController

# Every identity below is exact algebra on O(1) numbers: round-off of a few ulps, so 1e-13 (≈ 500 ulp)
ROUND_OFF = 1e-13


@pytest.mark.parametrize("N", range(2, 9))
def test_directions_are_orthonormal_and_orthogonal_to_ones(N):
    Psi = jacobi_matrix(N)
    Q = Psi[:, 1:]
    assert np.allclose(Psi[:, 0], 1.0 / N, rtol=0, atol=ROUND_OFF)
    assert np.abs(Q.T @ Q - np.eye(N - 1)).max() < ROUND_OFF
    assert np.abs(Q.sum(axis=0)).max() < ROUND_OFF
    # Ψ⁻¹ = [1, Q]' (docs/theory/formation_control.md §1.1), compared with a numerical inverse
    assert np.abs(np.linalg.inv(Psi) - np.column_stack([np.ones(N), Q]).T).max() < ROUND_OFF


def test_four_platforms_reproduce_the_papers_eq_38():
    r = np.random.default_rng(0).normal(size=(4, 2))
    _, q = JacobiTransform(4).to_jacobi(r)
    expected = [(r[1] - r[0]) / np.sqrt(2), (r[2] - r[3]) / np.sqrt(2), 0.5 * (r[3] + r[2] - r[1] - r[0])]
    assert np.abs(q - np.array(expected)).max() < ROUND_OFF
    assert default_tree(4) == ((0, 1), (3, 2))


def test_cross_maps_to_scaled_axes():
    a, b = 1.3, 0.7
    r = np.array([[-a, 0.0], [a, 0.0], [0.0, b], [0.0, -b]])
    center, q = JacobiTransform(4).to_jacobi(r)
    assert np.abs(center).max() < ROUND_OFF
    assert np.abs(q - [[np.sqrt(2) * a, 0.0], [0.0, np.sqrt(2) * b], [0.0, 0.0]]).max() < ROUND_OFF


@pytest.mark.parametrize("N", [2, 3, 4, 7])
def test_kinetic_energy_splits_exactly(N):
    rng = np.random.default_rng(N)
    v = rng.normal(size=(50, N, 2))  # a batch of velocity sets
    jt = JacobiTransform(N)
    center_part, shape_part = jt.kinetic_energy(v)
    total = 0.5 * np.sum(v**2, axis=(-2, -1))
    assert np.abs(center_part + shape_part - total).max() < ROUND_OFF * total.max()


@pytest.mark.parametrize("N", [2, 4, 5])
def test_inverse_maps_round_trip(N):
    rng = np.random.default_rng(10 + N)
    jt = JacobiTransform(N)
    r, f = rng.normal(size=(3, N, 2)), rng.normal(size=(3, N, 2))
    assert np.abs(jt.from_jacobi(*jt.to_jacobi(r)) - r).max() < ROUND_OFF
    assert np.abs(jt.forces_from_jacobi(*jt.forces_to_jacobi(f)) - f).max() < ROUND_OFF
    # equivalent forces act on the Jacobi coordinates by Newton's law: N r_c'' = f_c, q'' = u (eqs. 39-40)
    center_accel, q_accel = jt.to_jacobi(f)  # r'' = f mapped like positions
    f_c, u = jt.forces_to_jacobi(f)
    assert np.abs(N * center_accel - f_c).max() < ROUND_OFF
    assert np.abs(q_accel - u).max() < ROUND_OFF


def test_custom_tree_and_invalid_tree():
    Psi = jacobi_matrix(3, ((0, 1), 2))
    assert np.abs(Psi[:, 1] - np.array([-1, 1, 0]) / np.sqrt(2)).max() < ROUND_OFF
    with pytest.raises(ValueError, match="exactly once"):
        jacobi_matrix(3, ((0, 1), 1))


def test_shape_forces_leave_the_centre_untouched():
    """Newton's equations with shape-only forces: the centre moves on r_c0 + v_c0 t (eq. formation_control.4)."""
    N, rng = 5, np.random.default_rng(3)
    jt = JacobiTransform(N)
    control = FixedShapeController(stiffness=9.0, damping=6.0)
    q_desired = rng.normal(size=(N - 1, 2))
    r0, v0 = rng.normal(size=(N, 2)), rng.normal(size=(N, 2))

    def rhs(t, y):
        r, v = y[: 2 * N].reshape(N, 2), y[2 * N :].reshape(N, 2)
        _, q = jt.to_jacobi(r)
        _, dq = jt.to_jacobi(v)
        f = jt.forces_from_jacobi(np.zeros(2), control(q, dq, q_desired))
        return np.concatenate([v.ravel(), f.ravel()])

    t = np.linspace(0, 5, 51)
    sol = solve_ivp(rhs, (0, 5), np.concatenate([r0.ravel(), v0.ravel()]), t_eval=t, rtol=1e-12, atol=1e-12)
    centers = jt.to_jacobi(sol.y[: 2 * N].T.reshape(-1, N, 2))[0]
    expected = r0.mean(axis=0) + t[:, None] * v0.mean(axis=0)
    # the centre's equation r_c'' = Σ f_i / N = 0 is exact; what remains is the integrator's error
    # (rtol = atol = 1e-12 per step over ~10³ steps on O(10) states): 1e-9
    assert np.abs(centers - expected).max() < 1e-9
    # while the shape did move to its target (a non-trivial run)
    assert np.abs(jt.to_jacobi(sol.y[: 2 * N, -1].reshape(N, 2))[1] - q_desired).max() < 1e-3
