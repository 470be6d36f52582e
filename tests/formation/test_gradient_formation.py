"""Gradient-based adaptive formation: bounds, stable spacing term, convergence, SUSD.

Theory: docs/theory/distributed.md §7; source: Zhang et al. (2023), eqs. 38-44.
"""

from __future__ import annotations

import numpy as np
import pytest

from mobisense.core.config import ConfigError, parse_config
from mobisense.estimation.distributed.mesh import SensorMesh, paper_network
from mobisense.formation.distributed.gradient_formation import (
    FormationOptions,
    GradientFormation,
    desired_spacing,
    headings,
    spacing_potential,
    spacing_term,
    weighted_gradients,
)

EPS = {"epsilon1": 2e-3, "epsilon2": 1e-4, "epsilon3": 5.0}  # spacing in (5, 25)
SLOPE = np.array([0.006, -0.008])  # constant gradient |g| = 0.01


def hexagon(radius: float = 8.0, jitter: float = 0.0, seed: int = 0) -> tuple[np.ndarray, list[list[int]]]:
    """Six triangles around sensor 0: every intra-cell pair is an edge, so equal distances are feasible."""
    angles = np.pi / 3 * np.arange(6)
    ring = radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    positions = np.vstack([[0.0, 0.0], ring])
    positions += jitter * np.random.default_rng(seed).uniform(-1, 1, positions.shape)
    return positions, [[0, 1 + i, 1 + (i + 1) % 6] for i in range(6)]


def run(
    formation: GradientFormation, positions: np.ndarray, steps: int, field_gradient
) -> tuple[np.ndarray, list]:
    history = []
    for _ in range(steps):
        centres = formation.mesh.centres(positions)
        u, desired = formation.velocities(positions, field_gradient(centres), measurements=None)
        history.append((positions.copy(), desired))
        positions = positions + u  # Δt = 1 s, eq. 40
    return positions, history


def test_desired_spacing_stays_inside_its_bounds_and_shrinks_with_the_gradient() -> None:
    rng = np.random.default_rng(0)
    v = np.vstack([np.zeros((1, 2)), rng.normal(scale=10.0 ** rng.uniform(-4, 2, (200, 1)), size=(200, 2))])
    links = np.array([[i, i + 1] for i in range(len(v) - 1)])
    rho = desired_spacing(v, links, **EPS)
    low, high = EPS["epsilon3"], EPS["epsilon1"] / EPS["epsilon2"] + EPS["epsilon3"]
    assert np.all(rho > low) and np.all(rho <= high)
    pair_norm = np.linalg.norm(v[links[:, 0]] + v[links[:, 1]], axis=1)
    order = np.argsort(pair_norm)
    assert np.all(np.diff(rho[order]) <= 0)  # steeper field → tighter formation
    assert desired_spacing(np.zeros((2, 2)), np.array([[0, 1]]), **EPS)[0] == pytest.approx(high)


def test_spacing_term_is_minus_the_gradient_of_the_potential() -> None:
    rng = np.random.default_rng(1)
    positions, cells = paper_network()
    positions = positions + rng.uniform(-3, 3, positions.shape)
    links = SensorMesh(cells, positions).cell_pairs
    desired = rng.uniform(15, 40, len(links))
    f = spacing_term(positions, links, desired)
    h, numeric = 1e-5, np.zeros_like(positions)
    for i in range(len(positions)):
        for d in range(2):
            step = np.zeros_like(positions)
            step[i, d] = h
            numeric[i, d] = (
                spacing_potential(positions + step, links, desired)
                - spacing_potential(positions - step, links, desired)
            ) / (2 * h)
    # central differences: error O(h² V''') ≈ 1e-10 for V ~ 1e3 m², lengths ~ 30 m
    assert np.allclose(f, -numeric, rtol=0, atol=1e-6)


def test_spacing_term_decreases_the_potential() -> None:
    """The stable direction: with fixed desired distances, c f is a gradient step on V (c Δt < 2/λmax)."""
    positions, cells = hexagon(jitter=3.0, seed=2)
    links = SensorMesh(cells, positions).cell_pairs
    desired = np.full(len(links), 10.0)
    values = [spacing_potential(positions, links, desired)]
    for _ in range(200):
        positions = positions + 0.1 * spacing_term(positions, links, desired)
        values.append(spacing_potential(positions, links, desired))
    assert np.all(np.diff(values) < 0) and values[-1] < 1e-8 * values[0]


