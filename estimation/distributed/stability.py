"""Linearised error map of the distributed constrained filter (Zhang et al. (2023), eqs. 28–35) and its spectral radius.

For frozen geometry (each cell's sensors at ``prev`` at step k−1 and ``now`` at step k, repeated) and the
steady-state gain ``K_j`` of each cell's Riccati recursion (the projection leaves the covariance alone, as
in :mod:`mobisense.estimation.distributed.filter`), one step maps the prior errors ``e⁻_j`` (6 per cell) of the
constrained chains as follows, for a truth that satisfies the model (noise-free part):

    Hessian fit   e_H = −L C e⁻,            L = (D'D + ε₀I)⁻¹D' (eq. 19) or D⁺ (eq. 18)
    update        e⁺ = (I − K (I − D L) C) e⁻                         (eqs. 30-31)
    message       the neighbours receive e⁺_n[0]
    projection    ẽ_j = e⁺_j − m_j (G_j e⁺_j − Σ_s c_js e⁺_{n(s)}[0]),  m_j = M G'/(G M G')   (eqs. 34-35)
    prediction    e⁻_j(k+1) = A ẽ_j + B_U e_H   (U = [h; h], h = [½Δr'ĤΔr, ĤΔr])

with ``c_js = θΔt b_s/A`` the weight of the neighbour's centre value in ``ĝ`` and ``M = I`` (eq. 34) or ``P+``.
The spectral radius of this ``6n × 6n`` map equals the measured growth rate of a simulated error to 4
digits (tests). Eq. 34's metric is not invariant under a change of the length unit; the covariance metric is
(docs/theory/distributed.md §10.2). :func:`translating_mesh_errors` runs the filter on a mesh translating
through a known field, for measuring the constraint's benefit (docs/theory/distributed.md §10.1).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy.linalg import solve_discrete_are

from ..cooperative.information_model import vec_to_hessian
from .filter import DistributedFilter, FilterOptions, PdeModel, cell_measurement_matrices, cell_transition
from .fvm import far_points, laplacian_stencil, pde_constraint
from .mesh import SensorMesh

__all__ = ["steady_gain", "error_map", "spectral_radius", "rescale_length_unit", "translating_mesh_errors"]


def steady_gain(A: np.ndarray, C: np.ndarray, W: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state gain and posterior covariance of ``x_{k+1} = A x_k + w_k``, ``y_k = C x_k + v_k``.

    Parameters
    ----------
    A : ndarray, shape (n, n)
    C : ndarray, shape (m, n)
    W, R : ndarray, shapes (n, n) and (m, m)
        Process and measurement noise covariances (SPD).

    Returns
    -------
    K : ndarray, shape (n, m)
        Gain applied to the prior: ``x⁺ = x⁻ + K (y − C x⁻)``.
    P_plus : ndarray, shape (n, n)
        Posterior covariance ``(I − K C) P⁻``, with ``P⁻`` the stabilising solution of the filter's DARE.
    """
    P_minus = solve_discrete_are(A.T, C.T, W, R)
    K = np.linalg.solve(C @ P_minus @ C.T + R, C @ P_minus).T
    return K, (np.eye(len(A)) - K @ C) @ P_minus


