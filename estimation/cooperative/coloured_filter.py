"""Cooperative Kalman filter with spatially correlated ("coloured") measurement noise (docs/theory/cooperative.md §3).

The noise ``w_k = w(r_{i,k})`` of a static random field sampled along the platform trajectories is
modelled as first-order Markov, ``w_k = A^w w_{k−1} + η`` with ``A^w = V_k W_{k−1}⁻¹`` and
``Q^w = W_k − A^w W_{k−1} A^w'`` (docs/theory/cooperative.md, eq. cooperative.11, :meth:`SpatialNoise.markov`).
Two methods:

``augmented`` (default)
    State ``[s; w]`` of size ``3 + N``, measurement ``p = [C, I] [s; w] + D Ĥ + D e + n``: an exact
    Kalman filter for the Markov model.
``differenced``
    Bryson–Henrikson: ``p̄_k = p_k − A^w p_{k−1} = (C_k A_{k−1} − A^w C_{k−1}) s_{k−1} + b_k + ν̄_k`` with
    ``b_k = C_k h_{k−1} + D_k Ĥ_k − A^w D_{k−1} Ĥ_{k−1}`` and
    ``ν̄_k = C_k ε_{k−1} + η_{k−1} + v_k − A^w v_{k−1}`` (``v = D e + n``), docs/theory/cooperative.md,
    eq. cooperative.13. The noise of ``p̄_k`` is correlated with the process noise ``ε_{k−1}``; this is handled exactly
    by updating the pair ``(s_{k−1}, ε_{k−1})`` and then propagating. Its covariance adds ``Q^w`` to
    Zhang & Leonard (2010), eq. 19 (which omits η). The one approximation left is the paper's: ``v_{k−1}`` also enters
    ``p̄_{k−1}``, a correlation the method ignores (exact when ``U = 0`` and ``R → 0``).

Both return a :class:`~mobisense.estimation.cooperative.filter.CooperativeFilterResult` for ``s`` and are batched
like :func:`~mobisense.estimation.cooperative.filter.run_cooperative_filter`.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from .. import kalman
from .filter import CooperativeFilterResult, check_filter_inputs
from .information_model import (
    formation_center,
    hessian_drift,
    hessian_to_vec,
    taylor_matrices,
    transition_matrix,
)
from .noise_config import CooperativeNoise
from .spatial_noise import SpatialNoise

__all__ = ["run_coloured_filter"]


def _block_diag(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    batch = np.broadcast_shapes(A.shape[:-2], B.shape[:-2])
    n, m = A.shape[-1], B.shape[-1]
    out = np.zeros(batch + (n + m, n + m))
    out[..., :n, :n] = A
    out[..., n:, n:] = B
    return out


def run_coloured_filter(
    positions: np.ndarray,
    measurements: np.ndarray,
    noise: CooperativeNoise,
    spatial_noise: SpatialNoise,
    initial_state: np.ndarray,
    initial_covariance: np.ndarray,
    hessians: np.ndarray | None = None,
    method: Literal["augmented", "differenced"] = "augmented",
) -> CooperativeFilterResult:
    """Cooperative Kalman filter for ``p = C s + D Ĥ + w + D e + n``, correlated ``w`` (docs/theory/cooperative.md §3).

    Parameters
    ----------
    positions : ndarray, shape ([B,] K, N, 2)
    measurements : ndarray, shape ([B,] K, N)
    noise : CooperativeNoise
        ``M``, ``R`` (white part ``n``) and ``U``.
    spatial_noise : SpatialNoise
        Covariance kernel of ``w`` (gives ``W_k``, ``V_k``).
    initial_state : ndarray, shape ([B,] 3)
    initial_covariance : ndarray, shape ([B,] 3, 3)
    hessians : ndarray, shape ([B,] K, 2, 2), optional
        ``Ĥ_{c,k}`` (zero by default).
    method : {"augmented", "differenced"}

    Returns
    -------
    CooperativeFilterResult
        Estimates of ``s``; ``innovations`` are those of ``p`` (augmented) or ``p̄`` (differenced).
    """
    positions = np.asarray(positions, dtype=float)
    measurements = np.asarray(measurements, dtype=float)
    check_filter_inputs(positions, measurements)
    H = np.zeros(positions.shape[:-2] + (2, 2)) if hessians is None else np.asarray(hessians, dtype=float)
    if method not in ("augmented", "differenced"):
        raise ValueError(f"method: expected 'augmented' or 'differenced', got {method!r}")
    step = _augmented_steps if method == "augmented" else _differenced_steps
    out = step(positions, measurements, noise, spatial_noise, np.asarray(initial_state, float),
               np.asarray(initial_covariance, float), H)  # fmt: skip
    batch_axis = out["x"][0].ndim - 1
    stacked = {k: np.stack(v, axis=batch_axis if k in ("x", "xm", "nu") else v[0].ndim - 2) for k, v in out.items()}
    return CooperativeFilterResult(
        positions=positions, centers=formation_center(positions), states=stacked["x"], states_prior=stacked["xm"],
        covariances=stacked["P"], covariances_prior=stacked["Pm"], innovations=stacked["nu"],
        innovation_covariances=stacked["S"], hessians=H, meta={"engine": "numpy", "coloured_noise": method},
    )  # fmt: skip


def _step_model(positions: np.ndarray, hessians: np.ndarray, noise: CooperativeNoise, k: int) -> dict[str, np.ndarray]:
    """``C_k, D_k Ĥ_k, D U D' + R`` and, for k ≥ 1, ``A_{k−1}, h_{k−1}`` at step k."""
    pos = positions[..., k, :, :]
    C, D = taylor_matrices(pos)
    model = {
        "C": C,
        "DH": (D @ hessian_to_vec(hessians[..., k, :, :])[..., None])[..., 0],
        "R": noise.total_measurement_covariance(D),
    }
    if k > 0:
        shift = formation_center(pos) - formation_center(positions[..., k - 1, :, :])
        model["A"] = transition_matrix(shift)  # docs/theory/cooperative.md, eq. cooperative.5
        model["h"] = hessian_drift(hessians[..., k - 1, :, :], shift)[..., None]
    return model


