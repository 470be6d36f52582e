"""Hessian estimation (docs/theory/hessian.md): one-step filter, least squares, level-curve curvature."""

from __future__ import annotations

import numpy as np
import pytest

from mobisense.estimation.cooperative.hessian import curvature_hessian, least_squares_hessian, one_step_filter
from mobisense.estimation.cooperative.information_model import cross_formation
from mobisense.estimation.fields.library import OceanTemperatureField, QuadraticField, TwoChargesField

QUADRATIC = QuadraticField([[1.0, 0.3], [0.3, -0.5]], [1.0, 2.0], 3.0)


def _spd(rng: np.random.Generator, n: int, rank: int | None = None) -> np.ndarray:
    X = rng.normal(size=(n, rank or n))
    return X @ X.T + (0 if rank else 0.1 * np.eye(n))


def test_one_step_filter_matches_the_printed_form_and_its_cost() -> None:
    rng = np.random.default_rng(0)
    G, Sigma = _spd(rng, 4), _spd(rng, 4)
    z_hat, p = rng.normal(size=4), rng.normal(size=4)
    filtered, cov = one_step_filter(z_hat, G, p, Sigma)
    inv = np.linalg.inv
    I = np.eye(4)
    # Zhang & Leonard (2010), eq. 33 as printed (eq. hessian.2, left-hand form)
    printed = inv(I + G @ inv(Sigma)) @ z_hat + inv(I + Sigma @ inv(G)) @ p
    np.testing.assert_allclose(filtered, printed, atol=1e-12)
    np.testing.assert_allclose(cov, inv(I + G @ inv(Sigma)) @ G, atol=1e-12)  # Prop. 4.1
    # it minimises ½[(z − ẑ)' G⁻¹ (z − ẑ) + (p − z)' Σ⁻¹ (p − z)], whose Hessian inverse is the covariance
    np.testing.assert_allclose(filtered, inv(inv(G) + inv(Sigma)) @ (inv(G) @ z_hat + inv(Sigma) @ p), atol=1e-12)
    np.testing.assert_allclose(cov, inv(inv(G) + inv(Sigma)), atol=1e-12)
    # and stays defined for the rank-3 G of four platforms (G = C P C')
    G3 = _spd(rng, 4, rank=3)
    f3, c3 = one_step_filter(z_hat, G3, p, Sigma)
    assert np.all(np.isfinite(f3)) and np.linalg.eigvalsh(c3).min() > -1e-12


def test_least_squares_hessian_is_exact_on_quadratic_fields() -> None:
    rng = np.random.default_rng(1)
    for n in (3, 5, 8):  # with the state known, 3 generic platforms suffice
        positions = rng.normal(size=(6, n, 2))  # a batch of 6 random formations
        centers = positions.mean(axis=-2)
        state = np.concatenate([QUADRATIC.value(centers)[..., None], QUADRATIC.gradient(centers)], -1)
        H = least_squares_hessian(positions, QUADRATIC.value(positions), state)
        np.testing.assert_allclose(H, np.broadcast_to(QUADRATIC.H, H.shape), atol=1e-11)  # round-off, cond ~1e2
    positions = rng.normal(size=(4, 7, 2))  # joint fit of [z, ∇z, H]: N >= 6
    state, H = least_squares_hessian(positions, QUADRATIC.value(positions))
    np.testing.assert_allclose(H, np.broadcast_to(QUADRATIC.H, H.shape), atol=1e-11)
    np.testing.assert_allclose(state[..., 0], QUADRATIC.value(positions.mean(axis=-2)), atol=1e-11)


def test_least_squares_refuses_the_cross_whose_values_do_not_determine_h12() -> None:
    """For the cross, values at (±a, 0), (0, ±b) do not depend on the body-frame H12 at all."""
    positions = cross_formation(1.0, 1.5)
    other = QuadraticField([[1.0, -2.0], [-2.0, -0.5]], [1.0, 2.0], 3.0)  # differs only in H12
    np.testing.assert_allclose(other.value(positions), QUADRATIC.value(positions), atol=1e-14)
    with pytest.raises(ValueError, match="does not determine the Hessian"):
        least_squares_hessian(positions, QUADRATIC.value(positions), np.r_[3.0, 1.0, 2.0])


