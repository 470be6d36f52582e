"""Per-cell model, Hessian fit, projection stability, locality, benefit of the constraint.

Theory: docs/theory/distributed.md §3–§6.
"""

from __future__ import annotations

import control
import numpy as np
import pytest

from mobisense.estimation.cooperative.information_model import hessian_to_vec
from mobisense.estimation.distributed.filter import (
    CellFilter,
    DistributedFilter,
    FilterOptions,
    HessianOptions,
    PdeModel,
    cell_measurement_matrices,
    cell_transition,
    fit_hessian,
)
from mobisense.estimation.distributed.fvm import far_points, laplacian_stencil, pde_constraint, project
from mobisense.estimation.distributed.mesh import SensorMesh, grid_network, paper_network

THETA, V = 2.0, np.array([0.5, 1.0])
# v'Hv = 0 and H11 = H22: z below is linear in t at a fixed point and the square-cell FVM is exact
HESS = 1e-4 * np.array([[1.0, -1.25], [-1.25, 1.0]])
G0 = np.array([0.004, -0.003])
OPTIONS = FilterOptions(
    process_std={"value": 3e-3, "gradient": 1e-4},
    initial_std={"value": 0.5, "gradient": 0.02},
    hessian={"method": "ridge", "ridge": 1e6, "error_std": 1e-4},
)


def z(p: np.ndarray, t: float, hess: np.ndarray = HESS) -> np.ndarray:
    """An exact polynomial solution of ∂z/∂t = θΔz + v·∇z: q(r + v t) + θ tr(H) t."""
    s = p + V * t
    return 0.5 * np.einsum("...i,ij,...j->...", s, hess, s) + s @ G0 + THETA * np.trace(hess) * t


def grad_z(p: np.ndarray, t: float, hess: np.ndarray = HESS) -> np.ndarray:
    return (p + V * t) @ hess + G0


def state(centre: np.ndarray, k: int) -> np.ndarray:
    """True x(k) = [z(c, k−1), ∇z(c, k−1), z(c, k), ∇z(c, k)] at the previous centre c (Δt = 1)."""
    return np.concatenate(
        [[z(centre, k - 1.0)], grad_z(centre, k - 1.0), [z(centre, float(k))], grad_z(centre, float(k))]
    )


def test_transition_is_exact_for_the_polynomial_solution() -> None:
    rng = np.random.default_rng(0)
    for _ in range(5):
        c_prev, k = rng.uniform(-50, 50, 2), int(rng.integers(1, 100))
        c_now = c_prev + rng.uniform(-3, 3, 2)
        A, U = cell_transition(c_now - c_prev, HESS)
        # values ~1: 1e-13 is round-off; the model is exact for quadratic-in-space, linear-in-time fields
        assert np.allclose(A @ state(c_prev, k) + U, state(c_now, k + 1), rtol=0, atol=1e-13)


def test_measurement_model_is_exact_for_the_polynomial_solution() -> None:
    rng = np.random.default_rng(1)
    before = rng.uniform(-20, 20, (4, 2))
    after = before + rng.uniform(-2, 2, (4, 2))
    centre, k = before.mean(axis=0), 7
    C, D = cell_measurement_matrices(before - centre, after - centre)
    measured = np.concatenate([z(before, k - 1.0), z(after, float(k))])
    assert np.allclose(C @ state(centre, k) + D @ hessian_to_vec(HESS), measured, rtol=0, atol=1e-13)


def test_hessian_fits() -> None:
    rng = np.random.default_rng(2)
    before = rng.uniform(-20, 20, (3, 2))  # a triangle: 6 offsets determine the 3 Hessian entries
    C, D = cell_measurement_matrices(
        before - before.mean(0), before + rng.uniform(-2, 2, (3, 2)) - before.mean(0)
    )
    exact = D @ hessian_to_vec(HESS)
    assert np.allclose(
        fit_hessian(D, exact, HessianOptions(method="least_squares")), hessian_to_vec(HESS), atol=1e-15
    )
    residual = exact + 0.01 * rng.standard_normal(6)
    ridge = fit_hessian(D, residual, HessianOptions(method="ridge", ridge=50.0))
    # independent: ridge regression as least squares on the augmented system [D; √ε₀ I] h = [r; 0]
    augmented = np.linalg.lstsq(
        np.vstack([D, np.sqrt(50.0) * np.eye(4)]), np.concatenate([residual, np.zeros(4)])
    )[0]
    assert np.allclose(ridge, augmented, rtol=1e-10, atol=1e-15)
    assert ridge[1] == pytest.approx(ridge[2], rel=1e-12)  # symmetric


