"""Arclength continuation of the collocation BVP in ε: follows the solution curve through folds.

The PMP solutions of the default problem do not form a graph over ε: the branch that starts at the coasting Kalman
solution (ε = 0) ends in a fold at ε ≈ 0.005863 (measured; the test requires the first fold in [0.00586, 0.0065);
docs/theory/indirect.md §3.1), where the sensor would rather turn towards the process; Newton in ε (and
``scipy.integrate.solve_bvp``) fails there however small the ε step. Following the curve ``F(W, ε) = 0`` along its
arclength instead passes such folds: the curve turns back (an unstable extremal branch), turns again, and continues
to ε = 1 on the branch the direct method finds.

One step from X = (W, ε) with unit tangent T (norm ``|ΔX|² = |ΔW|²/nw + Δε²``), in Rheinboldt's local
parametrisation — the unknown X_k that changes fastest along the curve (k = argmax |T_k|) is fixed by the
predictor, so the bordering row is a unit vector and the bordered Jacobian stays as sparse as ∂F/∂W
(Keller's dense pseudo-arclength row makes SuperLU's symbolic structure dense: 30x slower here):

    predictor  X_p = X + Δs T
    corrector  F(W, ε) = 0,   X_k = X_p,k              (Newton on the bordered sparse system)
    tangent    [∂F/∂W ∂F/∂ε; e_k'] T_new = [0; 1], normalised, oriented along T

Δs grows by ``growth`` after an easy corrector (≤ 3 Newton iterations) and is halved after a failure or
when the step cut a corner (tangent turned by more than ~26°, or the corrector moved more than Δs/2).
:meth:`ArclengthTracker.advance_to` walks until the curve crosses a target ε going up and lands on it
with a Newton solve at fixed ε — so the ε schedule of :func:`mobisense.ocp.homotopy.run_continuation` (fixed δ
steps as in the paper, adaptive, or straight to 1) drives it unchanged.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .collocation_newton import NewtonResult, factorise, newton

__all__ = ["ArclengthTracker", "TrackerReport"]

#: linearisation (W, ε) -> (F, ∂F/∂W sparse, ∂F/∂ε)
Linearise = Callable[[np.ndarray, float], tuple[np.ndarray, sp.csc_matrix, np.ndarray]]


@dataclass
class TrackerReport:
    """What one :meth:`ArclengthTracker.advance_to` call did."""

    success: bool
    message: str
    arclength_steps: int = 0
    rejected_steps: int = 0
    newton_iterations: int = 0
    #: ε at the folds passed (dε/ds = 0), from a quadratic ε(s) between the two points around each
    folds: list[float] = field(default_factory=list)
    #: accepted points of the curve: (ε, unknowns at the last mesh point — the state and costate at tf)
    points: list[tuple[float, np.ndarray]] = field(default_factory=list)
    time_s: float = 0.0


class ArclengthTracker:
    """Follows ``F(W, ε) = 0`` from a solved point by arclength steps (local parametrisation).

    Parameters
    ----------
    linearise : callable
        ``linearise(W, ε) -> (F, ∂F/∂W, ∂F/∂ε)``, the Jacobian sparse and staircase-ordered.
    W, eps : ndarray, float
        A solved point of the curve.
    tolerance : float
        Newton tolerance on ``max|F|``.
    step, min_step, max_step, growth : float
        Initial, smallest and largest arclength step; growth factor after easy steps.
    max_steps : int
        Limit on accepted + rejected arclength steps per :meth:`advance_to`.
    end_size : int
        How many trailing entries of W to record per accepted point (:attr:`TrackerReport.points`).
    """

    def __init__(
        self,
        linearise: Linearise,
        W: np.ndarray,
        eps: float,
        tolerance: float,
        step: float = 0.02,
        min_step: float = 1e-7,
        max_step: float = 0.5,
        growth: float = 1.6,
        max_steps: int = 400,
        end_size: int = 0,
    ) -> None:
        self.linearise = linearise
        self.W = np.asarray(W, float)
        self.eps = float(eps)
        self.tolerance = tolerance
        self.step = step
        self.min_step = min_step
        self.max_step = max_step
        self.growth = growth
        self.max_steps = max_steps
        self.end_size = end_size
        self.theta = 1.0 / self.W.size
        self.tangent = self._tangent(self.W, self.eps, None)

    # ------------------------------------------------------------------ geometry
    @staticmethod
    def _bordered(J: sp.csc_matrix, J_eps: np.ndarray, k: int) -> sp.csc_matrix:
        """[∂F/∂W ∂F/∂ε; e_k'] (the local-parametrisation row last: the staircase order is kept)."""
        size = J.shape[1] + 1
        row = sp.csr_matrix(([1.0], ([0], [k])), shape=(1, size))
        return sp.vstack([sp.hstack([J, sp.csc_matrix(J_eps[:, None])]), row], format="csc")

    def _tangent(self, W: np.ndarray, eps: float, previous: np.ndarray | None) -> np.ndarray:
        """Unit tangent of the curve at (W, ε), oriented along ``previous`` (or with ε increasing)."""
        _, J, J_eps = self.linearise(W, eps)
        if previous is None:
            dW = factorise(J).solve(-J_eps)  # natural-parameter tangent dW/dε
            T = np.append(dW, 1.0)
        else:
            rhs = np.zeros(W.size + 1)
            rhs[-1] = 1.0
            guide = previous
            for _ in range(3):  # the bordered system is well conditioned only if T_k is a large component
                k = int(np.argmax(np.abs(guide)))
                T = factorise(self._bordered(J, J_eps, k)).solve(rhs)
                if abs(T[k]) >= 0.5 * np.abs(T).max():
                    break
                guide = T
            if self._dot(T, previous) < 0:
                T = -T
        return T / np.sqrt(self._dot(T, T))

    def _dot(self, a: np.ndarray, b: np.ndarray) -> float:
        return float(self.theta * a[:-1] @ b[:-1] + a[-1] * b[-1])

    # ------------------------------------------------------------------ steps
    def _corrector(self, X_pred: np.ndarray) -> NewtonResult:
        k = int(np.argmax(np.abs(self.tangent)))  # the local parameter

        def bordered(X: np.ndarray) -> tuple[np.ndarray, sp.csc_matrix]:
            F, J, J_eps = self.linearise(X[:-1], X[-1])
            return np.append(F, X[k] - X_pred[k]), self._bordered(J, J_eps, k)

        return newton(bordered, X_pred, self.tolerance, max_iterations=8)

    def _acceptable(self, T: np.ndarray, T_new: np.ndarray, correction: np.ndarray) -> bool:
        """Step control: the tangent turns by less than ~26° and the corrector moves less than Δs/2.

        Larger turns mean the step cut a corner of the curve (it may have jumped to another branch or
        reversed along this one); the step is then retried at half the length.
        """
        return self._dot(T, T_new) > 0.9 and np.sqrt(self._dot(correction, correction)) < 0.5 * self.step

    def _point_at(self, X: np.ndarray, T: np.ndarray, s: float) -> tuple[np.ndarray, np.ndarray] | None:
        """Corrected point at arclength ≈ s from X along T, and its tangent (None if Newton fails)."""
        saved = self.tangent
        self.tangent = T
        corrected = self._corrector(X + s * T)
        self.tangent = saved
        if not corrected.success:
            return None
        return corrected.X, self._tangent(corrected.X[:-1], corrected.X[-1], T)

    def _locate_fold(self, X1: np.ndarray, T1: np.ndarray, X2: np.ndarray, T2: np.ndarray) -> float:
        """ε at the fold between X1 and X2: secant iterations on dε/ds = 0 along the curve (6 at most)."""
        s_a, g_a = 0.0, T1[-1]
        s_b, g_b = float(np.sqrt(self._dot(X2 - X1, X2 - X1))), T2[-1]
        eps_fold = max(X1[-1], X2[-1]) if g_a > 0 else min(X1[-1], X2[-1])
        for _ in range(6):
            s_new = s_b - g_b * (s_b - s_a) / (g_b - g_a)
            point = self._point_at(X1, T1, s_new)
            if point is None:
                break
            X, T = point
            eps_fold = float(X[-1])
            if abs(T[-1]) < 1e-10:
                break
            s_a, g_a, s_b, g_b = s_b, g_b, s_new, T[-1]
        return eps_fold

    def _land(self, target: float) -> NewtonResult:
        """Newton at fixed ε = target from the tangent line through the current point."""
        ds = (target - self.eps) / self.tangent[-1]
        W0 = self.W + ds * self.tangent[:-1]
        return newton(lambda W: self.linearise(W, target)[:2], W0, self.tolerance, max_iterations=12)

    def advance_to(self, target: float) -> TrackerReport:
        """Follow the curve until it crosses ε = ``target`` going up, and solve there; False on failure."""
        t_start = time.perf_counter()
        report = TrackerReport(False, "")
        while report.arclength_steps + report.rejected_steps < self.max_steps:
            T = self.tangent
            eps_pred = self.eps + self.step * T[-1]
            if T[-1] > 0 and eps_pred >= target:
                landed = self._land(target)
                report.newton_iterations += landed.iterations
                if landed.success:
                    self.tangent = self._tangent(landed.X, target, T)
                    self.W, self.eps = landed.X, target
                    report.points.append((self.eps, self.W[-self.end_size :].copy()))
                    report.success, report.message = True, f"reached ε = {target:g}"
                    report.time_s = time.perf_counter() - t_start
                    return report
                self.step = (target - self.eps) / T[-1] * 0.5  # approach the target in smaller steps
            X = np.append(self.W, self.eps)
            X_pred = X + self.step * T
            corrected = self._corrector(X_pred)
            report.newton_iterations += corrected.iterations
            new_tangent = None
            if corrected.success and corrected.X[-1] >= 0.0:
                new_tangent = self._tangent(corrected.X[:-1], corrected.X[-1], T)
                if not self._acceptable(T, new_tangent, corrected.X - X_pred):
                    new_tangent, corrected.message = None, "the curve turns too sharply for this step"
            if new_tangent is None:
                report.rejected_steps += 1
                self.step *= 0.5
                if self.step < self.min_step:
                    report.message = (
                        f"arclength step below {self.min_step:g} at ε = {self.eps:.6g} ({corrected.message})"
                    )
                    break
                continue
            report.arclength_steps += 1
            if new_tangent[-1] * T[-1] < 0:  # dε/ds changed sign: a fold between the two points
                report.folds.append(self._locate_fold(X, T, corrected.X, new_tangent))
            self.W, self.eps, self.tangent = corrected.X[:-1], float(corrected.X[-1]), new_tangent
            report.points.append((self.eps, self.W[-self.end_size :].copy()))
            if corrected.iterations <= 3:
                self.step = min(self.step * self.growth, self.max_step)
        else:
            report.message = f"more than {self.max_steps} arclength steps before ε = {target:g}"
        report.time_s = time.perf_counter() - t_start
        return report