def error_map(
    prev: np.ndarray,
    now: np.ndarray,
    cells: Sequence[Sequence[int]],
    options: FilterOptions,
    measurement_std: float,
    diffusivity: float,
    velocity: Sequence[float],
    time_step: float = 1.0,
    metric: str | None = None,
) -> np.ndarray:
    """The ``6n × 6n`` map of the constrained chains' prior errors over one step (module docstring).

    Parameters
    ----------
    prev, now : ndarray, shape (N, 2)
        Sensor positions at steps k−1 and k (L); ``now = prev + Δr`` for a translating mesh.
    cells : sequence of sequences of int
    options : FilterOptions
        ``metric`` defaults to ``options.projection``.
    measurement_std : float
    diffusivity, velocity, time_step : the PDE the constraint assumes and Δt.
    """
    metric = options.projection if metric is None else metric
    prev, now = np.asarray(prev, float), np.asarray(now, float)
    mesh = SensorMesh(cells, prev)
    centres = mesh.centres(prev)
    n = mesh.n_cells
    W = options.process_std.covariance()
    Q = options.hessian.error_std**2 * np.eye(4)
    update = np.zeros((6 * n, 6 * n))
    proj = np.eye(6 * n)
    predict = np.zeros((6 * n, 6 * n))
    hessian_term = np.zeros((6 * n, 6 * n))
    for j, cell in enumerate(mesh.cells):
        p0, p1 = prev[list(cell)], now[list(cell)]
        c0 = p0.mean(axis=0)
        shift = p1.mean(axis=0) - c0
        A, _ = cell_transition(shift, np.zeros((2, 2)))
        C, D = cell_measurement_matrices(p0 - c0, p1 - c0)
        R = D @ Q @ D.T + measurement_std**2 * np.eye(len(C))
        if options.hessian.method == "ridge":
            L = np.linalg.solve(D.T @ D + options.hessian.ridge * np.eye(4), D.T)
        else:
            L = np.linalg.pinv(D)
        K, P_plus = steady_gain(A, C, W, R)
        BU = np.zeros((6, 4))
        for q in range(4):
            H = vec_to_hessian(np.eye(4)[q])
            h = np.concatenate([[0.5 * shift @ H @ shift], H @ shift])
            BU[:, q] = np.concatenate([h, h])
        sl = slice(6 * j, 6 * j + 6)
        update[sl, sl] = np.eye(6) - K @ (np.eye(len(C)) - D @ L) @ C
        predict[sl, sl] = A
        hessian_term[sl, sl] = BU @ L @ C
        edges = mesh.edges(j)
        across = [None if e.neighbour is None else (centres[e.neighbour], 0.0) for e in edges]
        points, _ = far_points(p0, np.zeros(len(p0)), across)
        stencil = laplacian_stencil(p0, c0, points)
        zeros = np.zeros(len(p0))
        G, _ = pde_constraint(stencil, zeros, zeros, time_step, diffusivity, np.asarray(velocity, float))
        M = np.eye(6) if metric == "euclidean" else P_plus
        m = M @ G / (G @ M @ G)
        proj[sl, sl] -= np.outer(m, G)
        weight = diffusivity * time_step / stencil.area
        for s, e in enumerate(edges):
            if e.neighbour is not None:
                proj[sl, 6 * e.neighbour] += m * weight * stencil.centre_weights[s]
    return predict @ proj @ update - hessian_term


def spectral_radius(T: np.ndarray) -> float:
    """``max |eig(T)|``: errors grow if > 1."""
    return float(np.max(np.abs(np.linalg.eigvals(T))))


def rescale_length_unit(options: FilterOptions, factor: float) -> FilterOptions:
    """The same filter with the length unit multiplied by ``factor`` (new unit = factor × old unit)."""
    o = options.model_copy(deep=True)
    o.process_std.gradient *= factor
    o.initial_std.gradient *= factor
    o.hessian.ridge /= factor**4
    o.hessian.error_std *= factor**2
    return o


def translating_mesh_errors(
    positions: np.ndarray,
    cells: Sequence[Sequence[int]],
    options: FilterOptions,
    measurement_std: float,
    pde: PdeModel,
    truth: Callable[[np.ndarray, float], np.ndarray],
    velocity: Sequence[float],
    steps: int,
    seed: int = 0,
) -> dict[str, np.ndarray]:
    """Errors of both chains of the distributed filter on a mesh translating through a known field.

    Parameters
    ----------
    positions : ndarray, shape (N, 2)
        Sensor positions at step 0 (L); at step k they are ``positions + k Δt velocity``.
    cells : sequence of sequences of int
    options : FilterOptions
    measurement_std : float
        σ of the white measurement noise (field unit).
    pde : PdeModel
        The constraint's θ, v and Δt.
    truth : callable
        ``truth(points (M, 2), t) -> (M,)``, the field.
    velocity : sequence of float
        Mesh velocity (L/T).
    steps : int
    seed : int

    Returns
    -------
    dict
        ``"constrained"`` and ``"unconstrained"``: value errors at the cell centres, shape (steps, n_cells).
    """
    positions = np.asarray(positions, float)
    shift = pde.time_step * np.asarray(velocity, float)
    mesh = SensorMesh(cells, positions)
    rng = np.random.default_rng(seed)
    network = DistributedFilter(mesh, options, measurement_std, pde)
    noise = lambda: measurement_std * rng.standard_normal(len(positions))  # noqa: E731
    network.start(positions, truth(positions, 0.0) + noise())
    errors: dict[str, list[np.ndarray]] = {"constrained": [], "unconstrained": []}
    for k in range(1, steps + 1):
        p, t = positions + shift * k, k * pde.time_step
        network.step(p, truth(p, t) + noise())
        centre_truth = truth(mesh.centres(p), t)
        for name in errors:
            errors[name].append(network.estimates(name == "constrained")[0] - centre_truth)
    return {name: np.array(e) for name, e in errors.items()}