def test_projection_metric_decides_stability() -> None:
    """Steady-state error map of a static cell with the projection fed back (Zhang et al. (2023), eq. 28, uses x̃+).

    The paper's Euclidean projection (M = I) mixes values and gradients of different units and, at these
    settings in metres, makes the loop unstable (its stability depends on the length unit: docs/theory/distributed.md
    §10.2); the covariance-weighted one (M = P+) keeps it stable (our default).
    """
    positions, cells = paper_network()
    offsets = positions[cells[0]] - positions[cells[0]].mean(axis=0)
    C, D = cell_measurement_matrices(offsets, offsets)
    A, _ = cell_transition(np.zeros(2), np.zeros((2, 2)))
    W = OPTIONS.process_std.covariance()
    R = 1e-8 * D @ D.T + 0.158**2 * np.eye(len(C))
    prior = control.dare(A.T, C.T, W, R)[0]  # steady-state prior covariance (python-control)
    K = prior @ C.T @ np.linalg.inv(C @ prior @ C.T + R)
    posterior = (np.eye(6) - K @ C) @ prior
    G = np.array([0.05 - 1.0, -V[0], -V[1], 1.0, 0.0, 0.0])  # eq. 26 with θΔtS/A = 0.05, Δt = 1
    radius = {}
    for name, metric in (("euclidean", np.eye(6)), ("covariance", posterior)):
        projector = np.eye(6) - metric @ np.outer(G, G) / (G @ metric @ G)
        radius[name] = np.max(np.abs(np.linalg.eigvals(projector @ (np.eye(6) - K @ C) @ A)))
    unconstrained = np.max(np.abs(np.linalg.eigvals((np.eye(6) - K @ C) @ A)))
    assert radius["euclidean"] > 1.05  # measured 1.12
    assert radius["covariance"] <= unconstrained + 1e-9 < 1.0  # measured 0.87 = unconstrained


def _run(
    mesh: SensorMesh,
    start: np.ndarray,
    velocity: np.ndarray,
    steps: int,
    seed: int,
    sigma: float = 0.158,
    options: FilterOptions = OPTIONS,
    hess: np.ndarray = HESS,
):
    rng = np.random.default_rng(seed)
    network = DistributedFilter(mesh, options, sigma, PdeModel(THETA, V, 1.0))
    network.start(start, z(start, 0.0, hess) + sigma * rng.standard_normal(len(start)))
    errors = {True: [], False: []}
    for k in range(1, steps + 1):
        positions = start + velocity * k
        network.step(positions, z(positions, float(k), hess) + sigma * rng.standard_normal(len(start)))
        truth = z(mesh.centres(positions), float(k), hess)
        for constrained in (True, False):
            errors[constrained].append(network.estimates(constrained)[0] - truth)
    return network, {key: np.array(value) for key, value in errors.items()}


def test_unconstrained_chain_converges_on_noise_free_data_from_a_linear_field() -> None:
    """Linear field (the model is exact, the ridge Hessian ≈ 0), σ = 1e-6: the start error decays below σ.

    The plane-fit start (2e-4) decays with a time constant of ~15 steps; after 200 steps the rms error
    over the last 20 is 2.9e-7 (all seeds 0-3 alike): below σ by a margin of 3.
    """
    positions, cells = grid_network(2, 2, (40.0, 40.0), origin=(-40.0, -40.0))
    mesh = SensorMesh(cells, positions)
    flat = np.zeros((2, 2))
    _, errors = _run(mesh, positions, np.array([0.3, 0.2]), 200, seed=0, sigma=1e-6, hess=flat)
    assert np.max(np.abs(errors[False][0])) > 1e-4
    assert np.sqrt(np.mean(errors[False][-20:] ** 2)) < 1e-6


