"""The Pontryagin boundary-value problem of the mobile-sensor Kalman problem (docs/theory/indirect.md §1–§2), by AD.

Everything is derived with CasADi from the model's own functions (:class:`mobisense.ocp.model.SensorKalmanModel`):
no adjoint is written by hand.

Homotopy family (our choice, documented)
----------------------------------------
The direct method's family (docs/theory/direct.md, eq. direct.9; Hussein (2008), eq. 23) divides the whole running cost
by ε. Its ε → 0 limit is the classical Kalman filter (u ≡ 0) only when K = 0 and the terminal sensor state is free;
otherwise it is the nonlinear problem min ∫(α/2|u|² + Tr KΣ) — no longer a Kalman filter to start from. The indirect
method therefore divides only the control energy by ε, and moves fixed terminal states from the coasting end point to
their targets:

    J_ε = Tr[M Σ(tf)] + ∫ (α/(2ε) |u|² + Tr[K Σ]) dt,    x_k(tf) = (1 − ε) x_k^coast(tf) + ε x_k^target.

For K = 0 and free terminal states (the paper's example) this *is* eq. 23; at ε = 0 it is exactly the
Kalman filter with coasting sensors for every problem; at ε = 1 it is problem II.1.

Continuation variable
---------------------
We solve for the costate ``μ = ε λ`` of ``ε J_ε`` (λ the costate of J_ε, docs/theory/indirect.md §1) with

    H̃(x, u, μ) = α/2|u|² + ε Tr[K Σ] + μ'f(x, u) = ε H           (docs/theory/indirect.md, eq. indirect.10)
    u* = argmin_u H̃ = −(1/α) B_s' μ = −(ε/α) B_s' λ                (docs/theory/indirect.md, eq. indirect.10)
    x' = ∂H̃/∂μ = f(x, u*),   μ' = −∂H̃/∂x |_{u*}                   (docs/theory/indirect.md, eq. indirect.11)
    x(t0) = x0,   μ_k(tf) = ε ∂Φ/∂x_k (free components),   x_k(tf) as above (fixed components).

Every unknown stays bounded as ε → 0, and ε = 0 is solved exactly by the coasting states with μ ≡ 0
(the homogeneous adjoint). λ = μ / ε is reported.

The minimiser u* is obtained by AD too: H̃ is quadratic in u (control-affine f, quadratic L), so one
Newton step from u = 0, ``u* = −(∂²H̃/∂u²)⁻¹ ∂H̃/∂u|_{u=0}``, is exact; the constructor checks that the
Hessian does not depend on u. Control bounds (``u_max``) would turn u* into a non-smooth saturation and
are not supported by the indirect method (use the direct method).

Costate of the upper-triangle vector σ: for an off-diagonal σ_ij (standing for Σ_ij and Σ_ji) μ_σij = 2 ε Λ_ij, diagonal
μ_σii = ε Λ_ii, with Λ the symmetric matrix costate of docs/theory/indirect.md §1.5 (eq. indirect.7).

Unknowns are scaled, ``z = y / D`` with y = [x, μ] and D (2 nx,) chosen by the caller, so that the BVP
solvers see O(1) numbers.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from ...core.config import ConfigError
from ..model import SensorKalmanModel, Structure
from ..state_layout import diagonal_indices

__all__ = ["HamiltonianSystem", "hamiltonian_system"]


@dataclass(frozen=True)
class _Functions:
    rhs: ca.Function  # (z, P, D) -> z'
    rhs_jac: ca.Function  # (z, P, D) -> ∂z'/∂z
    bc: ca.Function  # (za, zb, P, D) -> residual
    bc_jac: ca.Function  # (za, zb, P, D) -> (∂/∂za, ∂/∂zb)


class HamiltonianSystem:
    """State–costate system of one problem :class:`~mobisense.ocp.model.Structure`, as CasADi functions.

    Parameters
    ----------
    structure : Structure
        Problem structure (sizes, noise models, which terminal states are fixed).

    Attributes
    ----------
    model : SensorKalmanModel
        The model the Hamiltonian is built from.
    ny : int
        Size 2 nx of y = [x, μ].
    fixed_terminal : ndarray of bool, shape (nx,)
        Components of x fixed at tf (their costate is free there).

    Notes
    -----
    Functions (``z`` (2nx,) scaled unknowns, ``P`` packed parameters, ``D`` (2nx,) scales, y = D z):
    ``hamiltonian(x, mu, P)`` H̃ at u*; ``control(x, mu, P)`` u* (2N,); ``dHdu(x, u, mu, P)`` ∂H̃/∂u;
    ``rhs(z, P, D)`` dz/dt; ``rhs_jac`` its Jacobian; ``bc(za, zb, P, D)`` (2nx,) boundary residuals
    (initial states, then per component of x at tf either the transversality condition or the fixed
    value, all divided by the scale of the unknown they constrain); ``bc_jac`` -> (∂bc/∂za, ∂bc/∂zb).
    """

    def __init__(self, structure: Structure) -> None:
        if any(structure.bounded_control):  # also rejected when the problem is validated (mobisense.ocp.problem)
            raise ConfigError(
                f"sensors[{structure.bounded_control.index(True)}].u_max: expected no control bound with the "
                "indirect method (its control law would be a non-smooth saturation); remove u_max or use "
                "solver.method 'direct'"
            )
        self.structure = s = structure
        self.model = m = SensorKalmanModel(structure)
        self.layout = m.layout
        nx, nu = s.nx, s.nu
        self.ny = 2 * nx
        x = ca.SX.sym("x", nx)
        mu = ca.SX.sym("mu", nx)
        u = ca.SX.sym("u", nu)
        P = ca.SX.sym("P", self.layout.size)
        b = self.layout.unpack(P)

        # docs/theory/indirect.md, eq. indirect.10 (energy-only homotopy):
        # H̃ = α/2|u|² + ε Tr KΣ + μ'f, with running = [L, α/2|u|²]
        L = m.running(x, u, P)
        H = L[1] + b["eps"] * (L[0] - L[1]) + ca.dot(mu, m.f(x, u, P))
        dHdu = ca.gradient(H, u)
        Huu = ca.hessian(H, u)[0]
        if ca.depends_on(Huu, ca.vertcat(u, x, mu)):
            raise NotImplementedError("the indirect method needs a Hamiltonian quadratic in u with constant ∂²H/∂u²")
        # docs/theory/indirect.md, eq. indirect.10: u* = −(ε/α) B_s' λ, here as the exact Newton step from u = 0
        u_star = -ca.solve(Huu, ca.substitute(dHdu, u, ca.DM.zeros(nu)))
        x_dot = ca.substitute(ca.gradient(H, mu), u, u_star)  # = f(x, u*)
        mu_dot = -ca.substitute(ca.gradient(H, x), u, u_star)  # docs/theory/indirect.md, eq. indirect.3: λ' = −∂H/∂x
        self.control = ca.Function("control", [x, mu, P], [u_star], ["x", "mu", "P"], ["u"])
        self.hamiltonian = ca.Function(
            "hamiltonian", [x, mu, P], [ca.substitute(H, u, u_star)], ["x", "mu", "P"], ["H"]
        )
        self.dHdu = ca.Function("dHdu", [x, u, mu, P], [dHdu], ["x", "u", "mu", "P"], ["dHdu"])
        self.costate_rhs = ca.Function("costate_rhs", [x, u, mu, P], [-ca.gradient(H, x)])

        # terminal data: which components are fixed (selection constraints of the model)
        g_T, _ = m.terminal_constraints(x, P)
        fixed = np.zeros(nx, dtype=bool)
        self._constraint_row: dict[int, int] = {}  # fixed component k -> the constraint row fixing it
        if g_T.size1():
            jac = ca.jacobian(g_T, x)
            if ca.depends_on(jac, x):
                raise NotImplementedError("terminal constraints must be linear in the state")
            rows, cols = (np.array(v, dtype=int) for v in jac.sparsity().get_triplet())
            if len(np.unique(cols)) != g_T.size1() or len(cols) != g_T.size1():
                raise NotImplementedError("each terminal constraint must fix one state component")
            fixed[cols] = True
            self._constraint_row = dict(zip(cols.tolist(), rows.tolist(), strict=True))
        self.fixed_terminal = fixed
        self.terminal_gradient = ca.Function("dPhi", [x, P], [ca.gradient(m.terminal(x, P), x)])

        z = ca.SX.sym("z", self.ny)
        D = ca.SX.sym("D", self.ny)
        y = D * z
        z_dot = ca.vertcat(ca.substitute(x_dot, ca.vertcat(x, mu), y), ca.substitute(mu_dot, ca.vertcat(x, mu), y)) / D
        za, zb = ca.SX.sym("za", self.ny), ca.SX.sym("zb", self.ny)
        xa, xb, mub = D[:nx] * za[:nx], D[:nx] * zb[:nx], D[nx:] * zb[nx:]
        terminal = ca.vertcat(*[self._terminal_residual(k, xb, mub, P, b, D) for k in range(nx)])
        bc = ca.vertcat((xa - m.x0(P)) / D[:nx], terminal)
        self._f = _Functions(
            rhs=ca.Function("rhs", [z, P, D], [z_dot]),
            rhs_jac=ca.Function("rhs_jac", [z, P, D], [ca.jacobian(z_dot, z)]),
            bc=ca.Function("bc", [za, zb, P, D], [bc]),
            bc_jac=ca.Function("bc_jac", [za, zb, P, D], [ca.jacobian(bc, za), ca.jacobian(bc, zb)]),
        )
        self._mapped: dict[tuple[str, int], ca.Function] = {}

    def _terminal_residual(self, k: int, xb: ca.SX, mub: ca.SX, P: ca.SX, b: dict, D: ca.SX) -> ca.SX:
        """Residual of component k at tf: fixed value (scaled like x_k) or transversality (scaled like μ_k)."""
        nx = self.structure.nx
        if self.fixed_terminal[k]:
            # x_k(tf) = (1 − ε) x_k^coast(tf) + ε x_k^target; g_T is affine, so this is g_T(x) − (1 − ε) g_T(x^coast)
            g_T, _ = self.model.terminal_constraints(xb, P)
            g_coast, _ = self.model.terminal_constraints(self._coasting_end(P, b), P)
            row = self._constraint_row[k]
            return g_T[row] - (1 - b["eps"]) * g_coast[row]
        dPhi = self.terminal_gradient(xb, P)
        # docs/theory/indirect.md, eq. indirect.6: λ(tf) = ∂Φ/∂x(tf), times ε
        return (mub[k] - b["eps"] * dPhi[k]) / D[nx + k]

    def _coasting_end(self, P: ca.SX, b: dict) -> ca.SX:
        """State at tf of the coasting sensors (u ≡ 0): p0 + v0 (tf − t0), v0 (Σ entries: Σ0, unused)."""
        state = self.structure.state
        x0 = self.model.x0(P)
        p0, v0 = x0[state.positions], x0[state.velocities]
        return ca.vertcat(x0[state.sigma], p0 + v0 * (b["tf"] - b["t0"]), v0)

    # ------------------------------------------------------------------ numeric evaluation
    def _map(self, name: str, m: int) -> ca.Function:
        key = (name, m)
        if key not in self._mapped:
            self._mapped[key] = getattr(self._f, name).map(m, "serial")
        return self._mapped[key]

    def rhs(self, z: np.ndarray, P: np.ndarray, D: np.ndarray) -> np.ndarray:
        """dz/dt at many points: ``z`` (2nx, m) -> (2nx, m)."""
        return np.asarray(self._map("rhs", z.shape[1])(z, P, D))

    def rhs_jac(self, z: np.ndarray, P: np.ndarray, D: np.ndarray) -> np.ndarray:
        """∂(dz/dt)/∂z at many points: ``z`` (2nx, m) -> (2nx, 2nx, m) (scipy ``fun_jac`` layout)."""
        m, ny = z.shape[1], self.ny
        J = np.asarray(self._map("rhs_jac", m)(z, P, D))  # (ny, ny*m), blocks side by side
        return J.reshape(ny, m, ny).transpose(0, 2, 1)

    def bc(self, za: np.ndarray, zb: np.ndarray, P: np.ndarray, D: np.ndarray) -> np.ndarray:
        """Boundary residuals (2nx,)."""
        return np.asarray(self._f.bc(za, zb, P, D)).ravel()

    def bc_jac(self, za: np.ndarray, zb: np.ndarray, P: np.ndarray, D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Jacobians (2nx, 2nx) of the boundary residuals with respect to z(t0) and z(tf)."""
        Ja, Jb = self._f.bc_jac(za, zb, P, D)
        return np.asarray(Ja), np.asarray(Jb)

    @property
    def functions(self) -> _Functions:
        """The scalar (one-point) CasADi functions rhs, rhs_jac, bc, bc_jac (for symbolic solvers)."""
        return self._f

    # ------------------------------------------------------------------ helpers
    def default_scales(self, y_guess: np.ndarray, P: np.ndarray) -> np.ndarray:
        """Scales D (2nx,) of y = [x, μ] from a guess ``y_guess`` (2nx, T) and the parameters ``P``.

        States use max(model scale, max_t |x_k|). Costates of quantities that vary over orders of
        magnitude (Λ spans 1e-5…20 on the default problem) are scaled by their largest value, floored at
        1e-3 of the largest costate of the same kind, so that no scale is zero.
        """
        s = self.structure
        nx = s.nx
        x_scale = np.asarray(self.model.scales(P)[0]).ravel()
        peak = np.abs(y_guess).max(axis=1)
        D = np.empty(2 * nx)
        D[:nx] = np.maximum(x_scale, peak[:nx])
        groups = [np.arange(nx)[block] for block in s.state.groups.values()]
        all_peak = max(float(peak[nx:].max()), 1e-12)
        for group in groups:
            group_peak = max(float(peak[nx + group].max()), 1e-6 * all_peak)
            D[nx + group] = np.maximum(peak[nx + group], 1e-3 * group_peak)
        return D

    def diagonal_sigma(self) -> list[int]:
        """Indices of the diagonal Σ entries in x."""
        return diagonal_indices(self.structure.n)


@lru_cache(maxsize=16)
def hamiltonian_system(structure: Structure) -> HamiltonianSystem:
    """The (cached) :class:`HamiltonianSystem` of ``structure``."""
    return HamiltonianSystem(structure)