def _aligned_cross(field, center: np.ndarray, a: float) -> np.ndarray:  # noqa: ANN001
    """The paper's layout: platforms 1-2 along the level curve through the centre (Fig. 2)."""
    g = field.gradient(center)
    return cross_formation(a, a, center=center, orientation=np.arctan2(-g[0], g[1]))


@pytest.mark.parametrize(
    ("field", "center"),
    [
        (QUADRATIC, np.array([0.4, -0.2])),
        (OceanTemperatureField(), np.array([30.0, 33.0])),
        (TwoChargesField(), np.array([0.5, 2.0])),
    ],
    ids=["quadratic", "ocean", "two_charges"],
)
def test_curvature_hessian_converges_at_second_order(field, center: np.ndarray) -> None:  # noqa: ANN001
    """Steps s.1-s.8 from the previous step's Hessian: error O(a²) in the formation size a."""
    H_true = field.hessian(center)
    state = np.r_[field.value(center), field.gradient(center)]
    sizes = np.array([0.4, 0.2, 0.1, 0.05]) * (
        2.5 if isinstance(field, OceanTemperatureField) else 1.0
    )  # km for the ocean
    errors = []
    for a in sizes:
        positions = _aligned_cross(field, center, a)
        H = curvature_hessian(positions, field.value(positions), state, H_true, iterations=1)
        errors.append(np.abs(H - H_true).max() / np.abs(H_true).max())
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    # finite differences of angle and |∇z| over the three points J, c, K are second-order accurate:
    # the measured order approaches 2 once the formation is small against the field's scales
    assert np.all(np.abs(orders[1:] - 2.0) < 0.2), f"orders {orders}, errors {errors}"
    assert errors[-1] < 1e-3
    # a rotated (not aligned) cross converges too; the batch of two gives the same as one at a time
    rotated = cross_formation(sizes[-1], 1.3 * sizes[-1], center=center, orientation=0.3)
    both = np.stack([rotated, _aligned_cross(field, center, sizes[-1])])
    H_both = curvature_hessian(both, field.value(both), state, H_true, iterations=1)
    np.testing.assert_allclose(
        H_both[1], curvature_hessian(both[1], field.value(both[1]), state, H_true, iterations=1), atol=1e-14
    )
    assert np.abs(H_both[0] - H_true).max() / np.abs(H_true).max() < 5e-3


def test_curvature_hessian_keeps_the_unobservable_part_of_its_initial_guess() -> None:
    """The documented limitation: one snapshot of a cross cannot correct the body-frame H12 of Hᵖ.

    The map Hᵖ ↦ Ĥ of one pass has Jacobian eigenvalue 1 along that direction (measured here), so the
    estimate relies on Hᵖ from the previous step, as the paper prescribes.
    """
    center = np.array([0.4, -0.2])
    positions = _aligned_cross(QUADRATIC, center, 0.1)
    values = QUADRATIC.value(positions)
    state = np.r_[QUADRATIC.value(center), QUADRATIC.gradient(center)]

    def one_pass(h: np.ndarray) -> np.ndarray:
        H = curvature_hessian(positions, values, state, np.array([[h[0], h[1]], [h[1], h[2]]]), iterations=1)
        return np.array([H[0, 0], H[0, 1], H[1, 1]])

    h0, eps = np.array([1.0, 0.3, -0.5]), 1e-6
    J = np.stack([(one_pass(h0 + eps * e) - one_pass(h0 - eps * e)) / (2 * eps) for e in np.eye(3)], -1)
    eigenvalues = np.sort(np.abs(np.linalg.eigvals(J)))
    assert abs(eigenvalues[-1] - 1.0) < 1e-3  # neutral direction: kept from Hᵖ
    assert eigenvalues[0] < 1e-6  # and another direction fully determined by the data
