"""Independent reference transcription of the mobile-sensor Kalman OCP (no mobisense code).

The fair comparison for mobisense's direct method: what an expert would write with plain CasADi —
Radau collocation of degree 3 on K uniform intervals, controls at the collocation points, one SX
expression graph handed to Ipopt/MUMPS with MUMPS' matching and scaling switched off
(``mumps_permuting_scaling 0``, ``mumps_scaling 0``), exact Hessian, the coasting trajectory
(u ≡ 0, Σ from the Riccati ODE, integrated with CVODES) as the initial guess, and one cold solve at
ε = 1 (no homotopy).

Problem (docs/theory/ocp.md §1, same YAML schema as mobisense's problem files, the subset used here: no
terminal constraints, no control bounds, noise model ``quadratic_range`` or ``constant``)::

    Σ' = A Σ + Σ A' + B Q B' − Σ S(p) Σ,   S(p) = Σ_i C_i' diag(1/r_ij(p_i)) C_i
    r_ij = β_i |p_i − s_ij|² + γ_i        (s_ij: |c|-weighted mean location of the states row j measures)
    p_i' = v_i,  v_i' = u_i
    J = Tr[M Σ(tf)] + ∫ (α/2 |u|² + Tr[K Σ]) dt

Σ is represented by its upper triangle; variables are scaled by nominal values (Σ_ij by
sqrt(Σ0_ii Σ0_jj), positions by the largest initial sensor–state distance L, velocities by
max(L/T, |v0|), controls by that velocity / T).

Usage::

    python benchmarks/reference_transcription.py problems/hussein2008.yaml [--intervals K] [--tol 1e-9]
    python benchmarks/reference_transcription.py --synthetic n N SEED [--intervals K]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import dataclass
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # CasADi's OpenBLAS spin-waits otherwise

import casadi as ca  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["synthetic_problem", "ReferenceOCP", "ReferenceResult", "radau_matrices", "IPOPT_REFERENCE"]

#: 'The tuning every expert would apply': MUMPS without matching-based permutation and scaling.
IPOPT_REFERENCE: dict[str, Any] = {
    "linear_solver": "mumps",
    "mumps_permuting_scaling": 0,
    "mumps_scaling": 0,
    "print_level": 0,
    "sb": "yes",
}


# ---------------------------------------------------------------------------------------------- problems
def synthetic_problem(n: int, N: int, seed: int, intervals: int = 100, tf: float = 10.0) -> dict[str, Any]:
    """A random problem dict in the YAML schema: n coupled states, N sensors, random geometry.

    Parameters
    ----------
    n, N : int
        Process states (1–4) and sensors (1–8).
    seed : int
        Seed of the geometry (state locations in a 6×6 box, sensors on a ring of radius 8–12 with random
        initial velocities), the drift matrix A and the noise parameters.
    intervals : int
        ``solver.collocation.intervals``.
    tf : float
        Horizon length.

    Returns
    -------
    dict
        Problem dict (mobisense ``Problem.from_dict`` accepts it unchanged).
    """
    rng = np.random.default_rng(10_000 * n + 100 * N + seed)
    A = -0.4 * np.eye(n) + 0.15 * rng.standard_normal((n, n))
    G = rng.standard_normal((n, n))
    Q = 0.5 * np.eye(n) + 0.1 * G @ G.T
    locations = rng.uniform(-3.0, 3.0, (n, 2))
    sensors = []
    for i in range(N):
        phi = 2 * np.pi * (i + rng.uniform(0.0, 0.8)) / N
        radius = rng.uniform(8.0, 12.0)
        p0 = radius * np.array([np.cos(phi), np.sin(phi)])
        v0 = rng.uniform(-1.0, 1.0, 2)
        sensors.append(
            {
                "name": f"s{i}",
                "p0": p0.round(6).tolist(),
                "v0": v0.round(6).tolist(),
                "noise": {
                    "model": "quadratic_range",
                    "beta": round(float(rng.uniform(0.5, 3.0)), 6),
                    "gamma": round(float(rng.uniform(0.5, 3.0)), 6),
                },
            }
        )
    return {
        "name": f"synthetic_n{n}_N{N}_s{seed}",
        "horizon": {"t0": 0.0, "tf": tf},
        "process": {
            "A": A.round(6).tolist(),
            "B": np.eye(n).tolist(),
            "Q": Q.round(6).tolist(),
            "Sigma0": (50.0 * np.eye(n)).tolist(),
            "locations": locations.round(6).tolist(),
        },
        "sensors": sensors,
        "cost": {"M": (10.0 * np.eye(n)).tolist(), "K": np.eye(n).tolist(), "alpha": 0.05},
        "solver": {"collocation": {"scheme": "radau", "degree": 3, "intervals": intervals}},
    }


def radau_matrices(d: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Radau IIA collocation on [0, 1]: nodes tau (d+1,) incl. 0, derivative D (d+1, d), end E (d+1,), weights W (d,).

    ``sum_j D[j, r] x_j = h f(x_r)`` are the collocation equations at node r; ``W`` integrates the
    interpolant of values at the d collocation nodes.
    """
    tau = np.append(0.0, ca.collocation_points(d, "radau"))
    D = np.zeros((d + 1, d))
    E = np.zeros(d + 1)
    for j in range(d + 1):
        others = np.delete(tau, j)
        basis = np.poly1d(others, r=True) / np.prod(tau[j] - others)
        E[j] = basis(1.0)
        D[j] = basis.deriv()(tau[1:])
    W = np.zeros(d)
    for j in range(d):
        others = np.delete(tau[1:], j)
        basis = np.poly1d(others, r=True) / np.prod(tau[j + 1] - others)
        W[j] = basis.integ()(1.0)
    return tau, D, E, W


