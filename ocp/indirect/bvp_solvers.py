"""BVP solvers of the Pontryagin system behind one interface, registered by name (``solver.bvp.solver``).

A solver is built for one problem (its Hamiltonian system, parameters and unknown scales) and offers:

- ``solve(eps, guess)`` — solve at a fixed ε from a guess ``y(t)`` (a callable, e.g. the direct solution);
- ``follow(start, eps)`` — continue from an accepted solution of the same solver to ε (the homotopy).

Both return a :class:`BVPSolution` (nodes, unknowns, dense evaluation, cost pieces, solver report).
To add a solver, subclass :class:`BVPSolver` and decorate it with :func:`register_bvp_solver`: it is then a
choice of ``solver.bvp.solver`` and ``solver.bvp.refine_solver`` (:data:`mobisense.ocp.registries.BVP_SOLVERS`).

Solvers:

``collocation``
    CasADi collocation (the scheme and degree of ``solver.collocation``) on a uniform mesh of
    ``solver.bvp.intervals`` intervals, damped sparse Newton, and arclength continuation in ε
    (:mod:`mobisense.ocp.indirect.arclength`) — passes the folds of the default problem's solution curve.
``scipy``
    ``scipy.integrate.solve_bvp`` (4th-order Lobatto IIIA collocation with residual control and mesh
    refinement) with the vectorised CasADi right-hand side and exact Jacobians ``fun_jac``/``bc_jac``.
    Its continuation is natural-parameter (one ε at a time, each solve seeded by the last — Hussein's (2008)
    method), which cannot pass a fold: on the default problem it stops at ε ≈ 0.006, or, with the paper's
    δ = 0.05, fails at its first step (docs/theory/indirect.md §3.4).
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..model import Structure
from ..problem import Problem
from ..registries import BVP_SOLVERS
from .arclength import ArclengthTracker
from .collocation_newton import collocation_mesh, newton
from .hamiltonian import HamiltonianSystem, hamiltonian_system

__all__ = ["BVPSolution", "BVPSolver", "register_bvp_solver", "CollocationBVP", "ScipyBVP"]

#: y(t) guess: times (T,) -> unscaled y = [x; μ] of shape (2 nx, T)
Guess = Callable[[np.ndarray], np.ndarray]


@dataclass
class BVPSolution:
    """A (possibly failed) solution of the BVP at one ε.

    Attributes
    ----------
    eps : float
        Homotopy parameter.
    t : ndarray, shape (m,)
        Node times (T).
    y : ndarray, shape (2 nx, m)
        Unscaled [x; μ] at the nodes (μ = ε λ, see :mod:`mobisense.ocp.indirect.hamiltonian`).
    evaluate : callable
        Dense solution: times (T,) -> (2 nx, T).
    terminal_cost, running_cost, control_energy : float
        Φ = Tr[M Σ(tf)], ∫L = ∫(α/2|u|² + Tr KΣ) and ∫α/2|u|² of the solution.
    """

    eps: float
    t: np.ndarray
    y: np.ndarray
    evaluate: Guess
    terminal_cost: float
    running_cost: float
    control_energy: float
    success: bool
    message: str
    iterations: int
    time_s: float
    report: dict[str, Any] = field(default_factory=dict)
    raw: Any = None

    @property
    def nodes(self) -> int:
        """Number of time nodes of the discretisation."""
        return int(self.t.size)

    @property
    def cost_eps(self) -> float:
        """J_ε = Φ + ∫ Tr KΣ + (1/ε) ∫ α/2|u|² (the homotopy family of :mod:`mobisense.ocp.indirect.hamiltonian`)."""
        if self.eps <= 0:
            return float("inf")
        return self.terminal_cost + (self.running_cost - self.control_energy) + self.control_energy / self.eps


class BVPSolver(ABC):
    """Base class: a BVP solver for one problem.

    Parameters
    ----------
    problem : Problem
    values : dict
        Parameter values (:meth:`mobisense.ocp.model.ParameterLayout.values`); ε is set per solve.
    scales : ndarray, shape (2 nx,)
        Scales D of the unknowns y = [x; μ].
    """

    name: str = ""
    #: ``follow`` is a natural-parameter step (solve at the new ε from the last solution). From ε = 0, where
    #: μ ≡ 0 carries no costate information, the continuation then seeds the first step with the Kalman guess
    #: at that ε (states and adjoint costates), as Hussein (2008, §IV) does.
    natural_parameter: bool = False

    def __init__(self, problem: Problem, values: dict[str, Any], scales: np.ndarray) -> None:
        self.problem = problem
        self.options = problem.solver.bvp
        self.system: HamiltonianSystem = hamiltonian_system(Structure.of(problem))
        self.values = values
        self.D = np.asarray(scales, float)
        self.t0, self.tf = problem.horizon.t0, problem.horizon.tf

    def parameters(self, eps: float) -> np.ndarray:
        """Packed parameter vector at ε."""
        return self.system.layout.pack({**self.values, "eps": eps})

    @abstractmethod
    def solve(self, eps: float, guess: Guess | BVPSolution) -> BVPSolution:
        """Solve at fixed ``eps`` from ``guess`` (a callable y(t), or a solution of any solver)."""

    @abstractmethod
    def follow(self, start: BVPSolution, eps: float) -> BVPSolution:
        """Continue from ``start`` (a successful solution of this solver) to ``eps``."""


#: name -> solver class
def register_bvp_solver(cls: type[BVPSolver]) -> type[BVPSolver]:
    """Class decorator: make ``cls`` available as ``solver.bvp.solver: <cls.name>``."""
    return BVP_SOLVERS.register(cls.name, cls)


@register_bvp_solver
class CollocationBVP(BVPSolver):
    """CasADi collocation + damped sparse Newton; arclength continuation in ε."""

    name = "collocation"

    def __init__(self, problem: Problem, values: dict[str, Any], scales: np.ndarray) -> None:
        super().__init__(problem, values, scales)
        c = problem.solver.collocation
        K = self.options.intervals or c.intervals
        self.mesh = collocation_mesh(Structure.of(problem), c.scheme, c.degree, K)
        self.t_mesh = np.linspace(self.t0, self.tf, K + 1)
        self.P = self.parameters(1.0)  # ε is a separate argument of the mesh functions
        self._tracker: ArclengthTracker | None = None

    def _linearise(self, W: np.ndarray, eps: float) -> tuple[np.ndarray, Any, np.ndarray]:
        return self.mesh.linearise(W, eps, self.P, self.D, self.t_mesh)

    def _result(self, W: np.ndarray, eps: float, success: bool, message: str, iterations: int, t: float, **report: Any):
        m = self.mesh
        times, z = m.node_values(W, self.t_mesh)
        phi, running, energy = m.costs(W, self.P, self.D, self.t_mesh)
        D = self.D

        def evaluate(tt: np.ndarray) -> np.ndarray:
            return m.sample(W, self.t_mesh, np.asarray(tt, float)) * D[:, None]

        return BVPSolution(
            eps, times, z * D[:, None], evaluate, phi, running, energy, success, message, iterations, t, report, W
        )

    def _curve(self, points: list[tuple[float, np.ndarray]]) -> dict[str, list[float]]:
        """ε and Tr Σ(tf) at the accepted points of the solution curve (shows its folds)."""
        s = self.system.structure
        diagonal = self.system.diagonal_sigma()
        trace = [float((z[: s.nx] * self.D[: s.nx])[diagonal].sum()) for _, z in points]
        return {"eps": [e for e, _ in points], "trace_sigma_tf": trace}

    def solve(self, eps: float, guess: Guess | BVPSolution) -> BVPSolution:
        """Newton at fixed ε from the guess sampled at the mesh's starts and collocation nodes."""
        if isinstance(guess, BVPSolution):
            guess = guess.evaluate
        W0 = self.mesh.pack(self.t_mesh, lambda tt: guess(tt) / self.D[:, None])
        result = newton(
            lambda W: self._linearise(W, eps)[:2], W0, self.options.tolerance, self.options.newton_iterations
        )
        self._tracker = None
        return self._result(result.X, eps, result.success, result.message, result.iterations, result.time_s)

    def follow(self, start: BVPSolution, eps: float) -> BVPSolution:
        """Arclength steps from ``start`` until ε is crossed, then Newton at ε."""
        if self._tracker is None or self._tracker.eps != start.eps or self._tracker.W is not start.raw:
            h = self.problem.solver.homotopy
            self._tracker = ArclengthTracker(
                self._linearise,
                start.raw,
                start.eps,
                self.options.tolerance,
                step=0.2 * h.step,
                min_step=1e-3 * h.min_step,
                max_steps=self.options.max_arclength_steps,
                end_size=self.system.ny,
            )
        tracker = self._tracker
        before = (tracker.W, tracker.eps, tracker.tangent, tracker.step)
        report = tracker.advance_to(eps)
        details = {
            "arclength_steps": report.arclength_steps,
            "rejected_steps": report.rejected_steps,
            "folds": report.folds,
            "curve": self._curve(report.points),
        }
        if not report.success:  # back to the last accepted point, so that a shorter ε step can follow
            tracker.W, tracker.eps, tracker.tangent, tracker.step = before
            return self._result(
                before[0], before[1], False, report.message, report.newton_iterations, report.time_s, **details
            )
        return self._result(tracker.W, eps, True, report.message, report.newton_iterations, report.time_s, **details)


