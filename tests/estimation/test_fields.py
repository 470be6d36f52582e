"""Fields (docs/theory/cooperative.md §6) and the spatially correlated noise model (docs/theory/cooperative.md §3)."""

from __future__ import annotations

import numpy as np
import pytest

from mobisense.core.config import ConfigError, StrictModel, parse_config
from mobisense.core.files import write_netcdf
from mobisense.estimation.cooperative.spatial_noise import KERNELS, SpatialNoise
from mobisense.estimation.fields.base import FIELDS, Field
from mobisense.estimation.fields.gridded import GriddedField
from mobisense.estimation.fields.library import (
    FieldSpec,
    OceanTemperatureField,
    QuadraticField,
    TwoChargesField,
    grid_dataset,
    load_fields,
)


@pytest.fixture(scope="module")
def gridded_path(tmp_path_factory: pytest.TempPathFactory) -> str:
    ocean = OceanTemperatureField()
    path = tmp_path_factory.mktemp("grid") / "ocean.nc"
    write_netcdf(path, grid_dataset(ocean, np.linspace(0, 80, 321), np.linspace(0, 60, 241), name="temperature"))
    return str(path)


def _instances(gridded_path: str) -> dict[str, Field]:
    """One instance of every registered field (advection_diffusion only if that module exists)."""
    out: dict[str, Field] = {
        "quadratic": QuadraticField([[1.0, 0.4], [0.4, -2.0]], [0.3, -0.7], 2.0, [0.5, 0.5]),
        "two_charges": TwoChargesField(),
        "ocean_temperature": OceanTemperatureField(),
        "gridded": GriddedField(gridded_path, variable="temperature", degree=5),
    }
    for kind, cls in load_fields().items():
        if kind not in out:
            out[kind] = cls()  # optional fields registered by other modules, default parameters
    return out


POINTS = {  # well inside each field's domain, away from singularities
    "quadratic": np.array([[0.1, -0.3], [2.0, 1.0]]),
    "two_charges": np.array([[0.5, 2.0], [-1.0, -1.5]]),
    "ocean_temperature": np.array([[21.0, 38.0], [55.0, 20.0], [40.0, 30.0]]),
    "gridded": np.array([[21.0, 38.0], [55.0, 20.0]]),
}


def test_registry_contains_the_library_fields() -> None:
    kinds = load_fields()
    assert {"quadratic", "two_charges", "ocean_temperature", "gridded"} <= set(kinds)
    assert kinds is FIELDS