def test_weighted_mean_of_equal_gradients_is_that_gradient() -> None:
    positions, cells = paper_network()
    mesh = SensorMesh(cells, positions)
    grads = np.tile(SLOPE, (mesh.n_cells, 1))
    v = weighted_gradients(positions, mesh.centres(positions), grads, mesh.membership)
    assert np.allclose(v, SLOPE, rtol=1e-14)
    summed = weighted_gradients(positions, mesh.centres(positions), grads, mesh.membership, normalise=False)
    weights = (
        mesh.membership / np.sum((positions[:, None] - mesh.centres(positions)[None]) ** 2, axis=-1)
    ).sum(1)
    assert np.allclose(summed, weights[:, None] * SLOPE, rtol=1e-14)  # the paper's literal eq. 38
    w, w_perp = headings(v)
    assert np.allclose(w, SLOPE / np.linalg.norm(SLOPE)) and np.allclose(np.sum(w * w_perp, axis=1), 0.0)


def test_distances_converge_to_the_desired_ones_on_a_constant_gradient_field() -> None:
    """Equal desired distances (keep_shape off) on triangles: the hexagon becomes regular with side ρ."""
    positions, cells = hexagon(radius=8.0, jitter=2.0)
    mesh = SensorMesh(cells, positions)
    options = FormationOptions(a=0.5, b=0.2, c=0.15, keep_shape=False, **EPS)
    formation = GradientFormation(mesh, options, positions)
    final, history = run(formation, positions, 300, lambda centres: np.tile(SLOPE, (len(centres), 1)))
    rho = EPS["epsilon1"] / (2 * SLOPE @ SLOPE + EPS["epsilon2"]) + EPS["epsilon3"]  # ½‖2g‖² = 2|g|²
    desired = history[-1][1]
    assert np.allclose(desired, rho, rtol=1e-12)
    distances = np.linalg.norm(final[formation.links[:, 1]] - final[formation.links[:, 0]], axis=1)
    # geometric convergence at rate ≈ 1 − c λmin per step: after 300 steps far below 1e-8 m
    assert np.allclose(distances, rho, rtol=0, atol=1e-8)
    # the common motion is a w + b w⊥ (f sums to zero over the sensors)
    w = SLOPE / np.linalg.norm(SLOPE)
    drift = final.mean(axis=0) - history[-1][0].mean(axis=0)
    assert np.allclose(drift, 0.5 * w + 0.2 * np.array([-w[1], w[0]]), atol=1e-12)


def test_keep_shape_scales_the_paper_mesh() -> None:
    """With keep_shape the 9-cell mesh converges to its initial shape scaled to mean edge ρ."""
    positions, cells = paper_network(30.0, 24.0)
    mesh = SensorMesh(cells, positions)
    formation = GradientFormation(mesh, FormationOptions(a=1.0, c=0.2, **EPS), positions)
    final, history = run(formation, positions, 400, lambda centres: np.tile(SLOPE, (len(centres), 1)))
    rho = EPS["epsilon1"] / (2 * SLOPE @ SLOPE + EPS["epsilon2"]) + EPS["epsilon3"]
    assert np.allclose(history[-1][1], formation.shape_ratios * rho, rtol=1e-12)
    distances = np.linalg.norm(final[formation.links[:, 1]] - final[formation.links[:, 0]], axis=1)
    assert np.allclose(distances, formation.shape_ratios * rho, rtol=1e-8)
    assert np.all(mesh.areas(final) > 0)


def test_susd_reaches_the_desired_level_and_follows_it() -> None:
    """Linear field z = g·r: Σf = 0, so the mean measurement obeys m' = −a|g|(m − z_d) exactly."""
    positions, cells = hexagon(radius=6.0)
    mesh = SensorMesh(cells, positions)
    level = 0.4
    options = FormationOptions(law="susd", a=20.0, b=0.5, c=0.15, desired_level=level, keep_shape=True, **EPS)
    formation = GradientFormation(mesh, options, positions)
    means = []
    for _ in range(200):
        measurements = positions @ SLOPE
        means.append(measurements.mean())
        u, _ = formation.velocities(positions, np.tile(SLOPE, (mesh.n_cells, 1)), measurements)
        positions = positions + u
    rate = 1 - 20.0 * np.linalg.norm(SLOPE) ** 2 / np.linalg.norm(SLOPE)  # per step: 1 − a|g|
    errors = np.array(means) - level
    assert np.allclose(errors[1:], rate * errors[:-1], rtol=1e-9, atol=1e-15)
    assert abs(errors[-1]) < 1e-8
    w = SLOPE / np.linalg.norm(SLOPE)
    assert np.allclose(u.mean(axis=0), 0.5 * np.array([-w[1], w[0]]), atol=1e-8)  # along the level curve


def test_susd_needs_a_level() -> None:
    with pytest.raises(ConfigError, match="desired_level: required"):
        parse_config({"law": "susd", **EPS}, FormationOptions)
    with pytest.raises(ValueError, match="measurements"):
        positions, cells = hexagon()
        options = FormationOptions(law="susd", desired_level=0.0, **EPS)
        GradientFormation(SensorMesh(cells, positions), options, positions).velocities(
            positions, np.zeros((6, 2))
        )
