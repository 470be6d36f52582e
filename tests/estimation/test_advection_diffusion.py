"""The advection–diffusion fields: derivatives by complex step, PDE residual, sign convention.

Theory: docs/theory/distributed.md §1.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from mobisense.estimation.fields.advection_diffusion import AdvectionDiffusionField
from mobisense.estimation.fields.base import FIELDS, make_field

THETA, V, K = 2.0, np.array([0.5, 1.0]), 0.005
STEP = 1e-30  # complex-step increment: derivative error O(STEP²), no subtractive cancellation


def sample_points(rng: np.random.Generator, n: int = 40) -> tuple[np.ndarray, np.ndarray]:
    return rng.uniform(-300.0, 300.0, size=(n, 2)), rng.uniform(0.0, 600.0, size=n)


def complex_step(f, r: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """∂f/∂t and ∇f of a vectorised f(r, t) by complex step (exact to round-off)."""
    dt = f(r, t + 1j * STEP).imag / STEP
    grad = np.stack([f(r + 1j * STEP * e, t).imag / STEP for e in np.eye(2)], axis=-1)
    return dt, grad


def test_registered_and_built_by_name() -> None:
    field = make_field("advection_diffusion", diffusivity=THETA, velocity=V, wavenumber=K)
    assert FIELDS["advection_diffusion"] is AdvectionDiffusionField
    assert isinstance(field, AdvectionDiffusionField)
    with pytest.raises(ValueError, match="variant"):
        AdvectionDiffusionField(variant="exactly")
    with pytest.raises(ValueError, match="> 0"):
        AdvectionDiffusionField(diffusivity=0.0)


def test_shapes_broadcast() -> None:
    field = AdvectionDiffusionField()
    r = np.zeros((3, 4, 2))
    assert field.value(r, 1.0).shape == (3, 4)
    assert field.gradient(r, 1.0).shape == (3, 4, 2)
    assert field.hessian(r, 1.0).shape == (3, 4, 2, 2)
    # a time per leading index broadcasts against r[..., 0]
    assert field.value(r, np.arange(3.0)[:, None]).shape == (3, 4)


@pytest.mark.parametrize("variant", ["exact", "paper"])
def test_derivatives_match_complex_step(variant: str) -> None:
    rng = np.random.default_rng(1)
    field = AdvectionDiffusionField(THETA, V, 0.05 if variant == "paper" else K, variant=variant)
    r, t = sample_points(rng)
    dz_dt, grad = complex_step(field.value, r, t)
    _, hess = complex_step(field.gradient, r, t)
    # complex step is exact up to round-off; 1e-13 of the derivative scales πk, (πk)² (amplitude 1)
    scale = np.pi * field.wavenumber
    assert np.allclose(grad, field.gradient(r, t), rtol=0, atol=1e-13 * scale)
    assert np.allclose(dz_dt, field.time_derivative(r, t), rtol=0, atol=1e-13 * scale)
    assert np.allclose(hess, field.hessian(r, t), rtol=0, atol=1e-13 * scale**2)
    assert np.allclose(
        np.trace(hess, axis1=-2, axis2=-1), field.laplacian(r, t), rtol=0, atol=1e-13 * scale**2
    )


def test_exact_field_satisfies_the_pde_to_round_off() -> None:
    """Residual ∂z/∂t − θΔz − v·∇z from complex-step derivatives of value() and gradient() only."""
    rng = np.random.default_rng(2)
    field = AdvectionDiffusionField(THETA, V, K)
    r, t = sample_points(rng, 200)
    dz_dt = field.value(r, t + 1j * STEP).imag / STEP
    grad = np.stack([field.value(r + 1j * STEP * e, t).imag / STEP for e in np.eye(2)], axis=-1)
    laplacian = sum(field.gradient(r + 1j * STEP * e, t)[:, i].imag / STEP for i, e in enumerate(np.eye(2)))
    residual = dz_dt - THETA * laplacian - grad @ V
    # the terms are up to πk|v| ≈ 0.018 (ulp ≈ 3.5e-18); measured residual 3.5e-18, bound 1e-14 ≈ 3000 ulps
    assert np.max(np.abs(residual)) < 1e-14
    assert np.max(np.abs(dz_dt)) > 1e-3  # the terms that cancel are not themselves negligible
    assert np.max(np.abs(field.pde_residual(r, t))) < 1e-14


def test_sign_convention_against_symbolic_pde() -> None:
    """CasADi differentiates eq. distributed.1: ``x + v t`` solves ∂z/∂t = θΔz + v·∇z, ``x − v t`` does not."""
    x, y, t = ca.SX.sym("x"), ca.SX.sym("y"), ca.SX.sym("t")
    residuals = {}
    for sign in (+1, -1):
        z = ca.sin(np.pi * K * (x + sign * V[0] * t)) * ca.sin(np.pi * K * (y + sign * V[1] * t))
        z = z * ca.exp(-2 * THETA * np.pi**2 * K**2 * t)
        grad = ca.gradient(z, ca.vertcat(x, y))
        lap = ca.jacobian(grad[0], x) + ca.jacobian(grad[1], y)
        res = ca.jacobian(z, t) - THETA * lap - (V[0] * grad[0] + V[1] * grad[1])
        residuals[sign] = ca.Function("res", [x, y, t], [res, z])
    pts = np.random.default_rng(3).uniform([-200, -200, 0], [200, 200, 600], size=(50, 3))
    plus = np.array([float(residuals[1](*p)[0]) for p in pts])
    minus = np.array([float(residuals[-1](*p)[0]) for p in pts])
    symbolic_values = np.array([float(residuals[1](*p)[1]) for p in pts])
    field = AdvectionDiffusionField(THETA, V, K)
    assert np.allclose(field.value(pts[:, :2], pts[:, 2]), symbolic_values, rtol=0, atol=1e-15)
    assert np.max(np.abs(plus)) < 1e-15  # terms of size ≤ 0.018 cancelling to round-off
    # the flipped sign leaves 2 v·∇z, of order πk|v| = 0.018
    assert np.max(np.abs(minus)) > 1e-3


def test_paper_field_residual_is_the_predicted_one() -> None:
    """The paper's field misses the PDE by (k₂/k₁ − 1) v·∇z + 2θπ²(k₁² − k₂) z (module docstring)."""
    k1, k2 = 0.05, 1e-4
    field = AdvectionDiffusionField(THETA, V, k1, variant="paper", temporal_wavenumber=k2)
    rng = np.random.default_rng(4)
    r, t = rng.uniform(-30, 30, size=(100, 2)), rng.uniform(0, 600, size=100)
    # the printed form: sin(π(k1 x + v1 k2 t)) e^{−θπ²k2 t} sin(π(k1 y + k2 v2 t)) e^{−θπ²k2 t}
    decay = np.exp(-THETA * np.pi**2 * k2 * t)
    printed = (
        np.sin(np.pi * (k1 * r[:, 0] + V[0] * k2 * t))
        * decay
        * np.sin(np.pi * (k1 * r[:, 1] + k2 * V[1] * t))
        * decay
    )
    assert np.allclose(field.value(r, t), printed, atol=1e-15)
    predicted = (k2 / k1 - 1) * field.gradient(r, t) @ V + 2 * THETA * np.pi**2 * (k1**2 - k2) * field.value(
        r, t
    )
    assert np.allclose(field.pde_residual(r, t), predicted, rtol=1e-12, atol=1e-15)
    assert np.max(np.abs(predicted)) > 0.1  # far from a solution
