"""Rollouts of the cooperative Kalman filter over a recorded trajectory (docs/theory/cooperative.md §2.4).

Three ways to run the same kernels (:mod:`mobisense.estimation.kalman`) over K steps, chosen by
:func:`~mobisense.estimation.cooperative.filter.run_cooperative_filter`:

* :func:`rollout_shared` — positions shared by every run (numpy engine). The covariance recursion and the
  gains do not depend on the data, so they run once (K small steps, eqs. cooperative.6–8); each step of
  the batch is then the affine map of eq. cooperative.16, ``X ← A_k X + K_k Y_k + c_k`` on a ``(3, B)``
  block (two BLAS products per step for all runs).
* :func:`rollout_components` — one trajectory per run (numpy engine). Every matrix is a
  :class:`~mobisense.estimation.components.ComponentMatrix` whose entries are contiguous ``(K, B)``
  arrays: the measurement information of eq. cooperative.9 for all steps and runs at once, then the
  information-form recursion with one numpy operation per scalar formula over all runs.
* :func:`rollout_casadi` — a single run, compiled: :func:`kalman.predict` + :func:`kalman.information_update`
  as a CasADi function, JIT-compiled to C when a compiler is available.

Outputs are dicts of arrays with the batch first: ``x`` (…, K, 3), ``P`` ([…,] K, 3, 3) and, with
``outputs="all"``, the priors ``xm``, ``Pm``, the innovations ``nu`` (…, K, N) and their covariances
``S``. The arrays of the numpy rollouts are views of time-major storage (not C-contiguous).
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Any

import numpy as np

from .. import kalman
from ..components import ComponentMatrix
from .information_model import hessian_drift, hessian_to_vec, taylor_matrices, transition_matrix
from .noise_config import CooperativeNoise

__all__ = [
    "rollout_shared",
    "component_model",
    "rollout_components",
    "rollout_casadi",
    "prior_is_regular",
    "process_is_regular",
    "check_prior",
    "measurement_is_regular",
    "check_measurement",
    "OUTPUTS",
]

#: what a rollout returns: the posterior only, or also priors and innovations
OUTPUTS = ("all", "posterior")


def _columns(array: np.ndarray, batch: tuple[int, ...]) -> np.ndarray:
    """``(*batch, K, n)`` (broadcast) → ``(K, n, B)`` time-major columns, contiguous."""
    flat = np.broadcast_to(array, batch + array.shape[-2:]).reshape((-1,) + array.shape[-2:])
    return np.ascontiguousarray(np.transpose(flat, (1, 2, 0)))


def _batch_first(columns: np.ndarray, batch: tuple[int, ...]) -> np.ndarray:
    """``(K, n, [m,] B)`` time-major storage → ``(*batch, K, n[, m])`` view."""
    moved = np.moveaxis(columns, -1, 0)
    return moved.reshape(batch + moved.shape[1:])


def rollout_shared(
    model: dict[str, np.ndarray], measurements: np.ndarray, x0: np.ndarray, P0: np.ndarray, outputs: str = "all"
) -> dict[str, np.ndarray]:
    """Runs sharing one trajectory: covariances and gains once, then eq. cooperative.16 for all runs.

    Parameters
    ----------
    model : dict
        :func:`~mobisense.estimation.cooperative.filter.model_sequence` of the shared positions ``(K, N, 2)``
        (``u`` and ``DH`` may carry a batch of per-run Hessians).
    measurements : ndarray, shape (..., K, N)
    x0 : ndarray, shape (..., 3)
    P0 : ndarray, shape (3, 3)
    outputs : {"all", "posterior"}
    """
    F, Q, C, R = model["F"], model["Q"], model["C"], model["R"]
    K = C.shape[0]
    # covariance recursion and gains: data-independent, one run (docs/theory/cooperative.md, eqs. cooperative.6-8)
    P_prior, P_post, S_all, gains = (np.empty((K,) + s) for s in ((3, 3), (3, 3), R.shape[1:], (3, C.shape[1])))
    P = P0
    zero = np.zeros((3, 1))
    for k in range(K):
        _, P = kalman.predict(zero, P, F[k], Q[k])  # step 0: F = I, Q = 0
        P_prior[k] = P
        _, S_all[k] = kalman.innovation(zero, P, zero[:1], C[k], R[k])
        gains[k] = kalman.gain(P, C[k], S_all[k])
        P = P_post[k] = kalman.symmetrize(kalman.joseph_covariance(P, gains[k], C[k], R[k]))
    A, b = kalman.state_map(F, model["u"], gains, C)  # docs/theory/cooperative.md, eq. cooperative.16
    bias = b - gains @ model["DH"][..., None]  # y = p − D vec Ĥ: the known part enters through the bias
    batch = np.broadcast_shapes(measurements.shape[:-2], x0.shape[:-1], model["DH"].shape[:-2])
    n_runs = int(np.prod(batch, dtype=int))
    # time-major measurements (K, N, B): the transposed view is a BLAS operand as it is
    Y = np.broadcast_to(measurements, batch + measurements.shape[-2:]).reshape((n_runs,) + measurements.shape[-2:])
    Yt = np.transpose(Y, (1, 2, 0))
    c = _columns(bias[..., 0], batch) if bias.ndim > 3 else bias  # (K, 3, B) or (K, 3, 1)
    X = np.empty((K, 3, n_runs))
    x = np.broadcast_to(x0, batch + (3,)).reshape(n_runs, 3).T
    work = np.empty((3, n_runs))
    for k in range(K):  # x_k = A_k x_{k-1} + K_k p_k + c_k
        np.matmul(A[k], x, out=X[k])
        np.matmul(gains[k], Yt[k], out=work)
        X[k] += work
        X[k] += c[k]
        x = X[k]
    out = {"x": _batch_first(X, batch), "P": P_post}
    if outputs == "all":
        X_prev = np.concatenate([np.broadcast_to(x0, batch + (3,)).reshape(n_runs, 3).T[None], X[:-1]])
        P_prev = np.concatenate([P0[None], P_post[:-1]])
        u = _columns(model["u"][..., 0], batch) if model["u"].ndim > 3 else model["u"]
        Xm, _ = kalman.predict(X_prev, P_prev, F, Q, u)
        DH = _columns(model["DH"], batch) if model["DH"].ndim > 2 else model["DH"][..., None]
        nu, _ = kalman.innovation(Xm, P_prior, Yt - DH, C, R)
        out.update(xm=_batch_first(Xm, batch), Pm=P_prior, nu=_batch_first(nu, batch), S=S_all)
    return out


def component_model(positions: np.ndarray, hessians: np.ndarray, noise: CooperativeNoise) -> dict[str, Any]:
    """:func:`~mobisense.estimation.cooperative.filter.model_sequence` as component matrices of ``(K, B)`` entries.

    Parameters
    ----------
    positions : ndarray, shape (B, K, N, 2)
    hessians : ndarray, shape (B or 1, K, 2, 2)
    noise : CooperativeNoise

    Returns
    -------
    dict
        ``F`` (3, 3), ``u`` (3, 1), ``C`` (N, 3), ``DH`` (N, 1), ``R`` (N, N): component matrices, the
        same functions of :mod:`~mobisense.estimation.cooperative.information_model` evaluated entry by entry.
    """
    p = np.ascontiguousarray(np.transpose(positions, (2, 3, 1, 0)))  # (N, 2, K, B): entries contiguous
    points = ComponentMatrix([[p[i, 0], p[i, 1]] for i in range(p.shape[0])])
    C, D = taylor_matrices(points)
    center = np.mean(p, axis=0)  # (2, K, B), docs/theory/cooperative.md §1.1
    shift = np.zeros_like(center)
    shift[:, 1:] = center[:, 1:] - center[:, :-1]  # Δr_k, Δr_0 = 0
    shift_col = ComponentMatrix([[shift[0]], [shift[1]]])
    H = np.moveaxis(np.asarray(hessians, dtype=float), 0, 1)  # (K, B or 1, 2, 2)
    H_prev = np.concatenate([H[:1], H[:-1]])
    vec = hessian_to_vec(ComponentMatrix.from_array(H))
    return {
        "centers": np.transpose(center, (2, 1, 0)),  # (B, K, 2) view
        "F": transition_matrix(shift_col),
        "u": hessian_drift(ComponentMatrix.from_array(H_prev), shift_col),  # eq. cooperative.5 with Ĥ_{k-1}
        "C": C,
        "DH": D @ vec,  # D_k vec(Ĥ_k), docs/theory/cooperative.md, eq. cooperative.4
        "R": noise.total_measurement_covariance(D),
    }


def _store(out: np.ndarray, k: int, M: ComponentMatrix) -> None:
    for i, row in enumerate(M.rows):
        for j, e in enumerate(row):
            out[k, i, j] = e


def rollout_components(
    positions: np.ndarray,
    hessians: np.ndarray,
    noise: CooperativeNoise,
    measurements: np.ndarray,
    x0: np.ndarray,
    P0: np.ndarray,
    outputs: str = "all",
) -> dict[str, np.ndarray]:
    """Runs with their own trajectories (or covariances): information form over component matrices.

    Parameters
    ----------
    positions : ndarray, shape ([...,] K, N, 2)
    hessians : ndarray, shape ([...,] K, 2, 2)
    noise : CooperativeNoise
    measurements : ndarray, shape ([...,] K, N)
    x0 : ndarray, shape ([...,] 3)
    P0 : ndarray, shape ([...,] 3, 3)
    outputs : {"all", "posterior"}
    """
    K, N = positions.shape[-3:-1]
    batch = np.broadcast_shapes(
        positions.shape[:-3], hessians.shape[:-3], measurements.shape[:-2], x0.shape[:-1], P0.shape[:-2]
    )
    n_runs = int(np.prod(batch, dtype=int))

    def flat(a: np.ndarray, core: int) -> np.ndarray:
        return np.broadcast_to(a, batch + a.shape[a.ndim - core :]).reshape((n_runs,) + a.shape[a.ndim - core :])

    model = component_model(flat(positions, 3), hessians[None] if hessians.ndim == 3 else flat(hessians, 3), noise)
    Y = ComponentMatrix([[e] for e in np.ascontiguousarray(np.transpose(flat(measurements, 2), (2, 1, 0)))])
    Y = Y - model["DH"]  # y = p − D vec Ĥ, (N, 1) entries (K, B)
    J, j = kalman.information_contribution(Y, model["C"], model["R"])  # all steps and runs at once
    Q = ComponentMatrix.from_array(noise.process, constant=True)
    x = ComponentMatrix.from_array(flat(x0, 1)[..., None])  # entries (B,)
    regular = prior_is_regular(P0)
    P = ComponentMatrix.from_array(flat(P0, 2))
    X, P_out = np.empty((K, 3, 1, n_runs)), np.empty((K, 3, 3, n_runs))
    keep = outputs == "all"
    if keep:
        Xm, Pm = np.empty((K, 3, 1, n_runs)), np.empty((K, 3, 3, n_runs))
    F, u = model["F"], model["u"]
    for k in range(K):
        if k:  # step 0 fuses the prior directly
            x, P = kalman.predict(x, P, F.index(k), Q, u.index(k))  # docs/theory/cooperative.md, eq. cooperative.6
        if keep:
            _store(Xm, k, x)
            _store(Pm, k, P)
        if k or regular:
            x, P = kalman.information_update(
                x, P, J.index(k), j.index(k)
            )  # docs/theory/cooperative.md, eq. cooperative.9
        else:  # a prior with a known direction has no information form: fused by the covariance form
            x, P, _, _ = kalman.update(x, P, Y.index(0), model["C"].index(0), model["R"].index(0))
        _store(X, k, x)
        _store(P_out, k, P)
    centers = model["centers"]
    out = {"x": _batch_first(X[:, :, 0], batch), "P": _batch_first(P_out, batch),
           "centers": centers.reshape(batch + centers.shape[1:])}  # fmt: skip
    if keep:
        x_prior = ComponentMatrix([[Xm[:, i, 0]] for i in range(3)])
        P_prior = ComponentMatrix([[Pm[:, i, m] for m in range(3)] for i in range(3)])
        nu, S = kalman.innovation(x_prior, P_prior, Y, model["C"], model["R"])
        batch_shape = (K, n_runs)
        out.update(
            xm=_batch_first(Xm[:, :, 0], batch), Pm=_batch_first(Pm, batch),
            nu=_batch_first(np.moveaxis(nu.to_array(batch_shape)[..., 0], 1, -1), batch),
            S=_batch_first(np.moveaxis(S.to_array(batch_shape), 1, -1), batch),
        )  # fmt: skip
    return out


def prior_is_regular(P0: np.ndarray) -> bool:
    """True when every prior covariance ``P0`` (shape ``([...,] 3, 3)``) is positive definite to working precision.

    The information-form update ``P⁺ = (P⁻¹ + J)⁻¹`` needs ``P⁻¹``; a prior that knows a direction exactly (a
    zero eigenvalue, e.g. a known initial value) is fused by the covariance form instead. Later priors are
    ``F P⁺ F' + M``: positive definite when ``M`` is (:func:`check_prior`).
    """
    P = np.asarray(P0, dtype=float)
    eigenvalues = np.linalg.eigvalsh(0.5 * (P + np.swapaxes(P, -1, -2)))
    return bool(np.all(eigenvalues[..., 0] > 1e-14 * eigenvalues[..., -1]))


def process_is_regular(process: np.ndarray) -> bool:
    """True when the process noise ``M`` is positive definite (every prior after step 0 is then invertible)."""
    return bool(np.linalg.eigvalsh(0.5 * (process + process.T))[0] > 0)


def measurement_is_regular(measurement: np.ndarray | float) -> bool:
    """True when ``R`` (scalar, (N,) or (N, N)) is positive definite to working precision.

    The information-form rollouts weight the measurements by ``(DUD' + R)⁻¹``; ``D`` has rank ≤ 3 (two of its
    four columns are equal), so with a singular ``R`` (a platform measuring without noise) that matrix is
    singular for some formation, and for every one with N > 3.
    """
    R = np.asarray(measurement, dtype=float)
    if R.ndim < 2:
        return bool(np.all(R > 0))
    eigenvalues = np.linalg.eigvalsh(0.5 * (R + R.T))
    return bool(eigenvalues[0] > 1e-14 * eigenvalues[-1])


def check_measurement(measurement: np.ndarray | float) -> None:
    """Raise ``ValueError`` unless the information-form rollouts can weight the measurements (``R`` regular)."""
    if not measurement_is_regular(measurement):
        raise ValueError(
            "measurement covariance R: singular (a platform measuring without noise): the information-form "
            "rollouts need DUD' + R positive definite (engine='numpy' with positions shared by all runs, or "
            "CooperativeKalmanFilter, run the covariance form)"
        )


def check_prior(P0: np.ndarray, process: np.ndarray | None = None) -> None:
    """Raise ``ValueError`` unless ``P0`` is symmetric positive semidefinite (and, with ``process``, usable).

    With the process noise ``M`` (``process``), also unless the information-form rollouts can run from it: a
    singular ``P0`` (a direction known exactly) is fused at step 0 by the covariance form, after which
    ``F P⁺ F' + M`` is invertible only if ``M`` is positive definite.
    """
    P = np.asarray(P0, dtype=float)
    if P.shape[-2:] != (3, 3):
        raise ValueError(f"initial_covariance: expected ([B,] 3, 3) matrices, got shape {P.shape}")
    if not np.all(np.isfinite(P)):
        raise ValueError(f"initial_covariance: expected finite numbers, got {P.size - np.isfinite(P).sum()} non-finite")
    eigenvalues = np.linalg.eigvalsh(0.5 * (P + np.swapaxes(P, -1, -2)))
    scale = np.maximum(1.0, np.abs(P).max(axis=(-1, -2)))
    if np.any(np.abs(P - np.swapaxes(P, -1, -2)) > 1e-12 * scale[..., None, None]) or np.any(
        eigenvalues[..., 0] < -1e-12 * scale
    ):
        raise ValueError(
            "initial_covariance: expected symmetric positive semidefinite matrices, smallest eigenvalue "
            f"{float(eigenvalues[..., 0].min()):g}"
        )
    if process is not None and not prior_is_regular(P) and not process_is_regular(process):
        raise ValueError(
            "initial_covariance: singular, and the process noise M is singular too: the information-form "
            "rollouts need one of them positive definite (engine='numpy' with positions shared by all runs, or "
            "CooperativeKalmanFilter, run the covariance form)"
        )


# ------------------------------------------------------------------------------------------ compiled
#: steps per call of the compiled rollout's body (amortises CasADi's per-call overhead)
_UNROLL = 8


@functools.lru_cache(maxsize=1)
def _rollout_body() -> Any:
    """:func:`kalman.predict` + :func:`kalman.information_update` for ``_UNROLL`` steps, as a CasADi function.

    Only 3 × 3 algebra is left in the sequential part: the transition is built from ``Δr`` (structural
    zeros), ``M`` is a constant parameter, and the measurement information ``J_k, j_k`` of all steps is
    computed beforehand (numpy, vectorised over time). The function is compiled to machine code once
    per process when a C compiler is on the PATH (CasADi's JIT, ~1 s); otherwise CasADi's virtual
    machine evaluates it (about 3x slower, same results).
    """
    import shutil

    import casadi as ca

    x, P, M = ca.SX.sym("x", 3), ca.SX.sym("P", 3, 3), ca.SX.sym("M", 3, 3)
    dr, u = ca.SX.sym("dr", 2, _UNROLL), ca.SX.sym("u", 3, _UNROLL)
    J, j = ca.SX.sym("J", 3, 3 * _UNROLL), ca.SX.sym("j", 3, _UNROLL)
    xs, Ps = [], []
    xk, Pk = x, P
    for i in range(_UNROLL):
        xk, Pk = kalman.predict(xk, Pk, transition_matrix(dr[:, i]), M, u[:, i])
        xk, Pk = kalman.information_update(xk, Pk, J[:, 3 * i : 3 * i + 3], j[:, i])
        xs.append(xk)
        Ps.append(Pk)
    inputs, outputs = [x, P, dr, u, J, j, M], [xk, Pk, ca.horzcat(*xs), ca.horzcat(*Ps)]
    if shutil.which("gcc") or shutil.which("cc"):
        jit_options = {"flags": ["-O2"], "verbose": False, "directory": jit_directory()}
        options = {"jit": True, "compiler": "shell", "jit_options": jit_options}
        try:
            return ca.Function("cooperative_steps", inputs, outputs, options)
        except RuntimeError:  # compiler present but unusable: fall back to the virtual machine
            pass
    return ca.Function("cooperative_steps", inputs, outputs)


@functools.lru_cache(maxsize=16)
def _compiled_rollout(n_chunks: int) -> Any:
    """``mapaccum`` of :func:`_rollout_body` over ``n_chunks`` calls, accumulating ``(x, P)``."""
    return _rollout_body().mapaccum("cooperative_rollout", n_chunks, 2)


def _hstack(array: np.ndarray) -> np.ndarray:
    """``(K, n, m)`` matrices → ``[X_0, X_1, …]`` of shape ``(n, K·m)``, CasADi's layout for mapped inputs."""
    K, n, m = array.shape
    return np.transpose(array, (1, 0, 2)).reshape(n, K * m)


def rollout_casadi(
    model: dict[str, np.ndarray], measurements: np.ndarray, x0: np.ndarray, P0: np.ndarray, outputs: str = "all"
) -> dict[str, np.ndarray]:
    """A single run (measurements ``(K, N)``, ``x0`` (3,), ``P0`` (3, 3)) by the compiled rollout."""
    K = measurements.shape[0]
    y = (measurements - model["DH"])[..., None]
    J, j = kalman.information_contribution(y, model["C"], model["R"])
    if prior_is_regular(P0):  # step 0: no prediction
        x_first, P_first = kalman.information_update(x0[:, None], P0, J[0], j[0])
    else:  # a prior with a known direction has no information form: fused by the covariance form
        x_first, P_first, _, _ = kalman.update(x0[:, None], P0, y[0], model["C"][0], model["R"][0])
    n_chunks = max(1, -(-(K - 1) // _UNROLL))
    pad = n_chunks * _UNROLL - (K - 1)  # trailing steps without information, discarded

    def padded(a: np.ndarray) -> np.ndarray:
        return np.concatenate([a[1:], np.zeros((pad,) + a.shape[1:])])

    shifts = model["F"][:, 0, 1:]  # Δr_k from A_k = [[1, Δr'], [0, I]]
    res = _compiled_rollout(n_chunks)(
        x_first, P_first, padded(shifts).T, padded(model["u"][..., 0]).T, _hstack(padded(J)),
        padded(j[..., 0]).T, model["Q"][-1],
    )  # fmt: skip
    x = np.concatenate([x_first.T, np.asarray(res[2]).T[: K - 1]])
    P_all = np.transpose(np.asarray(res[3]).reshape(3, n_chunks * _UNROLL, 3), (1, 0, 2))  # (3, ·3) → (·, 3, 3)
    P = np.concatenate([P_first[None], P_all[: K - 1]])
    out = {"x": x, "P": P}
    if outputs == "all":  # priors, innovations and their covariances for all steps at once, same kernels
        x_prev = np.concatenate([x0[None], x[:-1]])[..., None]
        P_prev = np.concatenate([P0[None], P[:-1]])
        xm, Pm = kalman.predict(x_prev, P_prev, model["F"], model["Q"], model["u"])
        nu, S = kalman.innovation(xm, Pm, y, model["C"], model["R"])
        out.update(xm=xm[..., 0], Pm=Pm, nu=nu[..., 0], S=S)
    return out


@functools.lru_cache(maxsize=1)
def jit_directory() -> str:
    """The user's private folder for CasADi's JIT sources and objects (never the working directory).

    CasADi deletes its files when the compiled function is released; only a killed process leaves some,
    in the system's temporary folder rather than in the user's project.
    """
    import getpass
    import tempfile

    folder = Path(tempfile.gettempdir()) / f"mobisense-jit-{getpass.getuser()}"
    folder.mkdir(mode=0o700, exist_ok=True)
    return str(folder) + os.sep
