"""Cooperative Kalman filter for N ≥ 3 platforms in any shape (docs/theory/cooperative.md §2, case w = 0).

Three ways in, one set of equations (:mod:`mobisense.estimation.kalman`,
:mod:`mobisense.estimation.cooperative.information_model`):

* :class:`CooperativeKalmanFilter` — step by step (``predict`` then ``update``), for closed loops where
  positions and Hessian estimates are produced as the mission goes;
* :func:`run_cooperative_filter` — one shot over a recorded trajectory, returning a
  :class:`CooperativeFilterResult` (states, covariances, innovations; ``nees``; ``to_dataset``);
* both vectorised with the batch dimension first: positions ``(K, N, 2)`` shared by all Monte Carlo
  runs, or ``(B, K, N, 2)`` per run; measurements ``(K, N)`` or ``(B, K, N)``. With shared positions
  the covariance recursion (independent of the data) runs once for the whole batch.

The Hessian input ``Ĥ_{c,k}`` (docs/theory/cooperative.md, eq. cooperative.4) is either an array ``(..., K, 2, 2)``
(known or previously estimated), ``None`` (zero), or a :class:`HessianSource` called at each step (closed loop, e.g.
:class:`mobisense.estimation.cooperative.hessian.CurvatureHessian`). A single run with array Hessians is rolled out by a
CasADi function built from the same kernels (``engine="casadi"``, information form of eq. 17, JIT-compiled to C when a
compiler is available), 5-10x faster than filterpy stepping the same model (``benchmarks/bench_filters.py``).

Note: the state equation carries the second-order value term ``½ Δr' Ĥ Δr`` in ``h`` (see
:func:`~mobisense.estimation.cooperative.information_model.hessian_drift`), so it is exact on quadratic fields.

Example
-------
>>> import numpy as np
>>> from mobisense.estimation.cooperative.filter import run_cooperative_filter
>>> from mobisense.estimation.cooperative.information_model import cross_formation
>>> from mobisense.estimation.cooperative.noise_config import CooperativeNoise
>>> positions = cross_formation(1.0, 1.0, center=np.c_[np.linspace(0, 5, 6), np.zeros(6)])
>>> result = run_cooperative_filter(positions, np.zeros((6, 4)), CooperativeNoise.from_sigmas(0.1, 0.5, 0.0),
...                                 initial_state=np.zeros(3), initial_covariance=np.eye(3))
>>> result.states.shape
(6, 3)
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, Protocol

import numpy as np

from .. import kalman
from .information_model import (
    formation_center,
    hessian_drift,
    hessian_to_vec,
    taylor_matrices,
    transition_matrix,
)
from .noise_config import CooperativeNoise

__all__ = [
    "HessianSource",
    "CooperativeKalmanFilter",
    "CooperativeFilterResult",
    "run_cooperative_filter",
    "check_filter_inputs",
    "model_sequence",
]


class HessianSource(Protocol):
    """Closed-loop Hessian estimator called by the filter at every step after the prediction.

    ``__call__(positions, measurements, state_prior, covariance_prior, previous_hessian)`` receives
    positions ``(..., N, 2)``, measurements ``(..., N)``, the predicted state ``(..., 3)`` and covariance
    ``(..., 3, 3)`` at the new centre and the previous estimate ``(..., 2, 2)``; it returns ``Ĥ_{c,k}``
    with shape ``(..., 2, 2)``.
    """

    def __call__(
        self,
        positions: np.ndarray,
        measurements: np.ndarray,
        state_prior: np.ndarray,
        covariance_prior: np.ndarray,
        previous_hessian: np.ndarray,
    ) -> np.ndarray:
        """Return the Hessian estimate at the formation centre."""
        ...


@dataclass
class CooperativeFilterResult:
    """Output of :func:`run_cooperative_filter` (time axis after the batch axis).

    Attributes
    ----------
    positions : ndarray, shape (B, K, N, 2) or (K, N, 2)
    centers : ndarray, shape (B, K, 2) or (K, 2)
    states, states_prior : ndarray, shape (B, K, 3) or (K, 3)
        Posterior ``s_k(+)`` and predicted ``s_k(−)`` estimates of ``[z, ∂z/∂x, ∂z/∂y]`` at the centre.
    covariances, covariances_prior : ndarray, shape (B, K, 3, 3) or (K, 3, 3)
        ``P_k(+)``, ``P_k(−)``; unbatched when the positions are shared by all runs.
    innovations : ndarray, shape (B, K, N) or (K, N)
    innovation_covariances : ndarray, shape ([B,] K, N, N)
    hessians : ndarray, shape ([B,] K, 2, 2)
        The Hessian input used at each step.
    """

    positions: np.ndarray
    centers: np.ndarray
    states: np.ndarray
    states_prior: np.ndarray
    covariances: np.ndarray
    covariances_prior: np.ndarray
    innovations: np.ndarray
    innovation_covariances: np.ndarray
    hessians: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)

    def nees(self, true_states: np.ndarray) -> np.ndarray:
        """Normalised estimation error squared ``e' P(+)⁻¹ e`` per run and step, shape ``([B,] K)``."""
        error = self.states - np.asarray(true_states, dtype=float)
        return np.einsum("...i,...i->...", error, np.linalg.solve(self.covariances, error[..., None])[..., 0])

    def nis(self) -> np.ndarray:
        """Normalised innovation squared ``ν' S⁻¹ ν`` per run and step, shape ``([B,] K)``."""
        nu = self.innovations
        return np.einsum("...i,...i->...", nu, np.linalg.solve(self.innovation_covariances, nu[..., None])[..., 0])

    def to_dataset(self) -> Any:
        """The result as an ``xarray.Dataset`` (dimensions ``run, step, platform, state, state2, xy``)."""
        import xarray as xr

        batched = self.states.ndim == 3
        lead = ("run", "step") if batched else ("step",)

        def dims(array: np.ndarray, tail: tuple[str, ...]) -> tuple[str, ...]:
            return (lead if array.ndim - len(tail) == len(lead) else ("step",)) + tail

        state_names = ["z", "dz_dx", "dz_dy"]
        data = {
            "positions": (dims(self.positions, ("platform", "xy")), self.positions),
            "center": (dims(self.centers, ("xy",)), self.centers),
            "estimate": (lead + ("state",), self.states),
            "estimate_prior": (lead + ("state",), self.states_prior),
            "covariance": (dims(self.covariances, ("state", "state2")), self.covariances),
            "covariance_prior": (dims(self.covariances_prior, ("state", "state2")), self.covariances_prior),
            "innovation": (lead + ("platform",), self.innovations),
            "hessian": (dims(self.hessians, ("xy", "xy2")), self.hessians),
        }
        ds = xr.Dataset(
            data,
            coords={"state": state_names, "state2": state_names, "xy": ["x", "y"], "xy2": ["x", "y"]},
            attrs={k: str(v) for k, v in self.meta.items()},
        )
        ds["estimate"].attrs["long_name"] = "posterior estimate s(+) of [z, dz/dx, dz/dy] at the formation centre"
        return ds


