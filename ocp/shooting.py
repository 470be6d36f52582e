"""Reduced-space shooting for field problems: the controls are the only NLP variables (docs/theory/field.md §3).

u_i(t) is continuous and piecewise linear on K uniform intervals (nodes u_{i,0..K}: 2N(K+1) numbers);
the double integrator is integrated exactly (eq. field.7); Σ is propagated in whitened coordinates by
``m`` Möbius-RK4 steps per interval (:mod:`mobisense.ocp.mobius`, O(n²N) each); the cost

    J_ε = ε Tr[M Σ(tf)] + ∫ (α/2 Σ_i |u_i|² + Tr[K Σ]) dt                 (eq. field.8)

(ε times eq. direct.9: the same minimisers, with the terminal term rather than the running cost scaled; the
homotopy costs are reported as eq. direct.9) is a CasADi MX graph of the K interval calls, so its gradient is
the exact discrete adjoint. Ipopt
solves the NLP with a limited-memory BFGS Hessian. Fixed terminal p/v are linear constraints and
|u_i| ≤ u_max holds exactly at the nodes (|u(t)| is convex on each interval).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from ..core.interrupts import raise_if_interrupted
from .direct.iteration_limit import IterationLimit
from .field import substeps_for
from .field_constraints import path_row_function
from .mobius import mobius_rk4_step
from .problem import Problem

__all__ = ["FAR", "ShootingTrajectory", "FieldShooting"]

#: a sensor's distance from the field counts in the kinematic unit up to this many times the field's diagonal
FAR = 10.0


@dataclass
class ShootingTrajectory:
    """Node values on the K+1 times ``t`` (T): ``Sigma`` (K+1, n, n), ``p``, ``v``, ``u`` (K+1, N, 2), costs."""

    t: np.ndarray
    Sigma: np.ndarray
    p: np.ndarray
    v: np.ndarray
    u: np.ndarray
    costs: tuple[float, float, float]  # terminal Tr[MΣ(tf)], running ∫(α/2|u|² + Tr KΣ), control energy


class FieldShooting:
    """The reduced NLP of one field problem on K intervals with m substeps: build once, solve many ε.

    Parameters
    ----------
    problem : Problem
        A problem with ``process.field`` and point sensors.
    intervals : int
        K.
    substeps : int, optional
        m; default :func:`~mobisense.ocp.field.substeps_for` (at least 4 with a running weight K ≠ 0).
    scaling : {"kinematic", "energy"}
        Unit of the NLP variables: u / (L/T²) (``kinematic``, as the direct method) or u·sqrt(αh/J₀)
        (``energy``: the control-energy Hessian ≈ I; faster for the small-ε homotopy steps).
    control_bounds : bool
        Hold the sensors' |u| ≤ u_max (the coarse homotopy does not: see :func:`mobisense.ocp.field_solve`).
    """

    def __init__(self, problem: Problem, intervals: int, substeps: int | None = None, scaling: str = "kinematic",
                 max_h_lambda: float = 0.25, control_bounds: bool = True) -> None:  # fmt: skip
        t_build = time.perf_counter()
        self.problem = problem
        self.control_bounds = control_bounds
        self.field = problem.process.field.process()
        self.n, self.N, self.K = n, N, K = problem.n, problem.N, intervals
        mats = problem.matrices()
        self.M, self.Kw = mats["M"], mats["K"]
        self.running_state_cost = bool(np.any(self.Kw != 0))
        self.m = substeps or substeps_for(problem, K, max_h_lambda)
        self.scaling = scaling
        self.L = self.field.chol
        self.Linv = np.linalg.solve(self.L, np.eye(n))
        self.nw = 2 * N * (K + 1)
        T = problem.horizon.tf - problem.horizon.t0
        self.h = h = T / K
        w = ca.MX.sym("w", self.nw)
        self.P = P = ca.MX.sym("P", 3)  # ε, cost scale, control scale
        eps, cost_scale, u_scale = P[0], P[1], P[2]
        U = ca.reshape(w, 2 * N, K + 1) * u_scale
        pos = [ca.DM(np.concatenate([s.p0 for s in problem.sensors]))]
        vel = [ca.DM(np.concatenate([s.v0 for s in problem.sensors]))]
        for k in range(K):  # eq. field.7: exact for piecewise-linear u
            uk, uk1 = U[:, k], U[:, k + 1]
            pos.append(pos[-1] + h * vel[-1] + h**2 * (uk / 3 + uk1 / 6))
            vel.append(vel[-1] + h * (uk + uk1) / 2)
        # with path constraints the node states are NLP variables too (scaled by the length and speed units),
        # tied to the controls by eq. field.7 as equality rows: a node's path rows then depend on its own four
        # numbers, not on every earlier control (5 × 5 field, 26 rows per node on K = 100: 247 200 Jacobian
        # non-zeros, 0.26 s an iteration against 0.035 s without constraints)
        self.lifted = problem.constraints is not None
        x = w
        defects: list[Any] = []
        if self.lifted:
            length, speed = self.length_scale(), self.length_scale() / T
            X = ca.MX.sym("X", 4 * N, K)
            self.lift = ca.Function("lift", [w, P], [ca.vertcat(*[ca.vertcat(pos[k] / length, vel[k] / speed)
                                                                    for k in range(1, K + 1)])])  # fmt: skip
            pos = [pos[0]] + [X[: 2 * N, k] * length for k in range(K)]
            vel = [vel[0]] + [X[2 * N :, k] * speed for k in range(K)]
            for k in range(K):
                uk, uk1 = U[:, k], U[:, k + 1]
                defects += [(pos[k + 1] - pos[k] - h * vel[k] - h**2 * (uk / 3 + uk1 / 6)) / length,
                            (vel[k + 1] - vel[k] - h * (uk + uk1) / 2) / speed]  # fmt: skip
            x = ca.vertcat(w, ca.vec(X))
        F = self._interval_function()
        Z = ca.DM(self.Linv @ mats["Sigma0"] @ self.Linv.T).reshape((n * n, 1))
        Zs, running, energy = [Z], 0, 0
        for k in range(K):
            Z, q = F(Z, ca.vertcat(pos[k], vel[k], U[:, k], U[:, k + 1]))
            Zs.append(Z)
            running += q
            uk, uk1 = U[:, k], U[:, k + 1]
            energy += h / 3 * (ca.sumsqr(uk) + ca.dot(uk, uk1) + ca.sumsqr(uk1))
        energy = 0.5 * problem.cost.alpha * energy
        phi = ca.sum1(ca.sum2(ca.DM(self.L.T @ self.M @ self.L) * ca.reshape(Z, n, n)))  # Tr[MΣ] = Tr[L'ML Z]
        objective = (eps * phi + running + energy) / cost_scale
        g, self.lbg, self.ubg = self._constraints(pos, vel, U, u_scale)
        if defects:  # the kinematics first: equality rows
            g = ca.vertcat(*defects, g)
            self.lbg, self.ubg = np.r_[np.zeros(4 * N * K), self.lbg], np.r_[np.zeros(4 * N * K), self.ubg]
            t0, names = problem.horizon.t0, [sensor.name for sensor in problem.sensors]
            self.row_labels = [(f"kinematics of {'pv'[j // (2 * N)]} of sensor {names[(j % (2 * N)) // 2]}",
                                t0 + (k + 1) * h, length if j < 2 * N else speed, None, None)
                               for k in range(K) for j in range(4 * N)] + self.row_labels  # fmt: skip
        self.nlp = {"x": x, "p": P, "f": objective, "g": g}
        #: rows |u|²/u_max² − 1 of the bounded sensors in g, sensor by sensor and node by node
        self.bound_rows = np.array([j for j, label in enumerate(self.row_labels) if label[3] is not None], dtype=int)
        self._rows = ca.Function("rows", [x, P], [g])
        self._cost_terms = ca.Function("cost_terms", [x, P], [phi, running + energy, energy])
        self.trajectory = ca.Function("trajectory", [x, P], [ca.horzcat(*Zs), ca.horzcat(*pos), ca.horzcat(*vel), U])
        self.solvers: dict[float, Any] = {}
        self.interrupt: IterationLimit | None = None  # the solvers' iteration callback (created with the first)
        self.build_time_s = time.perf_counter() - t_build

    def _constraints(self, pos: list[Any], vel: list[Any], U: Any, u_scale: Any) -> tuple[Any, np.ndarray, np.ndarray]:
        """Terminal states, |u| ≤ u_max at the nodes and the path constraints at nodes 1 … K (eq. path.1–5)."""
        g: list[Any] = []
        lbg: list[float] = []
        ubg: list[float] = []
        # each row: what, time, its scale, u_max for a |u| ≤ u_max row (its size is then |u| − u_max) and the
        # group of a path-constraint row (its size is then natural_violation's)
        self.row_labels: list[tuple[str, float, float, float | None, str | None]] = []
        length = self.length_scale()
        t0, tf = self.problem.horizon.t0, self.problem.horizon.tf
        pK, vK = pos[-1], vel[-1]
        for i, s in enumerate(self.problem.sensors):
            for key, end, scale in (("p", pK, length), ("v", vK, length / (tf - t0))):
                target = None if s.terminal is None else getattr(s.terminal, key)
                if target is not None:
                    g.append((end[2 * i : 2 * i + 2] - ca.DM(target)) / scale)
                    lbg += [0.0, 0.0]
                    ubg += [0.0, 0.0]
                    self.row_labels += [(f"terminal {key}[{c}] of sensor {s.name}", tf, scale, None, None)
                                        for c in range(2)]  # fmt: skip
            if s.u_max is not None and self.control_bounds:
                for k in range(self.K + 1):
                    # relative to the bound: (|u|² − u_max²)/u_scale² was −(u_max/u_scale)² where u_max ≫ u_scale, and a
                    # bound that never binds (u_max = 1 for |u| ≤ 0.37) ran Ipopt to its iteration limit (first hour)
                    g.append(ca.sumsqr(U[2 * i : 2 * i + 2, k]) / s.u_max**2 - 1.0)
                    lbg.append(-np.inf)
                    ubg.append(0.0)
                    self.row_labels.append((f"|u| ≤ u_max of sensor {s.name}", t0 + k * self.h, 1.0, s.u_max, None))
        self.path_groups, self.path_units = np.array([], dtype=str), np.zeros(0)  # the path rows, one instant
        if self.problem.constraints is not None:
            function, numbers, labels = path_row_function(self.problem.constraints, self.N)
            params = ca.DM(np.r_[numbers, length, length / (tf - t0)])
            names = [s.name for s in self.problem.sensors]
            units = np.asarray(function(np.zeros(2 * self.N), np.zeros(2 * self.N), params)[1]).ravel()
            for k in range(1, self.K + 1):  # node 0 is the initial state, checked when the file is read
                g.append(function(pos[k], vel[k], params)[0])
                for (group, what), unit in zip(labels, units, strict=True):
                    self.row_labels.append((what.format(*names), t0 + k * self.h, float(unit), None, group))
            self.path_groups = np.array([group for group, _ in labels])
            self.path_units = units
            lbg += [-np.inf] * (self.K * len(labels))
            ubg += [0.0] * (self.K * len(labels))
        return (ca.vertcat(*g) if g else ca.MX(0, 1)), np.array(lbg), np.array(ubg)

    def row_excess(self, g: np.ndarray) -> np.ndarray:
        """How far each scaled row of ``g`` lies outside its bounds (0 where it holds), shape of ``g``."""
        return np.maximum(np.maximum(self.lbg - g, g - self.ubg), 0.0)

    def worst_violation(self, g: np.ndarray, u_scale: float) -> dict[str, Any] | None:
        """The most violated constraint of the rows ``g`` of a solve, in physical units (None: there are none).

        ``{constraint, time, violation}``: a terminal position (L) or velocity (L/T) off its target,
        |u| − u_max (L/T²) at a node, or a path constraint's violation at a node in its natural quantity (a
        disc's depth, …: :func:`mobisense.ocp.direct.violations.natural_violation`); ``u_scale`` is the control
        scale of the solve's parameters.
        """
        if not len(g):
            return None
        excess = self.row_excess(g)
        if not excess.max(initial=0.0) > 0.0:  # every row holds: the solve failed for another reason
            return None
        j = int(np.argmax(excess))
        what, when, scale, u_max, group = self.row_labels[j]
        if group is not None:  # a path constraint: a disc's depth, a separation deficit, … (direct method's units)
            from .direct.violations import ConstraintRow, natural_violation

            size, _ = natural_violation(ConstraintRow(what, when, "path", group), float(excess[j] * scale),
                                        self.problem)  # fmt: skip
        elif u_max is None:
            size = float(abs(g[j]) * scale)
        else:  # the row is |u|²/u_max² − 1
            size = float(u_max * (np.sqrt(max(1.0 + g[j], 0.0)) - 1.0))
        return {"constraint": what, "time": float(when), "violation": size}

    def length_scale(self) -> float:
        """The largest sensor–state distance at the start, at least 1 (L): the kinematic unit.

        A sensor's distance counts up to :data:`FAR` × the field's diagonal: one sensor out of reach (1e6 away)
        set the unit of every sensor's control, and the fine solve ran out of iterations on a plan already optimal.
        """
        locations = self.field.locations
        reach = FAR * max(float(np.linalg.norm(locations.max(axis=0) - locations.min(axis=0))), 1.0)
        return max(1.0, *(min(float(np.linalg.norm(np.asarray(s.p0) - locations, axis=1).max()), reach)
                          for s in self.problem.sensors))  # fmt: skip

    def parameters(self, eps: float, cost_scale: float) -> np.ndarray:
        """NLP parameters [ε, cost scale, control scale] (control scale in L/T²)."""
        T = self.problem.horizon.tf - self.problem.horizon.t0
        if self.scaling == "energy":
            u_scale = math.sqrt(cost_scale / (self.problem.cost.alpha * self.h))
        else:
            speed = max(self.length_scale() / T, *(np.linalg.norm(s.v0) for s in self.problem.sensors))
            u_scale = speed / T
        bounds = [s.u_max for s in self.problem.sensors if s.u_max is not None] if self.control_bounds else []
        if bounds and len(bounds) == self.N:  # every |u| bounded below the unit: |w| ≤ 1 (u_max = 1e-9 in a unit of
            u_scale = min(u_scale, min(bounds))  # 0.1 ran Ipopt out of iterations); one unit for all sensors, so
            # not when some are free: their w would be 1e8 (a 3 × 3 field then "solved" 8.5 % above the optimum)
        return np.array([eps, cost_scale, u_scale])

    def _interval_function(self) -> ca.Function:
        """Z_{k+1}, ∫_k Tr[K̃Z] dt from Z_k (n², column-major) and z = [p_k, v_k, u_k, u_{k+1}] (8N,)."""
        n, N, m, h = self.n, self.N, self.m, self.h
        sig, z = ca.MX.sym("z_sigma", n * n), ca.MX.sym("z", 8 * N)
        dt = h / m
        pk, vk, uk, uk1 = z[: 2 * N], z[2 * N : 4 * N], z[4 * N : 6 * N], z[6 * N :]
        tau = self.problem.process.field.time_constant
        a, q = 1.0 / tau, 2.0 / tau
        rinv = ca.DM([1.0 / s.noise.parameters()[0] for s in self.problem.sensors])
        loc, Linv = ca.DM(self.field.locations), ca.DM(self.Linv)
        Kt = ca.DM(self.L.T @ self.Kw @ self.L)
        cache: dict[int, tuple[Any, Any]] = {}

        def rows_at(key: int) -> tuple[Any, Any]:
            """C̃ (N × n) and 1/r (N, 1) at local time key·dt/2 from the exact cubic path."""
            if key not in cache:
                s = key * dt / 2
                p = pk + vk * s + uk * s**2 / 2 + (uk1 - uk) * s**3 / (6 * h)
                px = ca.horzcat(*[p[2 * i] for i in range(N)])
                py = ca.horzcat(*[p[2 * i + 1] for i in range(N)])
                cache[key] = (ca.mtimes(Linv, self.field.symbolic_cross_covariance(px, py, loc)).T, rinv)
            return cache[key]

        def trace_K(X: Any) -> Any:
            return ca.sum1(ca.sum2(Kt * X))

        def riccati(Z: Any, C: Any, r_inv: Any) -> Any:  # eq. field.5
            G = ca.mtimes(Z, C.T)
            return -2 * a * Z + q * ca.MX.eye(n) - ca.mtimes(G * ca.repmat(r_inv.T, n, 1), G.T)

        Z = ca.reshape(sig, n, n)
        quad = 0
        for j in range(m):
            rows = [rows_at(2 * j), rows_at(2 * j + 1), rows_at(2 * j + 2)]
            Z_next = mobius_rk4_step(Z, rows, a, q, dt)
            if self.running_state_cost:  # cubic Hermite quadrature (order 4) with Z' from eq. field.5
                d0, d1 = trace_K(riccati(Z, *rows[0])), trace_K(riccati(Z_next, *rows[2]))
                quad += dt / 2 * (trace_K(Z) + trace_K(Z_next)) + dt**2 / 12 * (d0 - d1)
            Z = Z_next
        return ca.Function("interval", [sig, z], [ca.vec(Z), quad])

    def solve(self, w: np.ndarray, eps: float, cost_scale: float, tolerance: float, max_iterations: int,
              memory: int, time_limit: float | None = None) -> tuple[np.ndarray, dict[str, Any]]:  # fmt: skip
        """Ipopt (L-BFGS) from the scaled controls ``w`` (nw,); returns the new w and Ipopt's record."""
        key = (tolerance, max_iterations)
        if key not in self.solvers:
            ipopt = {"tol": tolerance, "max_iter": max_iterations, "print_level": 0, "sb": "yes",
                     "hessian_approximation": "limited-memory", "limited_memory_max_history": memory,
                     "mu_init": 1e-2 if self.lbg.size else 1e-1}  # fmt: skip
            if time_limit is not None:
                ipopt["max_wall_time"] = float(time_limit)
            if self.interrupt is None:  # stops Ipopt within an iteration of Ctrl-C (one solve can take a minute)
                self.interrupt = IterationLimit(self.nlp["x"].numel(), self.nlp["g"].numel(), self.nlp["p"].numel(),
                                                self.lbg, self.ubg)
            self.solvers[key] = ca.nlpsol("field_shooting", "ipopt", self.nlp,
                                          {"ipopt": ipopt, "print_time": False, "error_on_fail": False,
                                           "iteration_callback": self.interrupt})  # fmt: skip
        solver = self.solvers[key]
        self.interrupt.reset(None)  # iterations reported from 0 for each solve
        raise_if_interrupted()
        P = self.parameters(eps, cost_scale)
        sol = solver(x0=self.variables(w, P), p=P, lbg=self.lbg, ubg=self.ubg)
        raise_if_interrupted()  # Ipopt stopped by the callback: the interrupt, not a result
        stats = solver.stats()
        return np.asarray(sol["x"]).ravel()[: self.nw], {
            "status": str(stats["return_status"]), "success": bool(stats["success"]),
            "iterations": int(stats["iter_count"]), "g": np.asarray(sol["g"]).ravel(),
            "lam_g": np.asarray(sol["lam_g"]).ravel(),
        }  # fmt: skip

    def variables(self, w: np.ndarray, P: np.ndarray) -> np.ndarray:
        """The NLP's variables of the scaled controls ``w``: ``w`` itself, and the node states they fly when lifted."""
        if not self.lifted:
            return np.asarray(w, float)
        return np.r_[np.asarray(w, float), np.asarray(self.lift(w, P)).ravel()]

    def rows(self, w: np.ndarray, cost_scale: float) -> np.ndarray:
        """The constraint rows (scaled, as Ipopt sees them) of the plan flown under the scaled controls ``w``.

        Lifted, the NLP's node states of a failed solve need not be the ones its controls fly; these are.
        """
        P = self.parameters(1.0, cost_scale)
        return np.asarray(self._rows(self.variables(w, P), P)).ravel()

    def cost_terms(self, w: np.ndarray, P: np.ndarray) -> tuple[Any, Any, Any]:
        """Tr[MΣ(tf)], the running cost and the control energy of the scaled controls ``w`` at parameters ``P``."""
        return self._cost_terms(self.variables(w, P), P)

    def evaluate(self, w: np.ndarray, cost_scale: float = 1.0) -> ShootingTrajectory:
        """Trajectory and the cost split at ε = 1 of the scaled controls ``w``."""
        P = self.parameters(1.0, cost_scale)
        Zs, pos, vel, U = (np.asarray(v) for v in self.trajectory(self.variables(w, P), P))
        n, N, K = self.n, self.N, self.K
        Z = Zs.reshape(n, n, K + 1, order="F").transpose(2, 0, 1)
        Sigma = self.L @ Z @ self.L.T
        Sigma = 0.5 * (Sigma + Sigma.transpose(0, 2, 1))
        t0 = self.problem.horizon.t0
        phi, run, en = (float(v) for v in self.cost_terms(w, P))
        return ShootingTrajectory(
            t=t0 + self.h * np.arange(K + 1), Sigma=Sigma, p=pos.T.reshape(K + 1, N, 2),
            v=vel.T.reshape(K + 1, N, 2), u=U.T.reshape(K + 1, N, 2), costs=(phi, run, en),
        )  # fmt: skip

    def controls_to_w(self, t: np.ndarray, u: np.ndarray, cost_scale: float) -> np.ndarray:
        """Scaled NLP vector (nw,) from controls ``u`` (T', N, 2) (L/T²) at times ``t`` (T',), linearly interpolated."""
        t_new = self.problem.horizon.t0 + self.h * np.arange(self.K + 1)
        flat = np.asarray(u, float).reshape(len(t), -1)
        U = np.column_stack([np.interp(t_new, t, flat[:, j]) for j in range(flat.shape[1])])
        return (U.T / self.parameters(1.0, cost_scale)[2]).ravel(order="F")
