"""Direct-collocation transcription of the mobile-sensor Kalman problem into an NLP (docs/theory/direct.md §1).

The decision vector holds, interval by interval, the scaled covariance at the d collocation nodes, the
scaled controls there and the state the interval hands to the next (:mod:`mobisense.ocp.direct.kernels`:
Radau's duplicated end states are eliminated, the linear sensor dynamics are solved exactly, x̃_0 is a
parameter). Constraints: gap rows tying the intervals together, collocation equations of σ, control
bounds, fixed terminal states. Objective: ``(ε Tr[MΣ(tf)] + ∫ L) / cost_scale``. Every number is a
parameter (:class:`mobisense.ocp.model.ParameterLayout`), so the homotopy and sweeps re-solve one NLP,
whose exact derivatives are assembled from per-interval kernels (:mod:`mobisense.ocp.direct.assembly`),
compiled and cached on disk when a C compiler is available (:mod:`mobisense.ocp.direct.kernel_cache`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from ...core.interrupts import deferred_interrupts, raise_if_interrupted
from .. import collocation, model, noise_models, path_constraints, state_layout
from ..collocation import CollocationScheme
from ..model import SensorKalmanModel, Structure
from ..problem import Problem
from ..registries import NOISE_MODELS
from . import kernels as kernels_module
from .assembly import assemble, index_maps, with_step
from .iteration_limit import INTERRUPT_CHECK_VARIABLES, IterationLimit
from .kernel_cache import load_compiled, source_digest
from .kernels import IntervalKernels, condensing_matrices
from .numeric_calls import BufferedFunction, ParameterMemo

__all__ = [
    "DirectCollocation",
    "NLPResult",
    "IPOPT_DEFAULTS",
    "COLD_START",
    "WARM_START",
    "CODEGEN_MODES",
    "AUTO_COMPILE_INSTRUCTIONS",
    "transcription_for",
    "transcription_cache_hits",
    "clear_transcription_cache",
]

#: Ipopt options used by default: MUMPS without its matching-based permutation and scaling, AMD ordering
#: (fastest measured on these banded KKT systems) and a workspace of 20 % over MUMPS' estimate instead of
#: Ipopt's 1000 % (allocating 11x the estimate at every factorisation cost 1.3x per iteration).
IPOPT_DEFAULTS: dict[str, Any] = {
    "linear_solver": "mumps",
    "mumps_permuting_scaling": 0,
    "mumps_scaling": 0,
    "mumps_pivot_order": 0,
    "mumps_mem_percent": 20,
    "print_level": 0,
    "sb": "yes",
}

#: Extra options of a cold solve (from the coasting guess or a random start). Not adopted, measured on the 24
#: problems of benchmarks/bench_ocp_quality.py (benchmarks/RESULTS.md): ``obj_scaling_factor`` 100 cuts the cold
#: iterations by 30 % (median ÷ reference 1.12 → 0.92) but moves the cold and random starts to other local
#: optima, and strategy ``auto`` then misses the best optimum found by the candidates on 2 of the first 3.
COLD_START: dict[str, Any] = {"mu_init": 1e-2}

#: Extra options of warm-started solves (primal and dual variables supplied).
WARM_START: dict[str, Any] = {
    "warm_start_init_point": "yes",
    "mu_init": 1e-8,
    "warm_start_bound_push": 1e-9,
    "warm_start_bound_frac": 1e-9,
    "warm_start_slack_bound_push": 1e-9,
    "warm_start_slack_bound_frac": 1e-9,
    "warm_start_mult_bound_push": 1e-9,
}

#: ``solver.codegen``: compile the kernels ``on`` (always, waiting for the compiler on a cache miss), ``off``
#: (never) or ``auto`` (when small; a cache miss compiles in the background for the next run)
CODEGEN_MODES = ("auto", "on", "off")
#: ``auto`` compiles kernels up to this many SX instructions in all (n = 4, N = 4: 133 000, 12 s once)
AUTO_COMPILE_INSTRUCTIONS = 250_000


@dataclass
class NLPResult:
    """Raw result of one NLP solve (scaled decision vector and multipliers)."""

    w: np.ndarray
    lam_w: np.ndarray
    lam_g: np.ndarray
    objective: float
    status: str
    success: bool
    iterations: int
    time_s: float
    g: np.ndarray


class DirectCollocation:
    """The NLP for one problem structure and one grid; solve it for any parameter vector.

    Parameters
    ----------
    structure : Structure
        Problem structure (sizes, noise models, which terminal/bound constraints exist).
    scheme : {"radau", "legendre"}
    degree : int
        Collocation polynomial degree d.
    intervals : int
        Number of collocation intervals K (uniform).
    ipopt_options : dict, optional
        Overrides of :data:`IPOPT_DEFAULTS` (without the ``ipopt.`` prefix).
    tolerance : float
        Ipopt ``tol``.
    max_iterations : int
        Ipopt ``max_iter`` of each solve.
    codegen : {"auto", "on", "off"}
        Compile the interval kernels (cached on disk; ``auto`` compiles a cache miss in the background and
        evaluates them in the virtual machine meanwhile; see :mod:`mobisense.ocp.direct.kernel_cache`).
    """

    def __init__(
        self,
        structure: Structure,
        scheme: str = "radau",
        degree: int = 3,
        intervals: int = 100,
        ipopt_options: dict[str, Any] | None = None,
        tolerance: float = 1e-9,
        max_iterations: int = 500,
        codegen: str = "auto",
    ) -> None:
        t_build = time.perf_counter()
        if codegen not in CODEGEN_MODES:
            raise ValueError(f"codegen: expected one of {CODEGEN_MODES}, got {codegen!r}")
        self.structure = structure
        self.model = SensorKalmanModel(structure)
        self.layout = self.model.layout
        self.colloc = CollocationScheme(scheme, degree)
        self.intervals = K = intervals
        self.ipopt_options = {**IPOPT_DEFAULTS, "tol": tolerance, "max_iter": max_iterations, **(ipopt_options or {})}
        self.kernels = k = IntervalKernels(self.model, self.colloc, "eliminated")
        self.functions, self.kernel_mode = self._kernel_functions(codegen)
        self.maps = index_maps(k, K)
        self.nw = self.maps.nw
        nlp = assemble(k, self.functions, self.maps, K)
        self._nlp, self._derivatives, self.cost_terms, self.ng = nlp.nlp, nlp.derivatives, nlp.cost_terms, nlp.ng
        # numeric evaluations on numpy arrays, without CasADi's per-number conversions (numeric_calls.py)
        self._costs = BufferedFunction(self.cost_terms)
        self._nodes = BufferedFunction(k.k_nodes.map(K, "serial"))
        self._pv_gradient = BufferedFunction(k.k_pv.map(K, "serial"))
        self._scale_vectors = BufferedFunction(self.model.scales)
        self._path_scale = BufferedFunction(self.model.path_scale)
        self._x0_scaled = BufferedFunction(k.x0_scaled)
        self._solvers: dict[tuple[bool, bool], BufferedFunction] = {}
        self._limit: IterationLimit | None = None
        self._bounds = self._make_bounds()
        self._memo = ParameterMemo()  # scales, x̃_0 and the kernels' parameter input, per parameter vector
        self.build_time_s = time.perf_counter() - t_build

    def _kernel_functions(self, codegen: str) -> tuple[dict[str, ca.Function], str]:
        functions = self.kernels.functions
        size = sum(f.n_instructions() for f in functions.values())
        if codegen == "off" or (codegen == "auto" and size > AUTO_COMPILE_INSTRUCTIONS):
            return functions, f"virtual machine (codegen {codegen}, {size} instructions)"
        sources = [collocation, model, noise_models, state_layout, kernels_module, path_constraints]
        sources += [NOISE_MODELS[name] for name in sorted(set(self.structure.noise_models))]
        digest = source_digest(sources)
        if digest is None:
            return functions, "virtual machine (a noise model has no source file to fingerprint)"
        c = self.colloc
        key = "|".join(
            [repr(self.structure), c.scheme, str(c.degree), self.kernels.layout, digest, self.kernels.fingerprint()]
        )
        return load_compiled(functions, key, background=codegen == "auto")

    @property
    def nlp(self) -> dict[str, ca.MX]:
        """The NLP handed to Ipopt: ``x`` (w, shape (nw,)), ``p`` (P), ``f`` (objective), ``g`` (constraints)."""
        return self._nlp

    @property
    def derivatives(self) -> dict[str, ca.Function]:
        """The assembled ``grad_f(w, P)``, ``jac_g(w, P)``, ``hess_lag(w, P, σ_f, λ_g)`` (upper triangle), for Ipopt."""
        return self._derivatives

    # ------------------------------------------------------------------ solving
    def _checked(self, limited: bool) -> bool:
        """Whether a solve runs with the iteration callback (:class:`IterationLimit`).

        A budgeted solve does, and any solve of a large NLP (:data:`INTERRUPT_CHECK_VARIABLES`), which Ctrl-C
        then stops within an iteration.
        """
        return limited or self.nw >= INTERRUPT_CHECK_VARIABLES

    def _solver(self, warm: bool, limited: bool = False) -> Any:
        """The Ipopt instance of a warm or cold, budgeted or unbudgeted solve.

        Where every solve has the callback, one instance serves budgeted and unbudgeted solves.
        """
        checked = self._checked(limited)
        if (warm, checked) not in self._solvers:
            options = {**(WARM_START if warm else COLD_START), **self.ipopt_options}
            extra: dict[str, Any] = {}
            if checked:
                if self._limit is None:
                    self._limit = IterationLimit(self.nw, self.ng, self.layout.size, *self._bounds[2:])
                extra["iteration_callback"] = self._limit
            self._solvers[(warm, checked)] = self._nlpsol(options, extra)
        return self._solvers[(warm, checked)]

    def _nlpsol(self, options: dict[str, Any], extra: dict[str, Any]) -> BufferedFunction:
        settings = {"ipopt": options, "print_time": False, "error_on_fail": False, "calc_lam_p": False}
        settings.update(self._derivatives, no_nlp_grad=True, **extra)
        return BufferedFunction(ca.nlpsol("direct_collocation", "ipopt", self._nlp, settings))

    def bounds(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(lbw, ubw, lbg, ubg): diagonal covariance entries ≥ 0, equalities, control bounds ≤ 0 (read-only)."""
        return self._bounds

    def _make_bounds(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        k, K = self.kernels, self.intervals
        lbw = np.full(self.nw, -np.inf)
        ubw = np.full(self.nw, np.inf)
        lbw[self.maps.local[:, k.diagonal_positions()].ravel()] = 0.0
        lbg = np.zeros(self.ng)
        ubg = np.zeros(self.ng)
        if k.n_bound:
            bound_rows = np.arange(K)[:, None] * k.nr + k.n_gap + k.n_path + np.arange(k.n_bound)
            lbg[bound_rows.ravel()] = -np.inf
        if k.n_cons:
            lbg[(np.arange(K)[:, None] * k.nr + k.nr - k.n_cons + np.arange(k.n_cons)).ravel()] = -np.inf
        for array in (lbw, ubw, lbg, ubg):
            array.setflags(write=False)
        return lbw, ubw, lbg, ubg

    def solve(
        self,
        P: np.ndarray,
        w0: np.ndarray,
        lam_w0: np.ndarray | None = None,
        lam_g0: np.ndarray | None = None,
        max_iterations: int | None = None,
    ) -> NLPResult:
        """Solve the NLP for parameters ``P`` from ``w0``; warm-started when multipliers are given.

        ``max_iterations`` stops this solve after that many Ipopt iterations (status ``User_Requested_Stop``),
        on top of the transcription's ``max_iter``.
        """
        warm = lam_w0 is not None and lam_g0 is not None
        solver = self._solver(warm, max_iterations is not None)
        if self._limit is not None:  # the callback's budget for this solve (None: only the interrupt check)
            self._limit.reset(max_iterations)
        lbw, ubw, lbg, ubg = self.bounds()
        args: dict[str, Any] = {"x0": w0, "p": P, "lbx": lbw, "ubx": ubw, "lbg": lbg, "ubg": ubg}
        if warm:
            args.update(lam_x0=lam_w0, lam_g0=lam_g0)
        t0 = time.perf_counter()
        # Ctrl-C/SIGTERM during Ipopt: CasADi's callback wrapper can swallow the KeyboardInterrupt and the solve
        # runs on (casadi/casadi#2006); the signal is held and raised once Ipopt returns, so it is never lost.
        # One that arrived while the NLP was being built inside CasADi was recorded: it stops the solve here
        raise_if_interrupted()
        with deferred_interrupts():
            sol, stats = solver.call(args)
        elapsed = time.perf_counter() - t0
        return NLPResult(
            w=sol["x"].ravel(),
            lam_w=sol["lam_x"].ravel(),
            lam_g=sol["lam_g"].ravel(),
            objective=float(sol["f"].item()),
            status=str(stats["return_status"]),
            success=bool(stats["success"]),
            iterations=int(stats["iter_count"]),
            time_s=elapsed,
            g=sol["g"].ravel(),
        )

    def cost_values(self, w: np.ndarray, P: np.ndarray) -> tuple[float, float, float]:
        """The cost terms of the decision vector ``w`` at parameters ``P``, as numbers.

        ``(Tr[M Σ(tf)], ∫ (α/2|u|² + Tr KΣ) dt, ∫ |u|² dt)``: what :attr:`cost_terms` gives, without ``DM``.
        """
        phi, running, energy = self._costs(w, P)
        return float(phi.item()), float(running.item()), float(energy.item())

    # ------------------------------------------------------------------ scaling and warm-start transfer
    @property
    def signature(self) -> tuple:
        """What must match for two NLPs to share decision-vector and multiplier layouts."""
        return (self.structure, self.colloc.scheme, self.colloc.degree, self.intervals, self.kernels.layout)

    def _scales(self, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self._memo.get(  # type: ignore[no-any-return]
            "scales", P, lambda P: tuple(v.ravel() for v in self._scale_vectors(P))
        )

    def variable_scales(self, P: np.ndarray) -> np.ndarray:
        """Physical size of one unit of each decision variable, shape (nw,) (read-only)."""
        return self._memo.get("variable_scales", P, self._variable_scales)  # type: ignore[no-any-return]

    def _variable_scales(self, P: np.ndarray) -> np.ndarray:
        x_scale, u_scale = self._scales(P)
        k, d = self.kernels, self.colloc.degree
        out = np.empty(self.nw)
        out[self.maps.z] = np.concatenate([np.tile(x_scale[: k.ns], d), np.tile(u_scale, d)])[None, :]
        out[self.maps.nxt] = x_scale[-k.nn :][None, :]
        return out

    def constraint_scales(self, P: np.ndarray) -> np.ndarray:
        """Physical size of one unit of each constraint residual, shape (ng,) (read-only)."""
        return self._memo.get("constraint_scales", P, self._constraint_scales)  # type: ignore[no-any-return]

    def _constraint_scales(self, P: np.ndarray) -> np.ndarray:
        b = self.layout.unpack(P)
        x_scale, _ = self._scales(P)
        k, d = self.kernels, self.colloc.degree
        interval = np.concatenate(
            [
                x_scale[-k.nn :],
                np.tile(x_scale[: k.ns], d),
                np.full(k.n_bound, float(b["control_scale"][0]) ** 2),
                np.tile(self._path_scale(P).ravel(), d),
            ]
        )
        terminal = [
            float(b["length_scale"][0]) if kind.startswith("terminal position") else float(b["velocity_scale"][0])
            for kind, _ in k.terminal_labels
        ]
        return np.concatenate([np.tile(interval, self.intervals), terminal])

    def transfer(
        self, w: np.ndarray, lam_w: np.ndarray, lam_g: np.ndarray, P_from: np.ndarray, P_to: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Re-express a primal–dual point of the NLP with parameters ``P_from`` in the scaling of ``P_to``.

        Physical values are kept: ``x = D_x w``, constraint multipliers ``μ = ν cost_scale / s_g`` and bound
        multipliers ``z = ζ cost_scale / D_x`` (the KKT conditions are invariant under these maps, eq. direct.8),
        so a solved neighbour of a sweep is an exact warm start for a problem whose scales differ.
        """
        cs_from = float(self.layout.unpack(np.asarray(P_from, float))["cost_scale"][0])
        cs_to = float(self.layout.unpack(np.asarray(P_to, float))["cost_scale"][0])
        v_from, v_to = self.variable_scales(P_from), self.variable_scales(P_to)
        g_from, g_to = self.constraint_scales(P_from), self.constraint_scales(P_to)
        return (
            w * v_from / v_to,
            lam_w * (cs_from / v_from) * (v_to / cs_to),
            lam_g * (cs_from / g_from) * (g_to / cs_to),
        )

    # ------------------------------------------------------------------ grids and (un)packing
    def times(self, t0: float, tf: float) -> tuple[np.ndarray, np.ndarray]:
        """Interval start times (K+1,) and collocation times (K, d)."""
        h = (tf - t0) / self.intervals
        starts = t0 + h * np.arange(self.intervals + 1)
        return starts, starts[:-1, None] + h * self.colloc.tau[None, 1:]

    def _extended(self, w: np.ndarray, P: np.ndarray) -> np.ndarray:
        """``[w; x̃_0]``: local positions ≥ nw refer to the scaled initial state (a parameter)."""
        x0 = self._memo.get("x0_scaled", P, lambda P: self._x0_scaled(P).ravel())
        return np.concatenate([np.asarray(w, float), x0])

    def _local(self, w: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The local vectors (na, K) and the kernels' parameter input (n_parameters + 1, K)."""
        K = self.intervals
        Ph = self._memo.get(
            "Ph", P, lambda P: np.repeat(with_step(P, self.kernels, K)[:, None], K, axis=1)
        )
        return self._extended(w, P)[self.maps.local].T, Ph

    def unpack(self, w: np.ndarray, P: np.ndarray) -> dict[str, np.ndarray]:
        """Unscaled states at starts ``xs`` (K+1, nx) and nodes ``xc`` (K, d, nx); controls ``u`` (K, d, nu)."""
        x_scale, _ = self._scales(P)
        s, d, K = self.structure, self.colloc.degree, self.intervals
        xc, u = self._nodes(*self._local(w, P))
        return {
            "xs": self._extended(w, P)[self.maps.boundary] * x_scale,
            "xc": xc.reshape(s.nx, K, d).transpose(1, 2, 0),
            "u": u.reshape(s.nu, K, d).transpose(1, 2, 0),
        }

    def pack(self, xs: np.ndarray, xc: np.ndarray, u: np.ndarray, P: np.ndarray) -> np.ndarray:
        """Scaled decision vector from unscaled trajectories (the sensor states at the nodes are implied)."""
        x_scale, u_scale = self._scales(P)
        k, K = self.kernels, self.intervals
        w = np.zeros(self.nw + k.nx)
        w[self.maps.boundary] = np.asarray(xs) / x_scale
        z = np.concatenate([(xc[:, :, : k.ns] / x_scale[: k.ns]).reshape(K, -1), (u / u_scale).reshape(K, -1)], axis=1)
        w[self.maps.z] = z
        return w[: self.nw]

    def costates(self, result: NLPResult, P: np.ndarray) -> np.ndarray:
        """Costate estimates λ at t0 and at every collocation node, shape (1 + K d, nx), from the multipliers.

        The collocation residual of node r is ``h (x̃' − f̃)``; weighted by its multiplier ν_r it mirrors
        ``−∫ λ'(ẋ − f) dt ≈ −Σ h W_r λ_r' D_x (x̃' − f̃)``, so ``λ(t_r) = −cost_scale ν_r / (ε W_r D_x)`` for J_ε
        (eq. direct.6). The sensors' collocation equations were solved exactly (eq. direct.11), so their
        multipliers are recovered from stationarity in the eliminated node states (eq. direct.12), and
        ``λ(t0) = ∂J_ε/∂x0`` from stationarity in x̃_0 (envelope theorem).
        """
        b = self.layout.unpack(np.asarray(P, float))
        x_scale, _ = self._scales(P)
        k, c, K, d = self.kernels, self.colloc, self.intervals, self.colloc.degree
        ns, ny = k.ns, k.ny
        scale = float(b["cost_scale"][0]) / float(b["eps"][0])
        h = (float(b["tf"][0]) - float(b["t0"][0])) / K
        lam = result.lam_g[: K * k.nr].reshape(K, k.nr)
        mu = lam[:, : k.n_gap]  # multipliers of next_k − end_k (K, nn)
        lam_path = lam[:, k.n_gap : k.n_gap + k.n_path]
        nu_sigma = lam_path.reshape(K, d, ns)
        lam_path = np.hstack([lam_path, lam[:, k.nr - k.n_cons :]])
        a, Ph = self._local(result.w, P)
        G = self._pv_gradient(a, Ph, lam_path.T).reshape(ny, K, d).transpose(1, 2, 0)  # (K, d, ny)
        # eq. direct.12: D̂ ν − h ν F̃ = e μ_y − G per interval, F̃ nilpotent: ν = D̂⁻¹B + h D̂⁻² B F̃
        _, _, e = condensing_matrices(c)
        B = e[None, :, None] * mu[:, None, -ny:] - G
        Dinv = np.linalg.inv(c.D[1:, :])
        F = np.zeros((ny, ny))
        F[: ny // 2, ny // 2 :] = np.eye(ny // 2)
        F *= x_scale[ns:][None, :] / x_scale[ns:][:, None]
        nu_y = np.einsum("rj,kjy->kry", Dinv, B) + h * np.einsum("rj,kjy->kry", Dinv @ Dinv, B) @ F
        nu = np.concatenate([nu_sigma, nu_y], axis=2)  # (K, d, nx)
        lam_nodes = -scale * nu.reshape(K * d, -1) / (np.tile(c.W, K)[:, None] * x_scale[None, :])
        mu0 = np.zeros(k.nx)
        mu0[-k.nn :] = mu[0]
        nu_init = -(c.D[0, :] @ nu[0]) + c.E[0] * mu0
        return np.vstack([-scale * nu_init / x_scale, lam_nodes])


@lru_cache(maxsize=16)
def _cached_transcription(
    structure: Structure,
    scheme: str,
    degree: int,
    intervals: int,
    tolerance: float,
    max_iterations: int,
    time_limit: float | None = None,
    codegen: str = "auto",
) -> DirectCollocation:
    extra = {} if time_limit is None else {"max_wall_time": time_limit}
    return DirectCollocation(
        structure,
        scheme,
        degree,
        intervals,
        ipopt_options=extra,
        tolerance=tolerance,
        max_iterations=max_iterations,
        codegen=codegen,
    )


def transcription_for(problem: Problem) -> DirectCollocation:
    """The (cached) transcription for ``problem``'s structure and solver options."""
    opts = problem.solver
    c = opts.collocation
    return _cached_transcription(
        Structure.of(problem),
        c.scheme,
        c.degree,
        c.intervals,
        opts.tolerance,
        opts.max_iterations,
        opts.time_limit,
        opts.codegen,
    )


def clear_transcription_cache() -> None:
    """Forget every transcription built in this process (benchmarks of cold builds)."""
    _cached_transcription.cache_clear()


def transcription_cache_hits() -> int:
    """How many times :func:`transcription_for` reused a built transcription in this process."""
    return _cached_transcription.cache_info().hits