def test_a_step_before_start_is_refused() -> None:
    positions, cells = grid_network(2, 2, (40.0, 40.0), origin=(-40.0, -40.0))
    network = DistributedFilter(SensorMesh(cells, positions), OPTIONS, 0.1, PdeModel(THETA, V, 1.0))
    with pytest.raises(RuntimeError, match=r"update\(\) before start\(\)"):
        network.step(positions, z(positions, 0.0))


def test_cell_filter_matches_filterpy() -> None:
    """Algorithm 1 for one cell written again with filterpy's KalmanFilter and the tested building blocks."""
    from filterpy.kalman import KalmanFilter

    rng = np.random.default_rng(7)
    sigma = 0.05
    corners = np.array([[0.0, 0.0], [30.0, 0.0], [25.0, 28.0], [-3.0, 24.0]])
    mesh = SensorMesh([[0, 1, 2, 3]], corners)
    cell = CellFilter(0, mesh.edges(0), OPTIONS, sigma, PdeModel(THETA, V, 1.0))
    path = [corners + rng.uniform(-0.5, 0.5, 2) * k + 0.02 * k**1.5 for k in range(31)]
    data = [z(p, float(k)) + sigma * rng.standard_normal(4) for k, p in enumerate(path)]
    cell.start(path[0], data[0])

    plane = np.linalg.lstsq(np.column_stack([np.ones(4), path[0] - path[0].mean(0)]), data[0], rcond=None)[0]
    chains = []
    for _ in range(2):  # [constrained, unconstrained]
        kf = KalmanFilter(dim_x=6, dim_z=8)
        kf.x, kf.P, kf.Q, kf.B = (
            np.concatenate([plane, plane]),
            OPTIONS.initial_std.covariance(),
            OPTIONS.process_std.covariance(),
            np.eye(6),
        )
        chains.append(kf)
    hessians = [np.zeros((2, 2)), np.zeros((2, 2))]
    for k in range(1, 31):
        c_prev = path[k - 1].mean(0)
        C, D = cell_measurement_matrices(path[k - 1] - c_prev, path[k] - c_prev)
        p = np.concatenate([data[k - 1], data[k]])
        R = 1e-8 * D @ D.T + sigma**2 * np.eye(8)
        for chain, kf in enumerate(chains):
            if k > 1:
                A, U = cell_transition(c_prev - path[k - 2].mean(0), hessians[chain])
                kf.predict(u=U, F=A)
            vec_h = fit_hessian(D, p - C @ kf.x, OPTIONS.hessian)
            kf.update(p - D @ vec_h, R=R, H=C)
            hessians[chain] = vec_h.reshape(2, 2).T
        points, far = far_points(path[k - 1], data[k - 1], [None] * 4)
        G, g = pde_constraint(laplacian_stencil(path[k - 1], c_prev, points), data[k - 1], far, 1.0, THETA, V)
        shared = chains[0].x[0]  # ẑ+(c^{k−1}, k−1) before the projection goes to the neighbours
        chains[0].x = project(chains[0].x, G, g, chains[0].P)

        message = cell.update(path[k], data[k])
        cell.constrain({})
        assert np.allclose(message.centre, c_prev) and message.value == pytest.approx(shared, abs=1e-10)
        # the two implementations agree to round-off (states ~1, covariances ≥ 1e-8)
        assert np.allclose(cell.state, [chains[0].x, chains[1].x], rtol=0, atol=1e-10)
        assert np.allclose(cell.covariance, chains[0].P, rtol=1e-9, atol=1e-15)


@pytest.mark.slow
def test_constrained_filter_beats_unconstrained_with_a_consistent_constraint() -> None:
    """Square cells translating through the exact polynomial solution: G x = g holds for the truth.

    Over 5 seeds and 300 steps (after a 20-step transient) the constrained error std is below the
    unconstrained one in every cell; measured ratios 0.52-0.81.
    """
    positions, cells = grid_network(3, 3, (40.0, 40.0), origin=(-60.0, -60.0))
    mesh = SensorMesh(cells, positions)
    for seed in range(5):
        _, errors = _run(mesh, positions, np.array([0.3, 0.2]), 300, seed)
        ratio = errors[True][20:].std(axis=0) / errors[False][20:].std(axis=0)
        assert np.all(ratio < 0.95), (seed, ratio)


