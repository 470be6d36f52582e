"""Collocation + Newton solver of the Pontryagin BVP, with ε as an optional unknown (for arclength steps).

Unknowns on a mesh ``t_0 < … < t_K`` (scaled, see :mod:`mobisense.ocp.indirect.hamiltonian`): ``W = [z_0, Z_0, z_1,
Z_1, …, z_K]`` with ``z_k`` (ny,) at the interval starts and ``Z_k`` (ny d,) at the d collocation nodes of interval k.
Residuals, all O(1) for O(1) unknowns (time normalised by the horizon T = t_K − t_0):

    collocation  T (Σ_j D[j,r] z_j / h_k − f(Z_r)) = 0          (d ny per interval)
    continuity   z_{k+1} − Σ_j E[j] z_j = 0                     (ny per interval)
    boundary     bc(z_0, z_K; ε) = 0                            (ny: nx initial, nx terminal)

— a square sparse system solved by damped Newton with a sparse LU (SuperLU), rows in staircase order
(initial conditions, interval by interval, terminal conditions) so that no fill-reducing column
permutation is needed. The same residual with ε appended as an unknown, bordered by one arclength
equation, is what :mod:`mobisense.ocp.indirect.arclength` uses to pass folds of the solution curve. Radau IIA
collocation of degree d is of order 2d − 1 at the mesh points, Gauss–Legendre of order 2d (the schemes
of :mod:`mobisense.ocp.collocation`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ...core.interrupts import raise_if_interrupted
from ..collocation import CollocationScheme
from ..model import Structure
from .hamiltonian import HamiltonianSystem, hamiltonian_system

__all__ = ["CollocationMesh", "NewtonResult", "newton", "factorise", "collocation_mesh"]


def factorise(J: sp.spmatrix) -> Any:
    """Sparse LU of a staircase-ordered collocation Jacobian (natural column order, see the residual)."""
    return splu(sp.csc_matrix(J), permc_spec="NATURAL")


@dataclass
class NewtonResult:
    """Outcome of :func:`newton`: solution X, convergence flag, iterations, final residual (max norm)."""

    X: np.ndarray
    success: bool
    iterations: int
    residual: float
    message: str
    time_s: float = 0.0


def newton(
    residual: Any,
    X0: np.ndarray,
    tolerance: float,
    max_iterations: int,
    divergence: float = 1e6,
) -> NewtonResult:
    """Damped Newton on ``residual(X) -> (F, J)`` (J sparse) until ``max|F| <= tolerance``.

    Each step halves the Newton step (up to 8 times) until ``|F|₂`` decreases; stops on stagnation,
    a singular Jacobian, an iterate with ``max|X| > divergence``, or ``max_iterations``.
    """
    t_start = time.perf_counter()
    X = np.array(X0, float)
    F, J = residual(X)
    norm = float(np.abs(F).max())
    for iteration in range(max_iterations + 1):
        raise_if_interrupted()  # the residual is evaluated by CasADi, whose bindings can swallow a Ctrl-C
        if not np.isfinite(norm):
            return NewtonResult(X, False, iteration, norm, "non-finite residual", time.perf_counter() - t_start)
        if norm <= tolerance:
            return NewtonResult(X, True, iteration, norm, "converged", time.perf_counter() - t_start)
        if iteration == max_iterations:
            break
        try:
            step = factorise(J).solve(-F)
        except RuntimeError:
            return NewtonResult(X, False, iteration, norm, "singular Jacobian", time.perf_counter() - t_start)
        fnorm2 = float(F @ F)
        damping = 1.0
        for _ in range(9):
            X_new = X + damping * step
            F_new, J_new = residual(X_new)
            if np.all(np.isfinite(F_new)) and float(F_new @ F_new) < fnorm2:
                break
            damping *= 0.5
        else:
            return NewtonResult(
                X, False, iteration, norm, "no descent along the Newton step", time.perf_counter() - t_start
            )
        X, F, J = X_new, F_new, J_new
        norm = float(np.abs(F).max())
        if np.abs(X).max() > divergence:
            return NewtonResult(X, False, iteration + 1, norm, "diverged", time.perf_counter() - t_start)
    return NewtonResult(X, False, max_iterations, norm, "too many iterations", time.perf_counter() - t_start)


@dataclass
class CollocationMesh:
    """The collocation BVP of one structure on K intervals: residual, Jacobians, cost and sampling.

    Build with :func:`collocation_mesh` (cached). Methods take the mesh ``t`` (K+1,), the parameters
    ``P``, scales ``D`` (ny,) and ε (the ε entry of P is overridden, so one function serves the whole
    continuation).
    """

    system: HamiltonianSystem
    scheme: CollocationScheme
    intervals: int
    functions: dict[str, ca.Function] = field(default_factory=dict)

    def __post_init__(self) -> None:
        s = self.system
        ny, d, K = s.ny, self.scheme.degree, self.intervals
        self.ny = ny
        self.per_interval = ny * (d + 1)
        self.nw = K * self.per_interval + ny
        eps_index = s.layout.offsets["eps"][0]
        W = ca.MX.sym("W", self.nw)
        eps = ca.MX.sym("eps")
        P = ca.MX.sym("P", s.layout.size)
        D = ca.MX.sym("D", ny)
        t = ca.MX.sym("t", K + 1)
        Pe = ca.vertcat(P[:eps_index], eps, P[eps_index + 1 :])
        blocks = ca.reshape(W[: K * self.per_interval], self.per_interval, K)
        z_start = blocks[:ny, :]
        Zc = blocks[ny:, :]
        z_next = ca.horzcat(blocks[:ny, 1:], W[K * self.per_interval :])
        h = (t[1:] - t[:-1]).T
        horizon = t[K] - t[0]
        coll, z_end = self._interval_kernel().map(K, "serial")(z_start, Zc, h, horizon, Pe, D)
        bc = s.functions.bc(W[:ny], W[K * self.per_interval :], Pe, D)
        # staircase order (initial conditions, then per interval its collocation and continuity rows, then the
        # terminal conditions): the Jacobian is almost block-banded and SuperLU needs no fill-reducing
        # column permutation (2.8x faster factorisation than COLAMD on the default problem)
        nx = s.structure.nx
        F = ca.vertcat(bc[:nx], ca.vec(ca.vertcat(coll, z_next - z_end)), bc[nx:])
        residual = ca.Function("residual", [W, eps, P, D, t], [F]).expand()
        Ws, es = ca.SX.sym("W", self.nw), ca.SX.sym("eps")
        Ps, Ds, ts = ca.SX.sym("P", s.layout.size), ca.SX.sym("D", ny), ca.SX.sym("t", K + 1)
        Fs = residual(Ws, es, Ps, Ds, ts)
        args = [Ws, es, Ps, Ds, ts]
        J = ca.jacobian(Fs, Ws)
        colind, row = J.sparsity().get_ccs()
        self._csc_structure = (np.asarray(row), np.asarray(colind), J.shape)
        self.functions = {
            "residual": ca.Function("F", args, [Fs]),
            # Jacobian nonzeros as a dense vector (CCS order): converts to numpy without a Python list
            "linearise": ca.Function(
                "linearise", args, [Fs, ca.vertcat(*J.nonzeros()), ca.densify(ca.jacobian(Fs, es))]
            ),
            "costs": self._cost_function(),
        }

    def _interval_kernel(self) -> ca.Function:
        """Scaled collocation residuals of one interval and its end value (eq. indirect.13)."""
        s, c = self.system, self.scheme
        ny, d = s.ny, c.degree
        z0 = ca.SX.sym("z0", ny)
        Zc = ca.SX.sym("Zc", ny * d)
        h = ca.SX.sym("h")
        horizon = ca.SX.sym("T")
        P = ca.SX.sym("P", s.layout.size)
        D = ca.SX.sym("D", ny)
        nodes = [z0] + [Zc[r * ny : (r + 1) * ny] for r in range(d)]
        residuals = []
        for r in range(d):
            slope = sum(c.D[j, r] * nodes[j] for j in range(d + 1)) / h
            residuals.append(horizon * (slope - s.functions.rhs(nodes[r + 1], P, D)))
        z_end = sum(c.E[j] * nodes[j] for j in range(d + 1))
        return ca.Function("interval", [z0, Zc, h, horizon, P, D], [ca.vertcat(*residuals), z_end])

    def _cost_function(self) -> ca.Function:
        """(Φ, ∫L, ∫α/2|u|²) of the collocation solution by the scheme's quadrature (order 2d−1 / 2d)."""
        s, c, K = self.system, self.scheme, self.intervals
        ny, nx, d = s.ny, s.structure.nx, c.degree
        W = ca.SX.sym("W", self.nw)
        P = ca.SX.sym("P", s.layout.size)
        D = ca.SX.sym("D", ny)
        t = ca.SX.sym("t", K + 1)
        running, energy = 0, 0
        for k in range(K):
            h = t[k + 1] - t[k]
            for r in range(d):
                y = D * W[k * self.per_interval + ny * (r + 1) : k * self.per_interval + ny * (r + 2)]
                u = s.control(y[:nx], y[nx:], P)
                L = s.model.running(y[:nx], u, P)
                running += h * c.W[r] * L[0]
                energy += h * c.W[r] * L[1]
        xT = D[:nx] * W[K * self.per_interval : K * self.per_interval + nx]
        return ca.Function("costs", [W, P, D, t], [s.model.terminal(xT, P), running, energy])

    # ------------------------------------------------------------------ numeric interface
    def linearise(
        self, W: np.ndarray, eps: float, P: np.ndarray, D: np.ndarray, t: np.ndarray
    ) -> tuple[np.ndarray, sp.csc_matrix, np.ndarray]:
        """Residual F (nw,), its sparse Jacobian ∂F/∂W (nw, nw) and ∂F/∂ε (nw,)."""
        F, J_nz, F_eps = self.functions["linearise"](W, eps, P, D, t)
        row, colind, shape = self._csc_structure
        J = sp.csc_matrix((np.asarray(J_nz).ravel(), row, colind), shape=shape)
        return np.asarray(F).ravel(), J, np.asarray(F_eps).ravel()

    def costs(self, W: np.ndarray, P: np.ndarray, D: np.ndarray, t: np.ndarray) -> tuple[float, float, float]:
        """Terminal cost Φ, running cost ∫L and control energy ∫α/2|u|² (unscaled)."""
        return tuple(float(v) for v in self.functions["costs"](W, P, D, t))  # type: ignore[return-value]

    def pack(self, t: np.ndarray, sample: Any) -> np.ndarray:
        """Scaled unknowns W from a callable ``sample(times) -> z (ny, len(times))``."""
        starts, nodes = self.times(t)
        zs = sample(starts)
        zc = sample(nodes.ravel()).reshape(self.ny, self.intervals, -1)
        W = np.empty(self.nw)
        K = self.intervals
        blocks = np.concatenate([zs[:, :K, None], zc], axis=2)  # (ny, K, d+1)
        W[: K * self.per_interval] = blocks.transpose(1, 2, 0).reshape(-1)
        W[K * self.per_interval :] = zs[:, K]
        return W

    def unpack(self, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(z at starts (ny, K+1), z at nodes (ny, K, d)) from W."""
        K, ny, d = self.intervals, self.ny, self.scheme.degree
        blocks = W[: K * self.per_interval].reshape(K, d + 1, ny)
        zs = np.concatenate([blocks[:, 0, :], W[None, K * self.per_interval :]]).T
        return zs, blocks[:, 1:, :].transpose(2, 0, 1)

    def times(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Interval starts (K+1,) and collocation times (K, d) of mesh ``t``."""
        h = np.diff(t)
        return t, t[:-1, None] + h[:, None] * self.scheme.tau[None, 1:]

    def node_values(self, W: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """All distinct node times (sorted) and the scaled unknowns there (ny, M)."""
        starts, nodes = self.times(t)
        zs, zc = self.unpack(W)
        times = np.concatenate([starts, nodes.ravel()])
        values = np.concatenate([zs, zc.reshape(self.ny, -1)], axis=1)
        order = np.argsort(times, kind="stable")
        keep = np.concatenate([[True], np.diff(times[order]) > 1e-12 * (t[-1] - t[0])])
        return times[order][keep], values[:, order][:, keep]

    def sample(self, W: np.ndarray, t: np.ndarray, times: np.ndarray) -> np.ndarray:
        """The collocation polynomial (degree d, through start and nodes) at ``times``: (ny, len(times))."""
        zs, zc = self.unpack(W)
        times = np.asarray(times, float)
        k = np.clip(np.searchsorted(t, times, side="right") - 1, 0, self.intervals - 1)
        weights = self.scheme.interpolation_matrix((times - t[k]) / (t[k + 1] - t[k]), nodes="all")
        values = np.concatenate([zs[:, k, None], zc[:, k, :]], axis=2)  # (ny, len(times), d+1)
        return np.einsum("ymj,mj->ym", values, weights)


@lru_cache(maxsize=8)
def _cached_mesh(structure: Structure, scheme: str, degree: int, intervals: int) -> CollocationMesh:
    return CollocationMesh(hamiltonian_system(structure), CollocationScheme(scheme, degree), intervals)


def collocation_mesh(structure: Structure, scheme: str, degree: int, intervals: int) -> CollocationMesh:
    """The (cached) collocation BVP for one structure, scheme, degree and number of intervals."""
    return _cached_mesh(structure, scheme, degree, intervals)