@register_bvp_solver
class ScipyBVP(BVPSolver):
    """``scipy.integrate.solve_bvp`` with CasADi vectorised right-hand side and exact Jacobians."""

    name = "scipy"

    #: 5-point Gauss–Legendre rule on [0, 1] for the running cost on each mesh interval
    _GAUSS = tuple(np.polynomial.legendre.leggauss(5))

    def solve(self, eps: float, guess: Guess | BVPSolution, mesh: np.ndarray | None = None) -> BVPSolution:
        """``solve_bvp`` at fixed ε from the guess on ``mesh`` (default: the guess's nodes or 101 points)."""
        from scipy.integrate import solve_bvp

        if isinstance(guess, BVPSolution):
            mesh = guess.t if mesh is None else mesh
            guess = guess.evaluate
        mesh = np.linspace(self.t0, self.tf, 101) if mesh is None else np.asarray(mesh, float)
        P, D, s = self.parameters(eps), self.D, self.system
        t_start = time.perf_counter()
        sol = solve_bvp(
            lambda t, z: s.rhs(z, P, D),
            lambda za, zb: s.bc(za, zb, P, D),
            mesh,
            guess(mesh) / D[:, None],
            fun_jac=lambda t, z: s.rhs_jac(z, P, D),
            bc_jac=lambda za, zb: s.bc_jac(za, zb, P, D),
            tol=self.options.scipy_tolerance,
            max_nodes=self.options.max_nodes,
        )
        elapsed = time.perf_counter() - t_start
        phi, running, energy = self._costs(sol, P)

        def evaluate(tt: np.ndarray) -> np.ndarray:
            return sol.sol(np.asarray(tt, float)) * D[:, None]

        return BVPSolution(
            eps,
            sol.x,
            sol.y * D[:, None],
            evaluate,
            phi,
            running,
            energy,
            bool(sol.status == 0),
            str(sol.message),
            int(sol.niter),
            elapsed,
            {"max_rms_residual": float(np.max(sol.rms_residuals))},
            sol,
        )

    def follow(self, start: BVPSolution, eps: float) -> BVPSolution:
        """Natural-parameter step, as Hussein (2008, §IV) does: ``solve_bvp`` at ε from ``start`` on its mesh.

        The guess keeps ``start``'s states and PMP costates λ = μ/ε (the paper's unknowns), i.e. the scaled
        costates are multiplied by ε/ε_start. (From ε_start = 0, where μ ≡ 0 carries no λ, the continuation
        passes the Kalman guess to :meth:`solve` instead: :attr:`BVPSolver.natural_parameter`.)
        """
        if start.eps <= 0.0:
            return self.solve(eps, start)
        nx, ratio, evaluate = self.system.structure.nx, eps / start.eps, start.evaluate

        def guess(tt: np.ndarray) -> np.ndarray:
            y = np.array(evaluate(tt), dtype=float)
            y[nx:] *= ratio
            return y

        return self.solve(eps, guess, mesh=start.t)

    def _costs(self, sol: Any, P: np.ndarray) -> tuple[float, float, float]:
        """Φ(x(tf)) and Gauss–Legendre quadrature of L, α/2|u|² on the cubic solution."""
        s, nx = self.system, self.system.structure.nx
        points, weights = self._GAUSS
        a, b = sol.x[:-1, None], sol.x[1:, None]
        tq = (a + 0.5 * (b - a) * (points[None, :] + 1.0)).ravel()
        wq = (0.5 * (b - a) * weights[None, :]).ravel()
        y = sol.sol(tq) * self.D[:, None]
        u = s.control.map(tq.size)(y[:nx], y[nx:], P)
        L = np.asarray(s.model.running.map(tq.size)(y[:nx], u, P))
        x_end = sol.y[:nx, -1] * self.D[:nx]
        return float(s.model.terminal(x_end, P)), float(L[0] @ wq), float(L[1] @ wq)
