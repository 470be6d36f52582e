"""The per-interval SX kernels of the collocation NLP (docs/theory/direct.md §1.2, §1.7).

Every interval ``k`` of the transcription sees only its own *local vector*
``a_k = [x̃_start (nx), z_k, next_k]``: the scaled state at the interval start, the interval's internal
variables ``z_k = [σ̃ at the d collocation nodes, ũ at the d nodes]`` and the variables it defines at its
end (``next_k``). The sensors' dynamics ``p' = v, v' = u`` are linear, so their collocation equations are
solved exactly (eq. direct.11): positions and velocities at the nodes and at the interval end are linear
maps of ``(p_k, v_k, U_k)`` and only the covariance keeps node variables. Layouts of ``next_k``:

- ``"eliminated"`` (Ipopt): with Radau the last node *is* the interval end, so the next interval starts
  from the covariance at node d and ``next_k`` holds only ``(p̃, ṽ)(t_{k+1})``; schemes without a node at
  τ = 1 (Legendre) keep the whole end state in ``next_k``. ``x̃_0`` is the parameter ``x0(P)/D_x``.
- ``"stage"`` (Fatrop): ``next_k`` is the whole state ``x̃_{k+1}`` (the stage-wise OCP form).

The gap rows ``next_k − end_k(a_k)`` tie the intervals together. :class:`IntervalKernels` builds, once per
structure and layout, the kernel's rows, its quadrature, their gradient, Jacobian and the upper triangle of
the Lagrangian's Hessian in the local variables (the Lagrangian is separable per interval), the node
values for output, and the terminal pieces. The kernels take ``[P; h]`` as input, so one set serves every
number of intervals K. :mod:`mobisense.ocp.direct.kernel_cache` compiles them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from ..collocation import CollocationScheme
from ..model import SensorKalmanModel
from ..state_layout import diagonal_indices

__all__ = ["LAYOUTS", "IntervalKernels", "condensing_matrices"]

#: the local layouts (see module docstring)
LAYOUTS = ("eliminated", "stage")


def condensing_matrices(colloc: CollocationScheme) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The exact collocation solution of ``y' = Fy + Gu`` for the double integrator (eq. direct.11).

    Returns
    -------
    A : ndarray, shape (d, d)
        Butcher matrix ``(D[1:, :]ᵀ)⁻¹``: ``v_r = v_0 + h Σ_j A_rj u_j``.
    A2 : ndarray, shape (d, d)
        ``A @ A``: ``p_r = p_0 + h τ_r v_0 + h² Σ_j A2_rj u_j``.
    e : ndarray, shape (d,)
        Interval-end weights ``E[1:]`` (``y_end = Σ_j E_j y_j``; e = (0, …, 0, 1) for Radau).
    """
    A = np.linalg.inv(colloc.D[1:, :].T)
    return A, A @ A, colloc.E[1:]


@dataclass
class _Nodes:
    """Symbolic node values of one interval (unscaled states and controls, scaled covariance nodes)."""

    x: list[Any]  # (nx,) at each node r = 1..d
    u: list[Any]  # (nu,) at each node
    sigma_scaled: list[Any]  # (ns,) at nodes 0..d (node 0 = interval start)
    y_end: Any  # (4N,) unscaled sensor states at the interval end