def test_every_built_in_kind_is_found_in_a_fresh_interpreter() -> None:
    """``make_field`` before any field module is imported (the registry's built-in entries are lazy)."""
    import subprocess
    import sys

    code = (
        "import sys; from mobisense.estimation import make_field; from mobisense.estimation.fields.base import FIELDS\n"
        "assert 'mobisense.estimation.fields.library' not in sys.modules\n"
        "print(type(make_field('quadratic')).__name__, *(FIELDS[k].kind for k in sorted(FIELDS)))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["QuadraticField", *sorted(load_fields())]


@pytest.mark.parametrize("kind", sorted(load_fields()))
def test_derivatives_match_central_differences(kind: str, gridded_path: str) -> None:
    field = _instances(gridded_path)[kind]
    r = POINTS.get(kind, np.array([[3.0, 4.0], [7.0, 2.5]]))
    scale = max(1.0, float(np.abs(r).max()))
    h = 1e-4 * scale
    e = np.eye(2) * h
    fd_grad = np.stack([(field.value(r + e[i]) - field.value(r - e[i])) / (2 * h) for i in range(2)], -1)
    fd_hess = np.stack([(field.gradient(r + e[i]) - field.gradient(r - e[i])) / (2 * h) for i in range(2)], -1)
    grad, hess = field.gradient(r), field.hessian(r)
    assert field.value(r).shape == r.shape[:-1] and grad.shape == r.shape and hess.shape == r.shape + (2,)
    # central differences: truncation h² |f'''| / 6 plus round-off eps |f| / h; with h = 1e-4 L both are
    # far below 1e-6 of the derivative scale for these smooth fields
    tol_g = 1e-6 * max(1.0, np.abs(grad).max())
    tol_h = 1e-6 * max(1.0, np.abs(hess).max())
    np.testing.assert_allclose(grad, fd_grad, atol=tol_g)
    np.testing.assert_allclose(hess, fd_hess, atol=tol_h)
    np.testing.assert_allclose(hess, np.swapaxes(hess, -1, -2), atol=1e-12 * max(1.0, np.abs(hess).max()))


def test_quadratic_and_two_charge_closed_forms() -> None:
    q = QuadraticField([[2.0, 1.0], [1.0, 3.0]], [1.0, -1.0], 5.0, [1.0, 1.0])
    np.testing.assert_allclose(q.value(np.array([2.0, 1.0])), 5.0 + 1.0 + 0.5 * 2.0, rtol=1e-15)
    charges = TwoChargesField(charges=[[0.0, 0.0], [4.0, 0.0]], strength=2.0)
    # midpoint: potentials add, fields cancel by symmetry
    mid = np.array([2.0, 0.0])
    np.testing.assert_allclose(charges.value(mid), 2.0, rtol=1e-15)
    np.testing.assert_allclose(charges.gradient(mid), 0.0, atol=1e-15)
    # 1/ρ is harmonic in 3-D, not in the plane: Laplacian of q/ρ in 2-D is q/ρ³ per charge
    np.testing.assert_allclose(np.trace(charges.hessian(mid)), 2 * 2.0 / 8.0, rtol=1e-14)


def test_ocean_field_has_a_13_degree_isotherm_crossing_the_domain() -> None:
    ocean = OceanTemperatureField()
    x = np.linspace(0.0, 80.0, 161)
    south = ocean.value(np.stack([x, np.zeros_like(x)], -1))
    north = ocean.value(np.stack([x, np.full_like(x, 60.0)], -1))
    assert np.all(south > 13.0) and np.all(north < 13.0)  # every meridian crosses 13 °C
    # and the temperatures are ocean-like (°C) with fronts of a few °C over a few km
    X, Y = np.meshgrid(x, np.linspace(0, 60, 121))
    values = ocean.value(np.stack([X, Y], -1))
    assert 9.0 < values.min() < 12.0 and 14.0 < values.max() < 17.5
    assert 0.1 < np.linalg.norm(ocean.gradient(np.stack([X, Y], -1)), axis=-1).max() < 1.0  # °C/km


def test_gridded_field_is_exact_on_quadratics_and_converges_on_the_ocean(tmp_path) -> None:
    quad = QuadraticField([[1.0, 0.4], [0.4, -2.0]], [0.3, -0.7], 2.0, [0.5, 0.5])
    path = tmp_path / "quad.nc"
    write_netcdf(path, grid_dataset(quad, np.linspace(-2, 2, 9), np.linspace(-1, 3, 11)))
    gridded = GriddedField(path)
    r = np.array([[0.13, 0.71], [-1.3, 2.2]])
    # an interpolating cubic spline reproduces polynomials of degree <= 3 up to round-off
    np.testing.assert_allclose(gridded.value(r), quad.value(r), atol=1e-12)
    np.testing.assert_allclose(gridded.hessian(r), quad.hessian(r), atol=1e-10)
    ocean = OceanTemperatureField()
    errors = []
    for n in (41, 81, 161):
        p = tmp_path / f"ocean{n}.nc"
        write_netcdf(p, grid_dataset(ocean, np.linspace(0, 80, n), np.linspace(0, 60, n)))
        errors.append(
            np.abs(GriddedField(p).value(POINTS["ocean_temperature"]) - ocean.value(POINTS["ocean_temperature"])).max()
        )
    order = np.log2(errors[1] / errors[2])
    assert order > 3.0, f"cubic spline interpolation should converge at ~4th order, measured {order:.2f} ({errors})"


def test_field_spec_validation_reports_key_and_suggestion() -> None:
    spec = FieldSpec.model_validate({"kind": "ocean_temperature", "front_width": 4.0})
    assert isinstance(spec.build(), OceanTemperatureField) and spec.build().w == 4.0
    with pytest.raises(ConfigError, match=r"field\.front_widht: unknown parameter .*did you mean 'front_width'"):
        parse_config({"field": {"kind": "ocean_temperature", "front_widht": 4.0}}, _Holder, "f.yaml")
    with pytest.raises(ConfigError, match=r"field\.kind: unknown field kind 'two_charge'; did you mean 'two_charges'"):
        parse_config({"field": {"kind": "two_charge"}}, _Holder, "f.yaml")
    with pytest.raises(ConfigError, match="strength must be > 0"):
        parse_config({"field": {"kind": "two_charges", "strength": -1.0}}, _Holder, "f.yaml")


class _Holder(StrictModel):
    field: FieldSpec


# ------------------------------------------------------------------------------------------- noise
@pytest.mark.parametrize("kernel", sorted(KERNELS))
def test_fourier_feature_realisations_have_the_kernel_covariance(kernel: str) -> None:
    noise = SpatialNoise(std=0.7, length_scale=2.0, kernel=kernel)
    rng = np.random.default_rng(7)
    points = np.array([[0.0, 0.0], [0.5, 0.0], [1.0, 1.0], [3.0, -1.0]])
    n_runs = 4000
    realisation = noise.realisation(rng, batch=(n_runs,), n_features=200)
    samples = realisation(np.broadcast_to(points, (n_runs,) + points.shape))  # (runs, 4)
    empirical = samples.T @ samples / n_runs
    expected = noise.W(points)
    # the sample covariance of n_runs draws has std ≈ sqrt((C_ii C_jj + C_ij²)/n) <= sqrt(2/n) σ²: 5 of them
    np.testing.assert_allclose(empirical, expected, atol=5 * np.sqrt(2 / n_runs) * noise.std**2)


def test_exact_samples_and_markov_model_match_the_joint_gaussian() -> None:
    noise = SpatialNoise(std=0.5, length_scale=1.5, kernel="matern32")
    previous = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    current = previous + np.array([0.3, 0.1])
    A_w, Q_w = noise.markov(current, previous)
    # independent check: Gaussian conditioning via the joint covariance (Schur complement)
    joint = noise.W(np.concatenate([current, previous]))
    S11, S12, S22 = joint[:3, :3], joint[:3, 3:], joint[3:, 3:]
    np.testing.assert_allclose(A_w, S12 @ np.linalg.inv(S22), atol=1e-12)
    np.testing.assert_allclose(Q_w, S11 - S12 @ np.linalg.inv(S22) @ S12.T, atol=1e-12)
    np.testing.assert_allclose(noise.V(current, previous), S12, atol=0)
    samples = noise.sample(np.concatenate([current, previous]), np.random.default_rng(3), size=(20000,))
    emp = np.cov(samples.T)
    np.testing.assert_allclose(emp, joint, atol=5 * np.sqrt(2 / 20000) * noise.std**2)  # 5 sample-cov std
    # the exponential kernel's correlation at one length scale is e^-1
    assert KERNELS["exponential"].correlation(np.array(1.0)) == pytest.approx(np.exp(-1.0), rel=1e-15)