@pytest.mark.slow
def test_the_constraint_needs_the_right_advection() -> None:
    """The same run with a filter told v = 0 or −v: the constraint then misstates ∂z/∂t and the error grows.

    Measured overall rms errors (seed 0, 200 steps): 0.040 with v, 0.062 with 0, 0.091 with −v.
    """
    positions, cells = grid_network(3, 3, (40.0, 40.0), origin=(-60.0, -60.0))
    mesh = SensorMesh(cells, positions)
    rms = {}
    for label, told in (("right", V), ("none", np.zeros(2)), ("reversed", -V)):
        rng = np.random.default_rng(0)
        network = DistributedFilter(mesh, OPTIONS, 0.158, PdeModel(THETA, told, 1.0))
        network.start(positions, z(positions, 0.0) + 0.158 * rng.standard_normal(len(positions)))
        errors = []
        for k in range(1, 201):
            moved = positions + np.array([0.3, 0.2]) * k
            network.step(moved, z(moved, float(k)) + 0.158 * rng.standard_normal(len(moved)))
            errors.append(network.estimates(True)[0] - z(mesh.centres(moved), float(k)))
        rms[label] = np.sqrt(np.mean(np.square(errors[20:])))
    assert rms["right"] < 0.8 * rms["none"] < 0.8 * rms["reversed"], rms


def test_cells_compute_from_their_own_sensors_and_messages_only() -> None:
    positions, cells = grid_network(3, 1, (30.0, 30.0))
    mesh = SensorMesh(cells, positions)  # cells 0 - 1 - 2 in a row: 0 and 2 are not neighbours
    rng = np.random.default_rng(3)
    first = z(positions, 0.0) + 0.1 * rng.standard_normal(len(positions))
    second_positions = positions + 0.5
    second = z(second_positions, 1.0) + 0.1 * rng.standard_normal(len(positions))

    def one_step(measurements: np.ndarray) -> list[np.ndarray]:
        network = DistributedFilter(mesh, OPTIONS, 0.1, PdeModel(THETA, V, 1.0))
        network.start(positions, first)
        network.step(second_positions, measurements)
        return [cell.state for cell in network.cells]

    reference = one_step(second)
    far_sensor = next(i for i in mesh.cells[2] if i not in mesh.cells[1])  # a sensor of cell 2 only
    changed = second.copy()
    changed[far_sensor] += 1.0
    perturbed = one_step(changed)
    assert np.array_equal(perturbed[0], reference[0])  # cell 0 never sees cell 2's sensors
    assert not np.array_equal(perturbed[1][0], reference[1][0])  # cell 1 hears of it through cell 2's message
    assert np.array_equal(perturbed[1][1], reference[1][1])  # ... but its unconstrained chain does not


def test_a_missing_message_turns_the_edge_into_boundary() -> None:
    positions, cells = grid_network(2, 1, (30.0, 30.0))
    mesh = SensorMesh(cells, positions)
    cell = CellFilter(0, mesh.edges(0), OPTIONS, 0.1, PdeModel(THETA, V, 1.0))
    own = list(cell.sensors)
    cell.start(positions[own], z(positions[own], 0.0))
    cell.update(positions[own] + 0.2, z(positions[own] + 0.2, 1.0))
    before = cell.state[0]
    cell.constrain({})
    G, g = cell.last_constraint
    vertices, values = positions[own], z(positions[own], 0.0)
    points, far = far_points(vertices, values, [None] * 4)
    expected = pde_constraint(
        laplacian_stencil(vertices, vertices.mean(0), points), values, far, 1.0, THETA, V
    )
    assert np.allclose(G, expected[0]) and g == pytest.approx(expected[1])
    assert np.allclose(cell.state[0], project(before, G, g, cell.covariance))
