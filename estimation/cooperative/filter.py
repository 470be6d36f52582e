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

import importlib.util
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import numpy as np

from .. import kalman
from ..checks import check_finite_array
from .information_model import (
    formation_center,
    hessian_drift,
    hessian_to_vec,
    taylor_matrices,
    transition_matrix,
)
from .noise_config import CooperativeNoise
from .rollouts import (
    OUTPUTS,
    check_measurement,
    check_prior,
    measurement_is_regular,
    prior_is_regular,
    process_is_regular,
    rollout_casadi,
    rollout_components,
    rollout_shared,
)

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
    states : ndarray, shape (B, K, 3) or (K, 3)
        Posterior estimates ``s_k(+)`` of ``[z, ∂z/∂x, ∂z/∂y]`` at the centre.
    covariances : ndarray, shape (B, K, 3, 3) or (K, 3, 3)
        ``P_k(+)``; unbatched when the positions are shared by all runs.
    hessians : ndarray, shape ([B,] K, 2, 2)
        The Hessian input used at each step.
    states_prior, covariances_prior : ndarray or None
        Predicted ``s_k(−)`` (shape of ``states``) and ``P_k(−)`` (shape of ``covariances``); None when
        the filter ran with ``outputs="posterior"``.
    innovations : ndarray, shape (B, K, N) or (K, N), or None
    innovation_covariances : ndarray, shape ([B,] K, N, N), or None
    meta : dict
        ``engine``, ``rollout`` and ``outputs`` used.

    Notes
    -----
    The arrays of the numpy engine are views of its time-major storage (not C-contiguous): copy one
    (``np.ascontiguousarray``) before handing it to code that needs contiguous memory.
    """

    positions: np.ndarray
    centers: np.ndarray
    states: np.ndarray
    covariances: np.ndarray
    hessians: np.ndarray
    states_prior: np.ndarray | None = None
    covariances_prior: np.ndarray | None = None
    innovations: np.ndarray | None = None
    innovation_covariances: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def nees(self, true_states: np.ndarray) -> np.ndarray:
        """Normalised estimation error squared ``e' P(+)⁻¹ e`` per run and step, shape ``([B,] K)``."""
        error = self.states - np.asarray(true_states, dtype=float)
        return np.einsum("...i,...i->...", error, np.linalg.solve(self.covariances, error[..., None])[..., 0])

    def nis(self) -> np.ndarray:
        """Normalised innovation squared ``ν' S⁻¹ ν`` per run and step, shape ``([B,] K)``."""
        if self.innovations is None or self.innovation_covariances is None:
            raise ValueError("nis: this result has no innovations (the filter ran with outputs='posterior')")
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
        tails = {
            "positions": (self.positions, ("platform", "xy")),
            "center": (self.centers, ("xy",)),
            "estimate": (self.states, ("state",)),
            "estimate_prior": (self.states_prior, ("state",)),
            "covariance": (self.covariances, ("state", "state2")),
            "covariance_prior": (self.covariances_prior, ("state", "state2")),
            "innovation": (self.innovations, ("platform",)),
            "hessian": (self.hessians, ("xy", "xy2")),
        }
        data = {name: (dims(a, tail), a) for name, (a, tail) in tails.items() if a is not None}
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
        ``M``, ``R`` and ``U`` (may be replaced between steps: the attribute is read at every step).
    initial_state : ndarray, shape (..., 3)
        Prior estimate of ``[z, ∇z]`` at the centre of ``initial_positions``.
    initial_covariance : ndarray, shape (..., 3, 3)
        Its covariance.
    initial_positions : ndarray, shape (..., N, 2)
        Platform positions at the first measurement.
    initial_hessian : ndarray, shape (..., 2, 2), optional
        ``Ĥ`` before the first step (zero by default).
    backend : {"auto", "numba", "numpy"}
        ``numpy`` evaluates the kernels of :mod:`mobisense.estimation.kalman` on arrays (any batch shape);
        ``numba`` runs each step as one compiled call (a single filter only: state ``(3,)``, positions
        ``(N, 2)``; needs ``pip install mobisense[fast]``), ≈ 15x faster per step
        (:mod:`~mobisense.estimation.cooperative.step_kernels`, equal to round-off); ``auto`` picks numba
        for a single filter when it is installed, numpy otherwise. The chosen one is ``self.backend``.

    Notes
    -----
    Call :meth:`update` at the initial positions first (there is no prediction before it), then
    :meth:`predict` and :meth:`update` at each new formation position. Each step makes new arrays:
    what :meth:`predict` returned is still the prior after :meth:`update`.

    Any N >= 1 is accepted, unlike :func:`run_cooperative_filter` (N >= 3): observability is a property of a
    window of steps (docs/theory/cooperative.md §4, Cd5), and the step API runs pairs (N = 2) that rotate. A
    formation that cannot see the gradient at one instant (one platform, collinear or coincident platforms)
    leaves the unobserved directions of ``P`` at their prior, so the covariance says what is not known;
    motion of the centre observes the gradient along it. N may change between steps (the estimate moves to
    the centre of the positions given). The constructor refuses a prior that is not finite and symmetric
    positive semidefinite (a singular one, e.g. a known initial value, is fine); each step checks shapes only.
    """

    def __init__(
        self,
        noise: CooperativeNoise,
        initial_state: np.ndarray,
        initial_covariance: np.ndarray,
        initial_positions: np.ndarray,
        initial_hessian: np.ndarray | None = None,
        backend: Literal["auto", "numba", "numpy"] = "auto",
    ) -> None:
        self.noise = noise
        self.state = check_finite_array("initial_state", initial_state, "(..., 3)", lambda s: s[-1:] == (3,))[..., None]
        check_prior(initial_covariance)  # finite, symmetric positive semidefinite (..., 3, 3): once, not per step
        self.covariance = np.asarray(initial_covariance, dtype=float)
        self.positions = check_finite_array("initial_positions", initial_positions, "(..., N, 2) with N >= 1",
                                            lambda s: len(s) >= 2 and s[-1] == 2 and s[-2] >= 1)  # fmt: skip
        self.hessian = np.zeros((2, 2)) if initial_hessian is None else check_finite_array(
            "initial_hessian", initial_hessian, "(..., 2, 2)", lambda s: s[-2:] == (2, 2)
        )  # fmt: skip
        single = (
            self.state.shape == (3, 1) and self.covariance.shape == (3, 3) and self.positions.ndim == 2
            and self.hessian.shape == (2, 2)
        )  # fmt: skip
        self.backend = _step_backend(backend, single)
        self._compiled: tuple[Any, Any] | None = None
        if self.backend == "numba":
            from .step_kernels import predict_step, update_step

            self._compiled = (predict_step, update_step)
        self._R0: tuple[CooperativeNoise, np.ndarray] | None = None

    def predict(self, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Move the estimate to the centre of ``positions`` ``(..., N, 2)`` (docs/theory/cooperative.md §2.1).

        Uses the current Hessian estimate for ``h_{k−1} = [½ Δr' Ĥ_{k−1} Δr; Ĥ_{k−1} Δr]`` (eq. cooperative.5:
        the paper's first-order ``[0; Ĥ Δr]`` plus the second-order value term). Returns the prior state
        ``(..., 3)`` and covariance ``(..., 3, 3)``.
        """
        positions = np.asarray(positions, dtype=float)
        shape = positions.shape
        if len(shape) < 2 or shape[-1] != 2 or not shape[-2]:  # shapes only (hot path: ~60 ns of a ~4 µs step)
            raise ValueError(f"positions: expected shape (..., N, 2) with N >= 1, got {shape}")
        if self._compiled is not None:
            x, P = np.empty((3, 1)), np.empty((3, 3))
            self._compiled[0](self.state, self.covariance, self.positions, positions, self.hessian,
                              self.noise.process, x, P)  # fmt: skip
            self.state, self.covariance, self.positions = x, P, positions
            return x[:, 0], P
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
        measurements = np.asarray(measurements, dtype=float)
        if hessian is not None:
            self.hessian = np.asarray(hessian, dtype=float)
        if self._compiled is not None:
            return self._update_compiled(measurements)  # which checks the shapes
        if measurements.shape[-1:] != self.positions.shape[-2:-1]:  # shapes only: hot path
            raise ValueError(
                f"measurements: expected shape (..., {self.positions.shape[-2]}), one per platform, "
                f"got {measurements.shape}"
            )
        C, D = taylor_matrices(self.positions)
        y = measurements - (D @ hessian_to_vec(self.hessian)[..., None])[..., 0]
        self.state, self.covariance, self.innovation, self.innovation_covariance = kalman.update(
            self.state, self.covariance, y[..., None], C, self.noise.total_measurement_covariance(D)
        )
        self.covariance = kalman.symmetrize(self.covariance)
        return self.state[..., 0], self.covariance

    def _update_compiled(self, measurements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        N = self.positions.shape[0]
        if measurements.shape != (N,) or self.hessian.shape != (2, 2):
            name, expected, got = (
                ("measurements", f"({N},), one per platform", measurements.shape) if measurements.shape != (N,)
                else ("hessian", "(2, 2)", self.hessian.shape)
            )  # fmt: skip
            raise ValueError(
                f"{name}: expected shape {expected} (backend 'numba' filters a single run; use backend='numpy' for "
                f"batches), got {got}"
            )
        if self._R0 is None or self._R0[0] is not self.noise or self._R0[1].shape[0] != N:
            self._R0 = (self.noise, np.ascontiguousarray(self.noise.measurement_matrix(N)))
        x, P, nu, S = np.empty((3, 1)), np.empty((3, 3)), np.empty((N, 1)), np.empty((N, N))
        self._compiled[1](self.state, self.covariance, self.positions, measurements, self.hessian,
                          self.noise.hessian_error, self._R0[1], x, P, nu, S)  # fmt: skip
        self.state, self.covariance, self.innovation, self.innovation_covariance = x, P, nu, S
        return x[:, 0], P


def _step_backend(backend: str, single: bool) -> str:
    """The step backend to use: numba for a single filter when available (``auto``), else numpy."""
    if backend not in ("auto", "numba", "numpy"):
        raise ValueError(f"backend: expected 'auto', 'numba' or 'numpy', got {backend!r}")
    if backend == "numba":
        if not single:
            raise ValueError("backend 'numba' filters a single run (state (3,), positions (N, 2)); use 'numpy'")
        if importlib.util.find_spec("numba") is None:
            raise ImportError("backend 'numba' needs numba: pip install 'mobisense[fast]'")
        return "numba"
    return "numba" if backend == "auto" and single and importlib.util.find_spec("numba") is not None else "numpy"


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


def run_cooperative_filter(
    positions: np.ndarray,
    measurements: np.ndarray,
    noise: CooperativeNoise,
    initial_state: np.ndarray,
    initial_covariance: np.ndarray,
    hessians: np.ndarray | HessianSource | None = None,
    engine: Literal["auto", "numpy", "casadi"] = "auto",
    initial_hessian: np.ndarray | None = None,
    outputs: Literal["all", "posterior"] = "all",
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
        a single run and numpy otherwise. With numpy, positions and covariance shared by all runs run
        the covariance recursion once and the states by eq. cooperative.16; otherwise every run is
        filtered with its own covariances, all runs at once (:mod:`~mobisense.estimation.cooperative.rollouts`).
    initial_hessian : ndarray, shape ([B,] 2, 2), optional
        Closed loop only: the previous estimate ``Hᵖ`` handed to the source at the first step (zero by
        default). The curvature method keeps the part of ``Hᵖ`` a single snapshot cannot observe.
    outputs : {"all", "posterior"}
        ``posterior`` keeps only the states and covariances ``s(+)``, ``P(+)`` (priors and innovations
        are None): less memory, and 2–4x faster for large batches.

    Returns
    -------
    CooperativeFilterResult
    """
    positions = np.asarray(positions, dtype=float)
    measurements = np.asarray(measurements, dtype=float)
    check_filter_inputs(positions, measurements)
    if outputs not in OUTPUTS:
        raise ValueError(f"outputs: expected one of {OUTPUTS}, got {outputs!r}")
    x0 = np.asarray(initial_state, dtype=float)
    P0 = np.asarray(initial_covariance, dtype=float)
    closed_loop = hessians is not None and callable(hessians)
    single = measurements.ndim == 2 and positions.ndim == 3 and x0.ndim == 1 and P0.ndim == 2
    check_prior(P0)
    # the compiled rollout is in information form: a singular prior needs a positive definite M after step 0,
    # and the measurements' weight (DUD' + R)⁻¹ a regular R
    informative = (prior_is_regular(P0) or process_is_regular(noise.process)) and measurement_is_regular(
        noise.measurement
    )
    if engine == "auto":
        engine = "casadi" if single and not closed_loop and informative else "numpy"
    if engine == "casadi" and (closed_loop or not single):
        raise ValueError("engine='casadi' needs a single run (2-D measurements) and array Hessians")
    if closed_loop:
        H0 = np.zeros((2, 2)) if initial_hessian is None else np.asarray(initial_hessian, dtype=float)
        return _run_closed_loop(positions, measurements, noise, x0, P0, hessians, H0)
    hessian_array = np.zeros(positions.shape[:-2] + (2, 2)) if hessians is None else np.asarray(hessians, float)
    if engine == "casadi":
        check_prior(P0, noise.process)
        check_measurement(noise.measurement)
    if engine == "casadi" or (positions.ndim == 3 and P0.ndim == 2):
        model = model_sequence(positions, hessian_array, noise)
        roll, rollout = (rollout_casadi, "compiled") if engine == "casadi" else (rollout_shared, "shared")
        out = roll(model, measurements, x0, P0, outputs)
        centers = model["centers"]
    else:
        check_prior(P0, noise.process)  # the per-run rollout is in information form
        check_measurement(noise.measurement)
        out = rollout_components(positions, hessian_array, noise, measurements, x0, P0, outputs)
        centers, rollout = out["centers"], "components"
    return CooperativeFilterResult(
        positions=positions, centers=centers, states=out["x"], covariances=out["P"], hessians=hessian_array,
        states_prior=out.get("xm"), covariances_prior=out.get("Pm"), innovations=out.get("nu"),
        innovation_covariances=out.get("S"), meta={"engine": engine, "rollout": rollout, "outputs": outputs},
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
        meta={"engine": "numpy", "rollout": "closed loop", "outputs": "all", "hessian_source": type(source).__name__},
    )  # fmt: skip


def _core_ndim(name: str) -> int:
    return 1 if name in ("xm", "x", "nu") else 2
