"""Direct-collocation transcription of the mobile-sensor Kalman problem into an Ipopt NLP (built once).

Decision vector, interval by interval (scaled variables, O(1)):
``w = [x_0, X_0, U_0, x_1, X_1, U_1, …, x_K]`` with ``x_k`` (nx,) the state at the start of interval k,
``X_k`` (nx, d) the states at the d collocation nodes and ``U_k`` (nu, d) the controls there.
Constraints: collocation equations (d per interval), continuity ``x_{k+1} = x_end(k)``, the initial
state, fixed terminal states, control-norm bounds. Objective: the cost multiplied by ε,
``ε Tr[MΣ(tf)] + ∫ L`` (same minimiser as J_ε, well scaled as ε → 0), divided by ``cost_scale``.
Every number is a parameter (:class:`mobisense.ocp.model.ParameterLayout`), so the homotopy and parameter
sweeps re-solve the same graph: one SX kernel per interval, mapped over the intervals, expanded.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from ..collocation import CollocationScheme
from ..model import SensorKalmanModel, Structure
from ..problem import Problem
from ..state_layout import diagonal_indices

__all__ = [
    "DirectCollocation",
    "NLPResult",
    "IPOPT_DEFAULTS",
    "COLD_START",
    "WARM_START",
    "transcription_for",
    "transcription_cache_hits",
    "clear_transcription_cache",
    "TranscriptionSize",
    "transcription_size",
]

#: Ipopt options used by default. MUMPS' matching-based permutation and scaling are switched off and the
#: fill-reducing ordering is AMD: on these banded collocation KKT systems that is the fastest combination
#: measured (benchmarks/bench_direct.py: default problem and K up to 400; every homotopy step re-runs the
#: symbolic analysis, where METIS, MUMPS' automatic choice, costs most).
IPOPT_DEFAULTS: dict[str, Any] = {
    "linear_solver": "mumps",
    "mumps_permuting_scaling": 0,
    "mumps_scaling": 0,
    "mumps_pivot_order": 0,
    "print_level": 0,
    "sb": "yes",
}

#: Extra options for the cold first step: the coasting guess is feasible and near-optimal for small ε, so a
#: smaller initial barrier than Ipopt's 0.1 saves iterations (default problem: 19 instead of 34).
COLD_START: dict[str, Any] = {"mu_init": 1e-2}

#: Extra options for warm-started homotopy steps (primal and dual variables supplied).
WARM_START: dict[str, Any] = {
    "warm_start_init_point": "yes",
    "mu_init": 1e-8,
    "warm_start_bound_push": 1e-9,
    "warm_start_bound_frac": 1e-9,
    "warm_start_slack_bound_push": 1e-9,
    "warm_start_slack_bound_frac": 1e-9,
    "warm_start_mult_bound_push": 1e-9,
}


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


@dataclass(frozen=True)
class TranscriptionSize:
    """Sizes of the NLP :class:`DirectCollocation` would build, computed without building it.

    ``variables`` and ``constraints`` are exact; ``jacobian_nnz`` and ``hessian_nnz`` (lower triangle of the
    Lagrangian Hessian) count the structural non-zeros of one collocation node times the nodes, and
    ``expression_nodes`` the SX nodes of the expanded NLP plus its Jacobian and Hessian functions, fitted to
    CasADi's counts for n = 1…10 states, N = 1…32 sensors, d = 3…9 (within −27 % … +30 %, mostly +10 %).
    """

    variables: int
    constraints: int
    jacobian_nnz: int
    hessian_nnz: int
    expression_nodes: int


def transcription_size(structure: Structure, degree: int, intervals: int) -> TranscriptionSize:
    """The :class:`TranscriptionSize` of the transcription of ``structure`` on ``intervals`` intervals of ``degree``."""
    s, d, K = structure, degree, intervals
    n, N, nx, nu, ns = s.n, s.N, s.nx, s.nu, s.n_sigma
    nodes = K * d
    bounded = sum(s.bounded_control)
    terminal = 2 * (sum(s.fixed_position) + sum(s.fixed_velocity))
    variables = K * (nx + nx * d + nu * d) + nx
    constraints = nodes * nx + K * nx + nx + terminal + nodes * bounded
    # a covariance residual depends on its node's slope (d + 1 values), a row and a column of Σ and every
    # sensor position (through S(p)); a position/velocity residual on its slope and one velocity/control
    jacobian = nodes * (ns * (d + 1 + 2 * n + 2 * N) + 4 * N * (d + 2) + 2 * bounded) + K * nx * (d + 2) + nx + terminal
    # Σ S(p) Σ couples every pair of covariance entries (S is a parameter, dense), and each sensor's
    # position with every covariance entry; controls enter quadratically
    hessian = nodes * (ns * (ns + 1) // 2 + 2 * N * ns + 5 * N)
    expression = nodes * (30 + 4 * d * nx + (180 * n**2 + 60) * N + 12 * n**3 + 24 * ns**2)
    return TranscriptionSize(variables, constraints, jacobian, hessian, expression)


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
    ) -> None:
        t_build = time.perf_counter()
        self.structure = s = structure
        self.model = SensorKalmanModel(structure)
        self.layout = self.model.layout
        self.colloc = CollocationScheme(scheme, degree)
        self.intervals = K = intervals
        self.ipopt_options = {**IPOPT_DEFAULTS, "tol": tolerance, "max_iter": max_iterations, **(ipopt_options or {})}
        nx, nu, d = s.nx, s.nu, degree
        self._index(nx, nu, d, K)

        kernel = self._interval_kernel()
        mapped = kernel.map(K, "serial")
        w = ca.MX.sym("w", self.nw)
        P = ca.MX.sym("P", self.layout.size)
        xs = ca.reshape(w[self.idx_xs.ravel(order="F").tolist()], nx, K + 1)
        Xc = ca.reshape(w[self.idx_xc.ravel(order="F").tolist()], nx * d, K)
        U = ca.reshape(w[self.idx_u.ravel(order="F").tolist()], nu * d, K)
        res, x_end, quad, ubound = mapped(xs[:, :K], Xc, U, P)
        x_scale, _ = self.model.scales(P)
        b = self.layout.unpack(P)
        x_final = xs[:, K] * x_scale
        terminal_res, terminal_labels = self.model.terminal_constraints(x_final, P)
        g = ca.vertcat(
            ca.vec(res),
            ca.vec(xs[:, 1:] - x_end),
            xs[:, 0] - self.model.x0(P) / x_scale,
            terminal_res,
            ca.vec(ubound),
        )
        running = ca.sum2(quad[0, :])
        energy = ca.sum2(quad[1, :])
        phi = self.model.terminal(x_final, P)
        objective = (b["eps"] * phi + running) / b["cost_scale"]
        self._nlp_function = ca.Function("nlp", [w, P], [objective, g]).expand()
        self.cost_terms = ca.Function("cost_terms", [w, P], [phi, running, energy]).expand()
        self._n_bound = ubound.size1() * ubound.size2()
        self.ng = g.size1()
        self._terminal_labels = terminal_labels
        self._solvers: dict[bool, Any] = {}
        self._bounds = self._make_bounds()
        self.build_time_s = time.perf_counter() - t_build

    # ------------------------------------------------------------------ layout
    def _index(self, nx: int, nu: int, d: int, K: int) -> None:
        per_interval = nx + nx * d + nu * d
        start = np.arange(K) * per_interval
        self.idx_xs = np.concatenate([start[:, None] + np.arange(nx), [K * per_interval + np.arange(nx)]]).T
        self.idx_xc = (start[:, None] + nx + np.arange(nx * d)).T  # (nx*d, K), node-major
        self.idx_u = (start[:, None] + nx + nx * d + np.arange(nu * d)).T  # (nu*d, K)
        self.nw = K * per_interval + nx

    def _interval_kernel(self) -> ca.Function:
        """SX kernel of one interval: collocation residuals, end state, quadratures, control bounds."""
        s, c, m = self.structure, self.colloc, self.model
        nx, nu, d = s.nx, s.nu, c.degree
        x_start = ca.SX.sym("x_start", nx)
        Xc = ca.SX.sym("Xc", nx * d)
        U = ca.SX.sym("U", nu * d)
        P = ca.SX.sym("P", self.layout.size)
        b = self.layout.unpack(P)
        h = (b["tf"] - b["t0"]) / self.intervals
        x_scale, u_scale = m.scales(P)
        nodes = [x_start] + [Xc[r * nx : (r + 1) * nx] for r in range(d)]
        residuals, quad_L, quad_E, bounds = [], 0, 0, []
        for r in range(d):
            u_r = U[r * nu : (r + 1) * nu] * u_scale
            x_r = nodes[r + 1] * x_scale
            slope = sum(c.D[j, r] * nodes[j] for j in range(d + 1))
            residuals.append(slope - h * m.f(x_r, u_r, P) / x_scale)
            L = m.running(x_r, u_r, P)
            quad_L += h * c.W[r] * L[0]
            quad_E += h * c.W[r] * L[1]
            bound, _ = m.control_bounds(u_r, P)
            bounds.append(bound)
        x_end = sum(c.E[j] * nodes[j] for j in range(d + 1))
        return ca.Function(
            "interval",
            [x_start, Xc, U, P],
            [ca.vertcat(*residuals), x_end, ca.vertcat(quad_L, quad_E), ca.vertcat(*bounds)],
            ["x_start", "Xc", "U", "P"],
            ["residual", "x_end", "quad", "bound"],
        )

    # ------------------------------------------------------------------ solving
    def _solver(self, warm: bool) -> Any:
        if warm not in self._solvers:
            w = ca.SX.sym("w", self.nw)
            P = ca.SX.sym("P", self.layout.size)
            f, g = self._nlp_function(w, P)
            options = {**(WARM_START if warm else COLD_START), **self.ipopt_options}
            self._solvers[warm] = ca.nlpsol(
                "direct_collocation",
                "ipopt",
                {"x": w, "p": P, "f": f, "g": g},
                {"ipopt": options, "print_time": False, "error_on_fail": False},
            )
        return self._solvers[warm]

    def bounds(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(lbw, ubw, lbg, ubg): diagonal covariance entries ≥ 0, equalities, control bounds ≤ 0 (read-only)."""
        return self._bounds

    def _make_bounds(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        lbw = np.full(self.nw, -np.inf)
        ubw = np.full(self.nw, np.inf)
        nx, d = self.structure.nx, self.colloc.degree
        diag = diagonal_indices(self.structure.n)
        lbw[self.idx_xs[diag].ravel()] = 0.0
        lbw[self.idx_xc[[r * nx + k for r in range(d) for k in diag]].ravel()] = 0.0
        lbg = np.zeros(self.ng)
        ubg = np.zeros(self.ng)
        if self._n_bound:
            lbg[-self._n_bound :] = -np.inf
        for array in (lbw, ubw, lbg, ubg):
            array.setflags(write=False)
        return lbw, ubw, lbg, ubg

    def solve(
        self,
        P: np.ndarray,
        w0: np.ndarray,
        lam_w0: np.ndarray | None = None,
        lam_g0: np.ndarray | None = None,
    ) -> NLPResult:
        """Solve the NLP for parameters ``P`` from ``w0``; warm-started when multipliers are given."""
        warm = lam_w0 is not None and lam_g0 is not None
        solver = self._solver(warm)
        lbw, ubw, lbg, ubg = self.bounds()
        args: dict[str, Any] = {"x0": w0, "p": P, "lbx": lbw, "ubx": ubw, "lbg": lbg, "ubg": ubg}
        if warm:
            args.update(lam_x0=lam_w0, lam_g0=lam_g0)
        t0 = time.perf_counter()
        sol = solver(**args)
        elapsed = time.perf_counter() - t0
        stats = solver.stats()
        return NLPResult(
            w=np.asarray(sol["x"]).ravel(),
            lam_w=np.asarray(sol["lam_x"]).ravel(),
            lam_g=np.asarray(sol["lam_g"]).ravel(),
            objective=float(sol["f"]),
            status=str(stats["return_status"]),
            success=bool(stats["success"]),
            iterations=int(stats["iter_count"]),
            time_s=elapsed,
            g=np.asarray(sol["g"]).ravel(),
        )

    # ------------------------------------------------------------------ scaling and warm-start transfer
    @property
    def signature(self) -> tuple:
        """What must match for two NLPs to share decision-vector and multiplier layouts."""
        return (self.structure, self.colloc.scheme, self.colloc.degree, self.intervals)

    def variable_scales(self, P: np.ndarray) -> np.ndarray:
        """Physical size of one unit of each decision variable, shape (nw,)."""
        x_scale, u_scale = (np.asarray(v).ravel() for v in self.model.scales(P))
        out = np.empty(self.nw)
        out[self.idx_xs] = x_scale[:, None]
        out[self.idx_xc] = np.tile(x_scale, self.colloc.degree)[:, None]
        out[self.idx_u] = np.tile(u_scale, self.colloc.degree)[:, None]
        return out

    def constraint_scales(self, P: np.ndarray) -> np.ndarray:
        """Physical size of one unit of each constraint residual, shape (ng,)."""
        b = self.layout.unpack(np.asarray(P, float))
        x_scale = np.asarray(self.model.scales(P)[0]).ravel()
        d, K = self.colloc.degree, self.intervals
        terminal = [
            float(b["length_scale"][0]) if kind.startswith("terminal position") else float(b["velocity_scale"][0])
            for kind, _ in self._terminal_labels
        ]
        bounds = np.full(self._n_bound, float(b["control_scale"][0]) ** 2)
        return np.concatenate([np.tile(x_scale, d * K), np.tile(x_scale, K), x_scale, terminal, bounds])

    def transfer(
        self, w: np.ndarray, lam_w: np.ndarray, lam_g: np.ndarray, P_from: np.ndarray, P_to: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Re-express a primal–dual point of the NLP with parameters ``P_from`` in the scaling of ``P_to``.

        Physical values are kept: ``x = D_x w``, constraint multipliers ``μ = ν cost_scale / s_g`` and bound
        multipliers ``z = ζ cost_scale / D_x`` (the KKT conditions are invariant under these maps), so a
        solved neighbour of a sweep is an exact warm start for a problem whose scales differ.
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

    def unpack(self, w: np.ndarray, P: np.ndarray) -> dict[str, np.ndarray]:
        """Unscaled states at starts ``xs`` (K+1, nx) and nodes ``xc`` (K, d, nx); controls ``u`` (K, d, nu)."""
        x_scale, u_scale = (np.asarray(v).ravel() for v in self.model.scales(P))
        nx, nu, d, K = self.structure.nx, self.structure.nu, self.colloc.degree, self.intervals
        xs = w[self.idx_xs].T * x_scale
        xc = w[self.idx_xc].T.reshape(K, d, nx) * x_scale
        u = w[self.idx_u].T.reshape(K, d, nu) * u_scale
        return {"xs": xs, "xc": xc, "u": u}

    def pack(self, xs: np.ndarray, xc: np.ndarray, u: np.ndarray, P: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`unpack`: scaled decision vector from unscaled trajectories."""
        x_scale, u_scale = (np.asarray(v).ravel() for v in self.model.scales(P))
        K = self.intervals
        w = np.empty(self.nw)
        w[self.idx_xs] = (xs / x_scale).T
        w[self.idx_xc] = (xc / x_scale).reshape(K, -1).T
        w[self.idx_u] = (u / u_scale).reshape(K, -1).T
        return w

    def costates(self, result: NLPResult, P: np.ndarray) -> np.ndarray:
        """Costate estimates λ at t0 and at every collocation node, shape (1 + K d, nx), from the multipliers.

        The collocation residual of node r is ``h (x̃' − f̃)`` with x̃ = x / D_x; weighted by its multiplier
        ν_r it mirrors ``−∫ λ'(ẋ − f) dt ≈ −Σ h W_r λ_r' D_x (x̃' − f̃)``, so
        ``λ(t_r) = −cost_scale ν_r / (ε W_r D_x)`` for J_ε (the NLP objective is ε J_ε / cost_scale).
        At t0 the multiplier ν_0 of ``x̃_0 = x0 / D_x`` is the sensitivity of the optimum to x0 (envelope
        theorem): ``λ(t0) = ∂J_ε/∂x0 = −cost_scale ν_0 / (ε D_x)``.
        """
        b = self.layout.unpack(np.asarray(P, float))
        x_scale = np.asarray(self.model.scales(P)[0]).ravel()
        nx, d, K = self.structure.nx, self.colloc.degree, self.intervals
        scale = float(b["cost_scale"][0]) / float(b["eps"][0])
        nu_coll = result.lam_g[: nx * d * K].reshape(K * d, nx)
        start = nx * d * K + nx * K
        nu_init = result.lam_g[start : start + nx]
        lam_nodes = -scale * nu_coll / (np.tile(self.colloc.W, K)[:, None] * x_scale[None, :])
        lam_t0 = -scale * nu_init / x_scale
        return np.vstack([lam_t0, lam_nodes])

    def constraint_labels(self, sensor_names: list[str], t0: float, tf: float) -> list[tuple[str, float]]:
        """(description, time) of every NLP constraint, in problem terms."""
        s, d, K = self.structure, self.colloc.degree, self.intervals
        state = s.state.labels(sensor_names)
        starts, nodes = self.times(t0, tf)
        labels: list[tuple[str, float]] = []
        for k in range(K):
            for r in range(d):
                labels += [(f"dynamics of {name} (collocation)", float(nodes[k, r])) for name in state]
        for k in range(K):
            labels += [(f"continuity of {name}", float(starts[k + 1])) for name in state]
        labels += [(f"initial value of {name}", float(starts[0])) for name in state]
        labels += [(f"{kind} of sensor {sensor_names[i]}", float(starts[-1])) for kind, i in self._terminal_labels]
        bounded = [i for i in range(s.N) if s.bounded_control[i]]
        for k in range(K):
            for r in range(d):
                labels += [(f"|u| ≤ u_max of sensor {sensor_names[i]}", float(nodes[k, r])) for i in bounded]
        return labels


@lru_cache(maxsize=16)
def _cached_transcription(
    structure: Structure,
    scheme: str,
    degree: int,
    intervals: int,
    tolerance: float,
    max_iterations: int,
    time_limit: float | None = None,
) -> DirectCollocation:
    extra = {} if time_limit is None else {"max_wall_time": time_limit}
    return DirectCollocation(
        structure, scheme, degree, intervals, ipopt_options=extra, tolerance=tolerance, max_iterations=max_iterations
    )


def transcription_for(problem: Problem) -> DirectCollocation:
    """The (cached) transcription for ``problem``'s structure and solver options."""
    opts = problem.solver
    c = opts.collocation
    return _cached_transcription(
        Structure.of(problem), c.scheme, c.degree, c.intervals, opts.tolerance, opts.max_iterations, opts.time_limit
    )


def clear_transcription_cache() -> None:
    """Forget every transcription built in this process (benchmarks of cold builds)."""
    _cached_transcription.cache_clear()


def transcription_cache_hits() -> int:
    """How many times :func:`transcription_for` reused a built transcription in this process."""
    return _cached_transcription.cache_info().hits