# ---------------------------------------------------------------------------------------------- the OCP
@dataclass
class ReferenceResult:
    """One solve: cost J, Ipopt status and iterations, wall time of the solver call (s)."""

    J: float
    status: str
    success: bool
    iterations: int
    solve_s: float
    x: np.ndarray
    u: np.ndarray
    stats: dict[str, Any]


class ReferenceOCP:
    """Radau collocation NLP of one problem dict, solved by Ipopt from the coasting trajectory.

    Parameters
    ----------
    data : dict
        Problem in the YAML schema (see :func:`synthetic_problem`).
    intervals : int, optional
        K (default ``data['solver']['collocation']['intervals']`` or 100).
    degree : int
        Collocation degree (Radau).
    ipopt_options : dict, optional
        Overrides of :data:`IPOPT_REFERENCE`.
    tol : float
        Ipopt ``tol``.
    """

    def __init__(
        self,
        data: dict[str, Any],
        intervals: int | None = None,
        degree: int = 3,
        ipopt_options: dict[str, Any] | None = None,
        tol: float = 1e-9,
        max_iter: int = 3000,
    ) -> None:
        t_build = time.perf_counter()
        self.data = data
        K = intervals or data.get("solver", {}).get("collocation", {}).get("intervals", 100)
        self.K, self.d = K, degree
        proc, cost = data["process"], data["cost"]
        A = np.asarray(proc["A"], float)
        B = np.asarray(proc["B"], float)
        BQB = B @ np.asarray(proc["Q"], float) @ B.T
        Sigma0 = np.asarray(proc["Sigma0"], float)
        locs = np.asarray(proc["locations"], float)
        M = np.asarray(cost["M"], float)
        Kw = np.zeros_like(M) if cost.get("K") is None else np.asarray(cost["K"], float)
        alpha = float(cost["alpha"])
        n = A.shape[0]
        sensors = data["sensors"]
        N = len(sensors)
        self.n, self.N = n, N
        tri = [(i, j) for i in range(n) for j in range(i, n)]
        ns = len(tri)
        nx, nu = ns + 4 * N, 2 * N
        self.nx, self.nu = nx, nu
        t0, tf = float(data["horizon"].get("t0", 0.0)), float(data["horizon"]["tf"])
        self.t0, self.tf = t0, tf
        T = tf - t0
        h = T / K

        # measurement rows: (sensor, row vector c, location, beta, gamma)
        rows = []
        for i, s in enumerate(sensors):
            C = np.eye(n) if s.get("measures") is None else np.asarray(s["measures"], float)
            noise = s["noise"]
            for c in C:
                loc = np.abs(c) @ locs / np.abs(c).sum()
                if noise["model"] == "quadratic_range":
                    rows.append((i, c, loc, float(noise["beta"]), float(noise["gamma"])))
                elif noise["model"] == "constant":
                    rows.append((i, c, loc, 0.0, float(noise["variance_value"])))
                else:
                    raise NotImplementedError(noise["model"])
            if s.get("terminal") or s.get("u_max"):
                raise NotImplementedError("terminal constraints / control bounds are not in the reference")

        # nominal values (scaling)
        dg = np.sqrt(np.diag(Sigma0))
        L = max(1.0, max(np.linalg.norm(np.asarray(s["p0"]) - l) for s in sensors for l in locs))
        V = max(L / T, max(np.linalg.norm(s["v0"]) for s in sensors))
        xs = np.concatenate([[dg[i] * dg[j] for i, j in tri], np.full(2 * N, L), np.full(2 * N, V)])
        us = np.full(nu, V / T)
        self.x_scale, self.u_scale = xs, us
        x0 = np.concatenate(
            [[Sigma0[i, j] for i, j in tri], *[s["p0"] for s in sensors], *[s["v0"] for s in sensors]]
        )
        self.x0 = x0

        # dynamics (unscaled) as an SX function
        x = ca.SX.sym("x", nx)
        u = ca.SX.sym("u", nu)
        Sig = ca.SX(n, n)
        for k, (i, j) in enumerate(tri):
            Sig[i, j] = x[k]
            Sig[j, i] = x[k]
        S = ca.SX(n, n)
        for i, c, loc, beta, gamma in rows:
            p = x[ns + 2 * i : ns + 2 * i + 2]
            r = beta * ca.sumsqr(p - loc) + gamma
            S += ca.DM(np.outer(c, c)) / r
        dSig = ca.mtimes(A, Sig) + ca.mtimes(Sig, A.T) + BQB - ca.mtimes([Sig, S, Sig])
        xdot = ca.vertcat(*[dSig[i, j] for i, j in tri], x[ns + 2 * N : ns + 4 * N], u)
        Lrun = 0.5 * alpha * ca.sumsqr(u) + ca.trace(ca.mtimes(Kw, Sig))
        self.f = ca.Function("f", [x, u], [xdot, Lrun])
        self.terminal = ca.Function("phi", [x], [ca.trace(ca.mtimes(M, Sig))])

        # collocation NLP (scaled variables), interval-major: [x_k, X_k1..d, U_k1..d] ..., x_K
        tau, D, E, W = radau_matrices(degree)
        self.tau = tau
        w, lbw, ubw, g = [], [], [], []
        diag = [k for k, (i, j) in enumerate(tri) if i == j]
        lb_x = np.full(nx, -np.inf)
        lb_x[diag] = 0.0
        J = 0
        Xk = ca.SX.sym("x_0", nx)
        w.append(Xk)
        lbw.append(x0 / xs)
        ubw.append(x0 / xs)  # initial state fixed by bounds
        self.idx = {"xs": [], "xc": [], "u": []}
        offset = nx
        self.idx["xs"].append(np.arange(nx))
        for k in range(K):
            Xc = [ca.SX.sym(f"X_{k}_{r}", nx) for r in range(degree)]
            Uc = [ca.SX.sym(f"U_{k}_{r}", nu) for r in range(degree)]
            for Xr in Xc:
                w.append(Xr)
                lbw.append(lb_x / xs)
                ubw.append(np.full(nx, np.inf))
                self.idx["xc"].append(np.arange(offset, offset + nx))
                offset += nx
            for Ur in Uc:
                w.append(Ur)
                lbw.append(np.full(nu, -np.inf))
                ubw.append(np.full(nu, np.inf))
                self.idx["u"].append(np.arange(offset, offset + nu))
                offset += nu
            nodes = [Xk] + Xc
            for r in range(degree):
                fr, Lr = self.f(Xc[r] * xs, Uc[r] * us)
                slope = sum(D[j, r] * nodes[j] for j in range(degree + 1))
                g.append(slope - h * fr / xs)
                J += h * W[r] * Lr
            x_end = sum(E[j] * nodes[j] for j in range(degree + 1))
            Xk = ca.SX.sym(f"x_{k + 1}", nx)
            w.append(Xk)
            lbw.append(lb_x / xs)
            ubw.append(np.full(nx, np.inf))
            self.idx["xs"].append(np.arange(offset, offset + nx))
            offset += nx
            g.append(x_end - Xk)
        J += self.terminal(Xk * xs)
        self.w = ca.vertcat(*w)
        self.lbw, self.ubw = np.concatenate(lbw), np.concatenate(ubw)
        g = ca.vertcat(*g)
        self.ng = g.shape[0]
        self.nw = self.w.shape[0]
        self.J = ca.Function("J", [self.w], [J])
        self.ipopt_options = {**IPOPT_REFERENCE, "tol": tol, "max_iter": max_iter, **(ipopt_options or {})}
        self.solver = ca.nlpsol(
            "reference",
            "ipopt",
            {"x": self.w, "f": J, "g": g},
            {"ipopt": self.ipopt_options, "print_time": False, "error_on_fail": False},
        )
        self.build_s = time.perf_counter() - t_build

    # ------------------------------------------------------------------ guess and solve
    def node_times(self) -> np.ndarray:
        """Times of every state in w (interval starts and collocation nodes), in w's order."""
        h = (self.tf - self.t0) / self.K
        t = [self.t0]
        for k in range(self.K):
            t += list(self.t0 + h * (k + self.tau[1:]))
            t.append(self.t0 + h * (k + 1))
        return np.array(t)

    def coasting_guess(self) -> np.ndarray:
        """Scaled decision vector of the coasting trajectory (u ≡ 0), integrated with CVODES."""
        x = ca.SX.sym("x", self.nx)
        xdot, Lr = self.f(x, ca.DM.zeros(self.nu))
        t_all = self.node_times()
        grid = np.unique(t_all)
        F = ca.integrator(
            "coast", "cvodes", {"x": x, "ode": xdot}, self.t0, grid[1:].tolist(), {"abstol": 1e-12, "reltol": 1e-12}
        )
        X = np.column_stack([self.x0, np.asarray(F(x0=self.x0)["xf"])])
        states = X[:, np.searchsorted(grid, t_all - 1e-12)].T  # (len(t_all), nx)
        w0 = np.zeros(self.nw)
        xs_idx = np.concatenate([self.idx["xs"][0]] + [np.concatenate(p) for p in self._state_blocks()])
        w0[xs_idx] = (states / self.x_scale).ravel()
        return w0

    def _state_blocks(self) -> list[list[np.ndarray]]:
        """Per interval: the index blocks of its collocation states and its end state, in time order."""
        d = self.d
        return [self.idx["xc"][k * d : (k + 1) * d] + [self.idx["xs"][k + 1]] for k in range(self.K)]

    def solve(self, w0: np.ndarray | None = None) -> ReferenceResult:
        """Solve from ``w0`` (default: coasting); cost, status, iterations, wall time."""
        w0 = self.coasting_guess() if w0 is None else w0
        t = time.perf_counter()
        sol = self.solver(x0=w0, lbx=self.lbw, ubx=self.ubw, lbg=0.0, ubg=0.0)
        elapsed = time.perf_counter() - t
        st = self.solver.stats()
        wopt = np.asarray(sol["x"]).ravel()
        xc = np.array([wopt[i] for i in self.idx["xc"]]) * self.x_scale
        u = np.array([wopt[i] for i in self.idx["u"]]) * self.u_scale
        return ReferenceResult(
            J=float(sol["f"]),
            status=str(st["return_status"]),
            success=bool(st["success"]),
            iterations=int(st["iter_count"]),
            solve_s=elapsed,
            x=xc,
            u=u,
            stats=st,
        )


# ---------------------------------------------------------------------------------------------- CLI
def main(argv: list[str] | None = None) -> int:
    """Solve one problem file (or a synthetic problem) and print J, iterations and times."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("problem", nargs="?", help="problem YAML file")
    parser.add_argument("--synthetic", nargs=3, type=int, metavar=("n", "N", "SEED"))
    parser.add_argument("--intervals", type=int, default=None)
    parser.add_argument("--tol", type=float, default=1e-9)
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    if args.synthetic:
        data = synthetic_problem(*args.synthetic)
    else:
        import yaml

        with open(args.problem, encoding="utf-8") as fh:
            data = yaml.safe_load(fh)
    ocp = ReferenceOCP(data, intervals=args.intervals, tol=args.tol)
    res = ocp.solve()
    print(
        f"{data['name']}: K = {ocp.K}, nw = {ocp.nw}, J = {res.J:.12g}, {res.status}, {res.iterations} iterations, "
        f"build {ocp.build_s:.3f} s, solve {res.solve_s:.3f} s, total {time.perf_counter() - t0:.3f} s"
    )
    return 0 if res.success else 1


if __name__ == "__main__":
    sys.exit(main())
