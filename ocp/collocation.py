"""Orthogonal collocation schemes on the unit interval: points, differentiation, continuity, quadrature.

A scheme of degree d has nodes ``tau = [0, tau_1, …, tau_d]`` (from ``casadi.collocation_points``).
With the Lagrange basis l_j over all d+1 nodes, the collocation equations of one interval of length h are

    sum_j D[j, r] x_j = h f(x_r, u_r),  r = 1..d        (D[j, r] = l_j'(tau_r))

the interval's end state is ``x_end = sum_j E[j] x_j`` (E[j] = l_j(1)), and integrals use the Gauss-type
quadrature ``∫_0^1 g ≈ sum_r W[r] g(tau_r)`` whose weights integrate the d-point basis on the
collocation nodes (exact to degree 2d−2 for Radau, 2d−1 for Legendre). With controls at the
collocation points the cost converges at order 2d−1 (Radau) and 2d (Legendre).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import casadi as ca
import numpy as np

from .registries import SCHEMES

__all__ = ["CollocationScheme", "collocation_scheme", "HULL_ELEVATION"]

#: degrees by which the control polynomial's Bernstein form is elevated for the bound |u| ≤ u_max (see
#: ``CollocationScheme.bernstein``): more coefficients, a tighter hull. Measured on terminal_and_bound.yaml at
#: K = 100, J above its K → ∞ value by 1.8e-6 relative at 0, 1.1e-6 at 2, 8e-7 at 8 (the hull tightens as
#: 1/degree): not worth the rows
HULL_ELEVATION = 0

@dataclass(frozen=True)
class CollocationScheme:
    """Collocation matrices for ``scheme`` (``radau`` | ``legendre``) of degree ``degree``."""

    scheme: str
    degree: int
    tau: np.ndarray = field(init=False)  # (d+1,) nodes incl. 0
    D: np.ndarray = field(init=False)  # (d+1, d) derivative of basis j at collocation node r
    E: np.ndarray = field(init=False)  # (d+1,) basis at tau = 1 (end of interval)
    W: np.ndarray = field(init=False)  # (d,) quadrature weights on the collocation nodes
    #: (d + HULL_ELEVATION, d) row i: the i-th Bernstein coefficient of the control polynomial from its node values
    bernstein: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        SCHEMES.check(self.scheme)
        d = self.degree
        tau = np.append(0.0, ca.collocation_points(d, SCHEMES[self.scheme]))
        D = np.zeros((d + 1, d))
        E = np.zeros(d + 1)
        for j in range(d + 1):
            basis = np.poly1d([1.0])
            for r in range(d + 1):
                if r != j:
                    basis *= np.poly1d([1.0, -tau[r]]) / (tau[j] - tau[r])
            E[j] = basis(1.0)
            D[j, :] = np.polyder(basis)(tau[1:])
        W = np.zeros(d)
        for j in range(d):
            basis = np.poly1d([1.0])
            for r in range(d):
                if r != j:
                    basis *= np.poly1d([1.0, -tau[r + 1]]) / (tau[j + 1] - tau[r + 1])
            antiderivative = np.polyint(basis)
            W[j] = antiderivative(1.0) - antiderivative(0.0)
        for name, value in (("bernstein", _bernstein_from_nodes(tau[1:], HULL_ELEVATION)), ("tau", tau), ("D", D),
                            ("E", E), ("W", W)):  # fmt: skip
            value.setflags(write=False)  # shared by every user of collocation_scheme()
            object.__setattr__(self, name, value)

    @property
    def order(self) -> int:
        """Order of convergence of the cost with per-point controls (2d−1 Radau, 2d Legendre)."""
        return 2 * self.degree - 1 if self.scheme == "radau" else 2 * self.degree

    @property
    def ends_at_node(self) -> bool:
        """True when the last collocation node is the interval end (Radau)."""
        return bool(abs(self.tau[-1] - 1.0) < 1e-14)

    def locate(self, times: np.ndarray, t0: float, tf: float, K: int) -> tuple[np.ndarray, np.ndarray]:
        """Interval index ``k`` (T,) and local time ``s`` in [0, 1] (T,) of each of ``times`` on K equal intervals.

        Interval k covers (t_k, t_k+1]: a Radau control node at τ = 1 belongs to the interval it ends.
        """
        scaled = (np.asarray(times, float) - t0) / ((tf - t0) / K)
        k = np.clip(np.ceil(scaled - 1e-9).astype(int) - 1, 0, K - 1)
        return k, scaled - k

    def evaluate(
        self, times: np.ndarray, t0: float, tf: float, states: np.ndarray, controls: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The collocation polynomials at ``times`` in [t0, tf]: states (T, nx) and controls (T, nu).

        ``states`` (K, d + 1, nx) are each interval's state nodes (its start and collocation points),
        ``controls`` (K, d, nu) its control nodes; the states are the Lagrange polynomials through the d + 1
        nodes, the controls those through the d collocation nodes (the functions the NLP optimises).
        """
        k, s = self.locate(times, t0, tf, len(states))
        x = np.einsum("tj,tjx->tx", self.interpolation_matrix(s, "all"), states[k])
        u = np.einsum("tj,tjc->tc", self.interpolation_matrix(s, "collocation"), controls[k])
        return x, u

    def interpolation_matrix(self, s: np.ndarray, nodes: str = "collocation") -> np.ndarray:
        """Lagrange interpolation weights at local times ``s`` in [0, 1].

        ``nodes="collocation"`` uses the d collocation nodes (controls), ``"all"`` the d+1 state nodes.
        Returns shape (len(s), number of nodes).
        """
        points = self.tau[1:] if nodes == "collocation" else self.tau
        s = np.atleast_1d(np.asarray(s, float))
        out = np.ones((s.size, points.size))
        for j in range(points.size):
            for r in range(points.size):
                if r != j:
                    out[:, j] *= (s - points[r]) / (points[j] - points[r])
        return out


@lru_cache(maxsize=32)
def collocation_scheme(scheme: str, degree: int) -> CollocationScheme:
    """The :class:`CollocationScheme` ``(scheme, degree)``, built once per process (its polynomials: ≈ 0.2 ms)."""
    return CollocationScheme(scheme, degree)


def _bernstein_from_nodes(nodes: np.ndarray, elevation: int = 0) -> np.ndarray:
    """The matrix B (d + e, d) with ``c = B u``: the Bernstein coefficients of the polynomial through ``(nodes, u)``.

    The polynomial, of degree d − 1, written in the Bernstein basis of degree m = d − 1 + e (``elevation`` e ≥ 0),
    is ``Σ_i c_i C(m, i) τ^i (1 − τ)^(m−i)``: a convex combination of the ``c_i`` at every τ ∈ [0, 1], so a vector
    polynomial stays in their convex hull, and ``|c_i| ≤ u_max`` for all i bounds ``|u(τ)|`` on the whole
    interval. The hull shrinks onto the curve as the degree is elevated (c_i → u(i/m)). From the monomial
    coefficients a_k: c_i = Σ_{k≤i} C(i,k)/C(m,k) a_k.
    """
    from math import comb

    d = len(nodes)
    m = d - 1 + elevation
    monomial = np.linalg.inv(np.vander(nodes, d, increasing=True))  # a = monomial @ u
    to_bernstein = np.array([[comb(i, k) / comb(m, k) if k <= i else 0.0 for k in range(d)] for i in range(m + 1)])
    return to_bernstein @ monomial