class IntervalKernels:
    """SX functions of one collocation interval and of the terminal state (see module docstring).

    Parameters
    ----------
    model : SensorKalmanModel
    colloc : CollocationScheme
    layout : {"eliminated", "stage"}

    Attributes
    ----------
    na, nz, nn : int
        Sizes of the local vector, of the internal variables and of ``next``.
    nr, n_gap, n_path, n_bound : int
        Rows of an interval: gap rows (``n_gap = nn``), collocation rows of σ (``d·ns``) and control-bound
        rows (``d·nb``), in this order.
    functions : dict
        ``k_eval(a, Ph) -> (rows, q, energy)``, ``k_grad(a, Ph) -> (q, ∇q)``, ``k_jac(a, Ph) -> (rows, ∂rows/∂a)``,
        ``k_hess(a, Ph, λ, σ) -> triu ∇²(σ q + λ·rows)``, ``t_eval(x̃_K, P) -> (terminal rows, ε Φ / c_s, Φ)``,
        ``t_grad``, ``t_jac``, ``t_hess`` (the same for the terminal pieces); ``q`` is the interval's running
        cost divided by ``c_s``.
    """

    def __init__(self, model: SensorKalmanModel, colloc: CollocationScheme, layout: str = "eliminated") -> None:
        if layout not in LAYOUTS:
            raise ValueError(f"layout: expected one of {LAYOUTS}, got {layout!r}")
        self.model, self.colloc, self.layout = model, colloc, layout
        s = model.structure
        self.nx, self.nu, self.ns, self.ny, self.d = s.nx, s.nu, s.n_sigma, 4 * s.N, colloc.degree
        self.nb = sum(s.bounded_control)
        self.nz = self.d * self.ns + self.d * self.nu
        #: next_k holds only the sensor states when the covariance at the end is node d's variable
        self.short_next = layout == "eliminated" and colloc.ends_at_node
        self.nn = self.ny if self.short_next else self.nx
        self.na = self.nx + self.nz + self.nn
        self.n_gap, self.n_path, self.n_bound = self.nn, self.d * self.ns, len(colloc.bernstein) * self.nb
        #: path-constraint rows g(x_r, P) ≤ 0 at the d nodes (docs/theory/path_constraints.md §2), last
        self.n_cons = self.d * model.n_path_rows
        self.nr = self.n_gap + self.n_path + self.n_bound + self.n_cons
        self.n_parameters = model.layout.size
        self.functions = self._interval_functions() | self._terminal_functions()
        self.k_nodes, self.k_pv = self._output_functions()

    # ------------------------------------------------------------------ local vector
    def split(self, a: Any) -> tuple[Any, list[Any], list[Any], Any]:
        """(x̃_start, σ̃ at nodes 1..d, ũ at nodes 1..d, next) of a local vector."""
        nx, ns, nu, d = self.nx, self.ns, self.nu, self.d
        sig = [a[nx + r * ns : nx + (r + 1) * ns] for r in range(d)]
        off = nx + d * ns
        u = [a[off + r * nu : off + (r + 1) * nu] for r in range(d)]
        return a[:nx], sig, u, a[nx + self.nz :]

    def diagonal_positions(self) -> np.ndarray:
        """Local positions of the diagonal covariance entries among z and next (bounded below by 0)."""
        diag = diagonal_indices(self.structure.n)
        pos = [self.nx + r * self.ns + k for r in range(self.d) for k in diag]
        if not self.short_next:
            pos += [self.nx + self.nz + k for k in diag]
        return np.array(pos, dtype=int)

    @property
    def structure(self) -> Any:
        """The problem structure of the model."""
        return self.model.structure

    def _nodes(self, a: Any, P: Any, h: Any, y_nodes: Any | None = None) -> _Nodes:
        """Node values; the sensor states at the nodes are condensed (eq. direct.11) unless ``y_nodes`` is given."""
        N, d, ns = self.structure.N, self.d, self.ns
        x_scale, u_scale = self.model.scales(P)
        x_start, sig, u_scaled, _ = self.split(a)
        u = [u_scaled[r] * u_scale for r in range(d)]
        A, A2, e = condensing_matrices(self.colloc)
        tau = self.colloc.tau[1:]
        y0 = x_start[ns:] * x_scale[ns:]
        p0, v0 = y0[: 2 * N], y0[2 * N :]
        U = ca.horzcat(*u)  # (nu, d): column j = u at node j (sensor-major rows, like v)

        def condensed(weights_v: np.ndarray, weights_p: np.ndarray, t: float) -> Any:
            v = v0 + h * ca.mtimes(U, ca.DM(weights_v))
            p = p0 + h * t * v0 + h**2 * ca.mtimes(U, ca.DM(weights_p))
            return ca.vertcat(p, v)

        if y_nodes is None:
            ys = [condensed(A[r], A2[r], tau[r]) for r in range(d)]
        else:
            ys = [y_nodes[r * self.ny : (r + 1) * self.ny] * x_scale[ns:] for r in range(d)]
        y_end = condensed(e @ A, e @ A2, 1.0)
        x = [ca.vertcat(sig[r] * x_scale[:ns], ys[r]) for r in range(d)]
        return _Nodes(x=x, u=u, sigma_scaled=[x_start[:ns], *sig], y_end=y_end)

    def _rows(self, a: Any, Ph: Any, y_nodes: Any | None = None) -> tuple[Any, Any, Any]:
        """(gap, collocation and bound rows; running cost / c_s; control energy) of one interval."""
        m, c, d, ns = self.model, self.colloc, self.d, self.ns
        P, h = Ph[: self.n_parameters], Ph[self.n_parameters]
        b = m.layout.unpack(P)
        x_scale, _ = m.scales(P)
        nodes = self._nodes(a, P, h, y_nodes)
        path, bounds, quad, energy = [], [], 0, 0
        for r in range(d):
            # docs/theory/direct.md, eq. direct.3 for σ: Σ_j D_jr σ̃_j − h f̃_σ(x_r, u_r) = 0
            slope = sum(c.D[j, r] * nodes.sigma_scaled[j] for j in range(d + 1))
            xdot = m.f(nodes.x[r], nodes.u[r], P)
            path.append(slope - h * xdot[:ns] / x_scale[:ns])
            L = m.running(nodes.x[r], nodes.u[r], P)
            quad += h * c.W[r] * L[0]
            energy += h * c.W[r] * L[1]
        for weights in c.bernstein:  # |u| ≤ u_max on the Bernstein coefficients: on the whole interval
            bounds.append(m.control_bounds(sum(w * nodes.u[j] for j, w in enumerate(weights)), P)[0])
        cons = [m.path(nodes.x[r], P) for r in range(d)] if self.n_cons else []
        y_end_scaled = nodes.y_end / x_scale[ns:]
        nxt = a[self.nx + self.nz :]
        if self.short_next:
            gap = nxt - y_end_scaled
        else:
            sigma_end = sum(c.E[j] * nodes.sigma_scaled[j] for j in range(d + 1))
            gap = nxt - ca.vertcat(sigma_end, y_end_scaled)
        return ca.vertcat(gap, *path, *bounds, *cons), quad / b["cost_scale"], energy

    # ------------------------------------------------------------------ functions
    def _interval_functions(self) -> dict[str, ca.Function]:
        a = ca.SX.sym("a", self.na)
        Ph = ca.SX.sym("Ph", self.n_parameters + 1)
        rows, q, energy = self._rows(a, Ph)
        lam = ca.SX.sym("lam", self.nr)
        sigma = ca.SX.sym("sigma")
        hess, _ = ca.hessian(sigma * q + ca.dot(lam, rows), a)
        return {
            "k_eval": ca.Function("k_eval", [a, Ph], [rows, q, energy]),
            "k_grad": ca.Function("k_grad", [a, Ph], [q, ca.gradient(q, a)]),
            "k_jac": ca.Function("k_jac", [a, Ph], [rows, ca.jacobian(rows, a)]),
            "k_hess": ca.Function("k_hess", [a, Ph, lam, sigma], [ca.triu(hess)]),
        }

    def _terminal_functions(self) -> dict[str, ca.Function]:
        m = self.model
        P = ca.SX.sym("P", self.n_parameters)
        b = m.layout.unpack(P)
        x_scale, _ = m.scales(P)
        xK = ca.SX.sym("xK", self.nx)
        x_phys = xK * x_scale
        phi_raw = m.terminal(x_phys, P)
        phi = b["eps"] * phi_raw / b["cost_scale"]
        term, self.terminal_labels = m.terminal_constraints(x_phys, P)
        self.n_term = int(term.numel())
        lam = ca.SX.sym("lam_t", self.n_term)
        sigma = ca.SX.sym("sigma")
        hess, _ = ca.hessian(sigma * phi + ca.dot(lam, term), xK)
        self.x0_scaled = ca.Function("x0_scaled", [P], [m.x0(P) / x_scale])
        return {
            "t_eval": ca.Function("t_eval", [xK, P], [term, phi, phi_raw]),
            "t_grad": ca.Function("t_grad", [xK, P], [phi, ca.gradient(phi, xK)]),
            "t_jac": ca.Function("t_jac", [xK, P], [term, ca.jacobian(term, xK)]),
            "t_hess": ca.Function("t_hess", [xK, P, lam, sigma], [ca.triu(hess)]),
        }

    def _output_functions(self) -> tuple[ca.Function, ca.Function]:
        """``k_nodes(a, Ph) -> (x at nodes (nx, d), u at nodes (nu, d))`` and the costate helper ``k_pv``.

        ``k_pv(a, Ph, λ) -> G (4N, d)``: the gradient of ``q + λ·(σ rows, path-constraint rows)`` w.r.t. the
        scaled sensor states at the nodes, evaluated at their condensed values — what the multipliers of
        the eliminated sensor collocation equations must balance (eq. direct.12).
        """
        a = ca.SX.sym("a", self.na)
        Ph = ca.SX.sym("Ph", self.n_parameters + 1)
        P, h = Ph[: self.n_parameters], Ph[self.n_parameters]
        nodes = self._nodes(a, P, h)
        k_nodes = ca.Function("k_nodes", [a, Ph], [ca.horzcat(*nodes.x), ca.horzcat(*nodes.u)])
        y_nodes = ca.SX.sym("y_nodes", self.d * self.ny)
        rows, q, _ = self._rows(a, Ph, y_nodes)
        lam_path = ca.SX.sym("lam_path", self.n_path + self.n_cons)
        path = ca.vertcat(rows[self.n_gap : self.n_gap + self.n_path], rows[self.nr - self.n_cons :])
        grad = ca.gradient(q + ca.dot(lam_path, path), y_nodes)
        x_scale, _ = self.model.scales(P)
        condensed = ca.vertcat(*[x[self.ns :] / x_scale[self.ns :] for x in nodes.x])
        grad = ca.substitute(grad, y_nodes, condensed)
        return k_nodes, ca.Function("k_pv", [a, Ph, lam_path], [ca.reshape(grad, self.ny, self.d)])

    def fingerprint(self) -> str:
        """A cheap summary of the generated functions (sizes and instruction counts), part of the cache key."""
        parts = []
        for name, f in sorted(self.functions.items()):
            sp = (
                ",".join(f"{f.nnz_in(i)}" for i in range(f.n_in()))
                + "/"
                + ",".join(f"{f.nnz_out(i)}" for i in range(f.n_out()))
            )
            parts.append(f"{name}:{sp}:{f.n_instructions()}")
        return ";".join(parts)