def _augmented_steps(
    positions: np.ndarray,
    measurements: np.ndarray,
    noise: CooperativeNoise,
    spatial: SpatialNoise,
    x0: np.ndarray,
    P0: np.ndarray,
    H: np.ndarray,
) -> dict[str, list[np.ndarray]]:
    N = positions.shape[-2]
    out: dict[str, list[np.ndarray]] = {k: [] for k in ("x", "P", "xm", "Pm", "nu", "S")}
    batch = np.broadcast_shapes(measurements.shape[:-2], x0.shape[:-1])
    x = np.concatenate([np.broadcast_to(x0, batch + (3,)), np.zeros(batch + (N,))], axis=-1)[..., None]
    P = _block_diag(P0, spatial.W(positions[..., 0, :, :]))  # w_0 ~ N(0, W_0)
    for k in range(measurements.shape[-2]):
        m = _step_model(positions, H, noise, k)
        if k > 0:
            A_w, Q_w = spatial.markov(positions[..., k, :, :], positions[..., k - 1, :, :])
            F = _block_diag(m["A"], A_w)  # [s; w] dynamics, docs/theory/cooperative.md, eq. cooperative.12
            Q = _block_diag(np.broadcast_to(noise.process, A_w.shape[:-2] + (3, 3)), Q_w)
            u = np.concatenate([m["h"], np.zeros(m["h"].shape[:-2] + (N, 1))], axis=-2)
            x, P = kalman.predict(x, P, F, Q, u)
        out["xm"].append(x[..., :3, 0])
        out["Pm"].append(P[..., :3, :3])
        Haug = np.concatenate([m["C"], np.broadcast_to(np.eye(N), m["C"].shape[:-2] + (N, N))], axis=-1)
        y = (measurements[..., k, :] - m["DH"])[..., None]
        x, P, nu, S = kalman.update(x, P, y, Haug, m["R"])
        P = kalman.symmetrize(P)
        for name, value in (("x", x[..., :3, 0]), ("P", P[..., :3, :3]), ("nu", nu[..., 0]), ("S", S)):
            out[name].append(value)
    return out


def _differenced_steps(
    positions: np.ndarray,
    measurements: np.ndarray,
    noise: CooperativeNoise,
    spatial: SpatialNoise,
    x0: np.ndarray,
    P0: np.ndarray,
    H: np.ndarray,
) -> dict[str, list[np.ndarray]]:
    out: dict[str, list[np.ndarray]] = {k: [] for k in ("x", "P", "xm", "Pm", "nu", "S")}
    M = noise.process
    previous = None
    x, P = x0[..., None], P0
    for k in range(measurements.shape[-2]):
        m = _step_model(positions, H, noise, k)
        if k == 0:  # first measurement: w_0 ~ N(0, W_0) as white noise
            out["xm"].append(np.broadcast_to(x[..., 0], measurements.shape[:-2] + (3,)))
            out["Pm"].append(P)
            y = (measurements[..., 0, :] - m["DH"])[..., None]
            x, P, nu, S = kalman.update(x, P, y, m["C"], m["R"] + spatial.W(positions[..., 0, :, :]))
        else:
            A_w, Q_w = spatial.markov(positions[..., k, :, :], positions[..., k - 1, :, :])
            xm, Pm = kalman.predict(x, P, m["A"], M, m["h"])
            out["xm"].append(xm[..., 0])
            out["Pm"].append(Pm)
            # docs/theory/cooperative.md, eq. cooperative.13:
            # p̄_k = C̄ s_{k−1} + b_k + C_k ε_{k−1} + η + v_k − A^w v_{k−1}
            C_bar = m["C"] @ m["A"] - A_w @ previous["C"]
            b = (m["C"] @ m["h"])[..., 0] + m["DH"] - (A_w @ previous["DH"][..., None])[..., 0]
            p_bar = measurements[..., k, :] - (A_w @ measurements[..., k - 1, :, None])[..., 0]
            R_bar = Q_w + m["R"] + A_w @ previous["R"] @ np.swapaxes(A_w, -1, -2)  # eq. 19 plus Q^w
            # update the pair (s_{k−1}, ε_{k−1}), prior blockdiag(P, M), then s_k = [A, I] (s, ε) + h
            joint_x = np.concatenate([x, np.zeros(x.shape)], axis=-2)
            joint_P = _block_diag(P, np.broadcast_to(M, P.shape[:-2] + (3, 3)))
            joint_H = np.concatenate([C_bar, np.broadcast_to(m["C"], C_bar.shape)], axis=-1)
            joint_x, joint_P, nu, S = kalman.update(joint_x, joint_P, (p_bar - b)[..., None], joint_H, R_bar)
            T = np.concatenate([m["A"], np.broadcast_to(np.eye(3), m["A"].shape)], axis=-1)
            x = T @ joint_x + m["h"]
            P = T @ joint_P @ np.swapaxes(T, -1, -2)
        P = kalman.symmetrize(P)
        previous = m
        for name, value in (("x", x[..., 0]), ("P", P), ("nu", nu[..., 0]), ("S", S)):
            out[name].append(value)
    return out