class CooperativeKalmanFilter:
    """Step-by-step cooperative Kalman filter (docs/theory/cooperative.md §2), batched over leading dimensions.

    Parameters
    ----------
    noise : CooperativeNoise
        ``M``, ``R`` and ``U``.
    initial_state : ndarray, shape (..., 3)
        Prior estimate of ``[z, ∇z]`` at the centre of ``initial_positions``.
    initial_covariance : ndarray, shape (..., 3, 3)
        Its covariance.
    initial_positions : ndarray, shape (..., N, 2)
        Platform positions at the first measurement.
    initial_hessian : ndarray, shape (..., 2, 2), optional
        ``Ĥ`` before the first step (zero by default).

    Notes
    -----
    Call :meth:`update` at the initial positions first (there is no prediction before it), then
    :meth:`predict` and :meth:`update` at each new formation position.
    """

    def __init__(
        self,
        noise: CooperativeNoise,
        initial_state: np.ndarray,
        initial_covariance: np.ndarray,
        initial_positions: np.ndarray,
        initial_hessian: np.ndarray | None = None,
    ) -> None:
        self.noise = noise
        self.state = np.asarray(initial_state, dtype=float)[..., None]
        self.covariance = np.asarray(initial_covariance, dtype=float)
        self.positions = np.asarray(initial_positions, dtype=float)
        self.hessian = np.zeros((2, 2)) if initial_hessian is None else np.asarray(initial_hessian, dtype=float)
        if self.state.shape[-2] != 3 or self.covariance.shape[-2:] != (3, 3):
            raise ValueError(
                f"initial_state/initial_covariance: expected shapes (..., 3) and (..., 3, 3), "
                f"got {self.state.shape[:-1]} and {self.covariance.shape}"
            )

    def predict(self, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Move the estimate to the centre of ``positions`` ``(..., N, 2)`` (docs/theory/cooperative.md §2.1).

        Uses the current Hessian estimate for ``h_{k−1} = [½ Δr' Ĥ_{k−1} Δr; Ĥ_{k−1} Δr]`` (eq. cooperative.5:
        the paper's first-order ``[0; Ĥ Δr]`` plus the second-order value term). Returns the prior state
        ``(..., 3)`` and covariance ``(..., 3, 3)``.
        """
        positions = np.asarray(positions, dtype=float)
        shift = formation_center(positions) - formation_center(self.positions)
        u = hessian_drift(self.hessian, shift)[..., None]
        self.state, self.covariance = kalman.predict(
            self.state, self.covariance, transition_matrix(shift), self.noise.process, u
        )
        self.positions = positions
        return self.state[..., 0], self.covariance

    def update(self, measurements: np.ndarray, hessian: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Fuse the measurements ``p_k`` ``(..., N)`` taken at the current positions (eqs. 15-17).

        ``hessian`` ``(..., 2, 2)`` is ``Ĥ_{c,k}`` (kept for the next prediction); the current estimate
        is used when omitted. Returns the posterior state ``(..., 3)`` and covariance ``(..., 3, 3)``.
        """
        if hessian is not None:
            self.hessian = np.asarray(hessian, dtype=float)
        C, D = taylor_matrices(self.positions)
        y = np.asarray(measurements, dtype=float) - (D @ hessian_to_vec(self.hessian)[..., None])[..., 0]
        self.state, self.covariance, self.innovation, self.innovation_covariance = kalman.update(
            self.state, self.covariance, y[..., None], C, self.noise.total_measurement_covariance(D)
        )
        self.covariance = kalman.symmetrize(self.covariance)
        return self.state[..., 0], self.covariance


# ------------------------------------------------------------------------------------------ one shot
def check_filter_inputs(positions: np.ndarray, measurements: np.ndarray) -> None:
    """Raise ``ValueError`` unless positions are ``([B,] K, N, 2)`` and measurements ``([B,] K, N)``."""
    if positions.ndim < 3 or positions.shape[-1] != 2:
        raise ValueError(f"positions: expected shape ([B,] K, N, 2), got {positions.shape}")
    if measurements.shape[-2:] != positions.shape[-3:-1]:
        raise ValueError(
            f"measurements: expected shape ([B,] {positions.shape[-3]}, {positions.shape[-2]}) to match the "
            f"positions, got {measurements.shape}"
        )
    if positions.shape[-2] < 3:
        raise ValueError(
            f"positions: the cooperative filter needs N >= 3 platforms, got {positions.shape[-2]} "
            "(N = 2 needs a rotating formation and Hessian input from elsewhere; see docs/theory/cooperative.md §4)"
        )


def model_sequence(positions: np.ndarray, hessians: np.ndarray, noise: CooperativeNoise) -> dict[str, np.ndarray]:
    """Matrices of every step at once: ``F_k, u_k, Q_k, C_k, (D Ĥ)_k, (D U D' + R)_k``.

    Step 0 has ``F = I, u = 0, Q = 0`` so the first update fuses the initial prior directly.
    """
    centers = formation_center(positions)
    shifts = np.diff(centers, axis=-2, prepend=centers[..., :1, :])  # Δr_k = r_{c,k} − r_{c,k−1}, Δr_0 = 0
    previous_hessians = np.concatenate([hessians[..., :1, :, :], hessians[..., :-1, :, :]], axis=-3)
    C, D = taylor_matrices(positions)
    Q = np.broadcast_to(noise.process, shifts.shape[:-1] + (3, 3)).copy()
    Q[..., 0, :, :] = 0.0
    return {
        "F": transition_matrix(shifts),  # docs/theory/cooperative.md, eq. cooperative.5
        # h_{k−1}, docs/theory/cooperative.md, eq. cooperative.5
        "u": hessian_drift(previous_hessians, shifts)[..., None],
        "Q": Q,
        "C": C,
        # D_k Ĥ_{c,k}, docs/theory/cooperative.md, eq. cooperative.4
        "DH": (D @ hessian_to_vec(hessians)[..., None])[..., 0],
        "R": noise.total_measurement_covariance(D),
        "centers": centers,
    }


def _rollout_numpy(model: dict[str, np.ndarray], measurements: np.ndarray, x0: np.ndarray, P0: np.ndarray) -> dict:
    K = measurements.shape[-2]
    state_batch = np.broadcast_shapes(measurements.shape[:-2], x0.shape[:-1], model["C"].shape[:-3], P0.shape[:-2])
    covariance_batch = np.broadcast_shapes(model["C"].shape[:-3], P0.shape[:-2])  # data-independent recursion
    x = np.broadcast_to(x0, state_batch + (3,))[..., None]
    P = np.broadcast_to(P0, covariance_batch + (3, 3))
    out: dict[str, list[np.ndarray]] = {k: [] for k in ("xm", "Pm", "x", "P", "nu", "S")}
    for k in range(K):
        x, P = kalman.predict(x, P, model["F"][..., k, :, :], model["Q"][..., k, :, :], model["u"][..., k, :, :])
        out["xm"].append(x[..., 0])
        out["Pm"].append(P)
        y = (measurements[..., k, :] - model["DH"][..., k, :])[..., None]
        x, P, nu, S = kalman.update(x, P, y, model["C"][..., k, :, :], model["R"][..., k, :, :])
        P = kalman.symmetrize(P)
        for name, value in (("x", x[..., 0]), ("P", P), ("nu", nu[..., 0]), ("S", S)):
            out[name].append(value)
    axis_of = {"xm": -2, "x": -2, "nu": -2, "Pm": -3, "P": -3, "S": -3}
    return {k: np.stack(v, axis=axis_of[k]) for k, v in out.items()}


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
        jit_options = {"flags": ["-O2"], "verbose": False, "directory": _jit_directory()}
        options = {"jit": True, "compiler": "shell", "jit_options": jit_options}
        try:
            return ca.Function("cooperative_steps", inputs, outputs, options)
        except RuntimeError:  # compiler present but unusable: fall back to the virtual machine
            pass
    return ca.Function("cooperative_steps", inputs, outputs)


@functools.lru_cache(maxsize=1)
def _jit_directory() -> str:
    """The user's private folder for CasADi's JIT sources and objects (never the working directory).

    CasADi deletes its files when the compiled function is released; only a killed process leaves some,
    in the system's temporary folder rather than in the user's project.
    """
    import getpass
    import tempfile

    folder = Path(tempfile.gettempdir()) / f"mobisense-jit-{getpass.getuser()}"
    folder.mkdir(mode=0o700, exist_ok=True)
    return str(folder) + os.sep


@functools.lru_cache(maxsize=16)
def _compiled_rollout(n_chunks: int) -> Any:
    """``mapaccum`` of :func:`_rollout_body` over ``n_chunks`` calls, accumulating ``(x, P)``."""
    return _rollout_body().mapaccum("cooperative_rollout", n_chunks, 2)


def _hstack(array: np.ndarray) -> np.ndarray:
    """``(K, n, m)`` matrices → ``[X_0, X_1, …]`` of shape ``(n, K·m)``, CasADi's layout for mapped inputs."""
    K, n, m = array.shape
    return np.transpose(array, (1, 0, 2)).reshape(n, K * m)


def _rollout_casadi(model: dict[str, np.ndarray], measurements: np.ndarray, x0: np.ndarray, P0: np.ndarray) -> dict:
    K = measurements.shape[0]
    y = (measurements - model["DH"])[..., None]
    J, j = kalman.information_contribution(y, model["C"], model["R"])
    x_first, P_first = kalman.information_update(x0[:, None], P0, J[0], j[0])  # step 0: no prediction
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
    # priors, innovations and their covariances for all steps at once, with the same kernels
    x_prev = np.concatenate([x0[None], x[:-1]])[..., None]
    P_prev = np.concatenate([P0[None], P[:-1]])
    xm, Pm = kalman.predict(x_prev, P_prev, model["F"], model["Q"], model["u"])
    nu, S = kalman.innovation(xm, Pm, y, model["C"], model["R"])
    return {"x": x, "P": P, "xm": xm[..., 0], "Pm": Pm, "nu": nu[..., 0], "S": S}


def run_cooperative_filter(
    positions: np.ndarray,
    measurements: np.ndarray,
    noise: CooperativeNoise,
    initial_state: np.ndarray,
    initial_covariance: np.ndarray,
    hessians: np.ndarray | HessianSource | None = None,
    engine: Literal["auto", "numpy", "casadi"] = "auto",
    initial_hessian: np.ndarray | None = None,
) -> CooperativeFilterResult:
    """Run the cooperative Kalman filter over a trajectory (docs/theory/cooperative.md §2, eqs. cooperative.6–9).

    Parameters
    ----------
    positions : ndarray, shape (K, N, 2) or (B, K, N, 2)
        Platform positions at each measurement time (L); shared by all runs when 3-D.
    measurements : ndarray, shape (K, N) or (B, K, N)
        ``p_{i,k}`` (field unit).
    noise : CooperativeNoise
        ``M, R, U``.
    initial_state : ndarray, shape (3,) or (B, 3)
        Prior of ``[z, ∇z]`` at the first formation centre.
    initial_covariance : ndarray, shape (3, 3) or (B, 3, 3)
    hessians : ndarray, shape ([B,] K, 2, 2), HessianSource or None
        ``Ĥ_{c,k}``: given, estimated in the loop, or zero.
    engine : {"auto", "numpy", "casadi"}
        ``casadi`` compiles the whole rollout (single run, array Hessians only); ``auto`` picks it for
        a single run and numpy otherwise.
    initial_hessian : ndarray, shape ([B,] 2, 2), optional
        Closed loop only: the previous estimate ``Hᵖ`` handed to the source at the first step (zero by
        default). The curvature method keeps the part of ``Hᵖ`` a single snapshot cannot observe.

    Returns
    -------
    CooperativeFilterResult
    """
    positions = np.asarray(positions, dtype=float)
    measurements = np.asarray(measurements, dtype=float)
    check_filter_inputs(positions, measurements)
    x0 = np.asarray(initial_state, dtype=float)
    P0 = np.asarray(initial_covariance, dtype=float)
    closed_loop = hessians is not None and callable(hessians)
    single = measurements.ndim == 2 and positions.ndim == 3 and x0.ndim == 1 and P0.ndim == 2
    if engine == "auto":
        engine = "casadi" if single and not closed_loop else "numpy"
    if engine == "casadi" and (closed_loop or not single):
        raise ValueError("engine='casadi' needs a single run (2-D measurements) and array Hessians")
    if closed_loop:
        H0 = np.zeros((2, 2)) if initial_hessian is None else np.asarray(initial_hessian, dtype=float)
        return _run_closed_loop(positions, measurements, noise, x0, P0, hessians, H0)
    hessian_array = np.zeros(positions.shape[:-2] + (2, 2)) if hessians is None else np.asarray(hessians, float)
    model = model_sequence(positions, hessian_array, noise)
    roll = _rollout_casadi if engine == "casadi" else _rollout_numpy
    out = roll(model, measurements, x0, P0)
    return CooperativeFilterResult(
        positions=positions, centers=model["centers"], states=out["x"], states_prior=out["xm"],
        covariances=out["P"], covariances_prior=out["Pm"], innovations=out["nu"],
        innovation_covariances=out["S"], hessians=hessian_array, meta={"engine": engine},
    )  # fmt: skip


def _run_closed_loop(
    positions: np.ndarray,
    measurements: np.ndarray,
    noise: CooperativeNoise,
    x0: np.ndarray,
    P0: np.ndarray,
    source: HessianSource,
    initial_hessian: np.ndarray,
) -> CooperativeFilterResult:
    K = measurements.shape[-2]
    batch = np.broadcast_shapes(measurements.shape[:-2], positions.shape[:-3], x0.shape[:-1], P0.shape[:-2])
    x0 = np.broadcast_to(x0, batch + (3,))
    H0 = np.broadcast_to(initial_hessian, batch + (2, 2))
    filt = CooperativeKalmanFilter(noise, x0, P0, positions[..., 0, :, :], H0)
    keys = ("xm", "Pm", "x", "P", "nu", "S", "H")
    out: dict[str, list[np.ndarray]] = {k: [] for k in keys}
    for k in range(K):
        if k == 0:
            xm, Pm = filt.state[..., 0], filt.covariance
        else:
            xm, Pm = filt.predict(positions[..., k, :, :])
        H = source(positions[..., k, :, :], measurements[..., k, :], xm, Pm, filt.hessian)
        x, P = filt.update(measurements[..., k, :], H)
        for name, value in zip(
            keys, (xm, Pm, x, P, filt.innovation[..., 0], filt.innovation_covariance, H), strict=True
        ):
            out[name].append(np.broadcast_to(value, batch + value.shape[len(value.shape) - _core_ndim(name) :]))
    stacked = {k: np.stack(v, axis=len(batch)) for k, v in out.items()}
    return CooperativeFilterResult(
        positions=positions, centers=formation_center(positions), states=stacked["x"],
        states_prior=stacked["xm"], covariances=stacked["P"], covariances_prior=stacked["Pm"],
        innovations=stacked["nu"], innovation_covariances=stacked["S"], hessians=stacked["H"],
        meta={"engine": "numpy", "hessian_source": type(source).__name__},
    )  # fmt: skip


def _core_ndim(name: str) -> int:
    return 1 if name in ("xm", "x", "nu") else 2
