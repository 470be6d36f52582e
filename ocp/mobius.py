"""The Möbius-RK4 step of the whitened field Riccati equation, O(n²N) per step (docs/theory/field.md §3.2).

In whitened coordinates Z = L⁻¹ΣL⁻ᵀ (Kₛ = LL') the field's Riccati equation is
Z' = −2aZ + qI − Z C̃'R⁻¹C̃ Z (eq. field.5). With Z = X Y⁻¹ it is the linear system
X' = −aX + qY, Y' = C̃'R⁻¹C̃ X + aY (eq. field.6), which is not stiff; one classical RK4 step of it and
Z ← X Y⁻¹ by the Woodbury identity never forms an n × n product of two dense matrices.
"""

from __future__ import annotations

from typing import Any

import casadi as ca

__all__ = ["Span", "mobius_rk4_step"]

#: CasADi linear solver of the small r × r (r = 3N) Woodbury system (LAPACK LU, partial pivoting).
LINEAR_SOLVER = "lapacklu"


class Span:
    """A symbolic matrix γ X0 + δ I + Σ_b C_b' V_b.

    X0 is the step's initial (symmetric) Z, C_b (N × n) the measurement rows at stage time b, V_b (N × n).
    Linear combinations cost no n × n work.
    """

    def __init__(self, gx: Any = 0.0, gi: Any = 0.0, blocks: dict[int, Any] | None = None) -> None:
        self.gx, self.gi = gx, gi
        self.blocks = dict(blocks or {})

    def __add__(self, other: Span) -> Span:
        blocks = dict(self.blocks)
        for k, v in other.blocks.items():
            blocks[k] = blocks[k] + v if k in blocks else v
        return Span(self.gx + other.gx, self.gi + other.gi, blocks)

    def __rmul__(self, s: Any) -> Span:
        return Span(s * self.gx, s * self.gi, {k: s * v for k, v in self.blocks.items()})

    def left_rows(self, j: int, CX0: dict[int, Any], C: dict[int, Any], gram: Any) -> Any:
        """C_j · (this matrix), N × n, in O(n N²) from the precomputed C_j X0 and Gram blocks C_j C_b'."""
        out = self.gx * CX0[j] + self.gi * C[j]
        for b, V in self.blocks.items():
            out = out + ca.mtimes(gram(j, b), V)
        return out


def mobius_rk4_step(Z: Any, rows: list[tuple[Any, Any]], a: Any, q: Any, dt: Any) -> Any:
    """One RK4 step of the linear (Hamiltonian) form of Z' = −2aZ + qI − Z C̃'R⁻¹C̃ Z, then Z ← X Y⁻¹.

    With Z = X Y⁻¹:  X' = −aX + qY,  Y' = C̃'R⁻¹C̃ X + aY,  X(0) = Z, Y(0) = I (exact for the Riccati flow).
    The linear system's eigenvalues are ±sqrt(a² + q‖C̃'R⁻¹C̃‖) — about the square root of the Riccati
    equation's stiffness 2‖Z C̃'R⁻¹C̃‖ — so one step per interval is stable and O(h⁴) accurate where
    explicit RK4 on the Riccati form needs ~h·Σσ²/r steps. Every RK4 stage of X and Y stays in the span
    {X0, I, C_b'·} (b = the three stage times), so only C_b X0 (3 products, 3n²N flops) and the final
    assembly X Y⁻¹ = (X − XU (βI + VU)⁻¹ V)/β (Woodbury, 2n²·3N) touch n×n matrices: O(n² N) per step.
    ``rows`` = [(C̃, 1/r) at t, t + dt/2, t + dt], C̃ (N × n), 1/r (N × 1). Returns Z(t + dt), symmetrised.
    """
    C = {b: rows[b][0] for b in range(3)}
    rinv = {b: rows[b][1] for b in range(3)}
    n = Z.size1()
    CX0 = {b: ca.mtimes(C[b], Z) for b in range(3)}
    grams: dict[tuple[int, int], Any] = {}

    def gram(j: int, b: int) -> Any:
        if (j, b) not in grams:
            grams[(j, b)] = ca.mtimes(C[j], C[b].T)
        return grams[(j, b)]

    def stage(X: Span, Y: Span, b: int) -> tuple[Span, Span]:
        W = X.left_rows(b, CX0, C, gram) * ca.repmat(rinv[b], 1, n)  # R⁻¹ C̃ X  (N × n)
        return (-a) * X + q * Y, a * Y + Span(blocks={b: W})

    X0, Y0 = Span(gx=1.0), Span(gi=1.0)
    kX1, kY1 = stage(X0, Y0, 0)
    kX2, kY2 = stage(X0 + (dt / 2) * kX1, Y0 + (dt / 2) * kY1, 1)
    kX3, kY3 = stage(X0 + (dt / 2) * kX2, Y0 + (dt / 2) * kY2, 1)
    kX4, kY4 = stage(X0 + dt * kX3, Y0 + dt * kY3, 2)
    X = X0 + (dt / 6) * kX1 + (dt / 3) * kX2 + (dt / 3) * kX3 + (dt / 6) * kX4
    Y = Y0 + (dt / 6) * kY1 + (dt / 3) * kY2 + (dt / 3) * kY3 + (dt / 6) * kY4
    keys = sorted(Y.blocks)
    Ut = ca.vertcat(*[C[k] for k in keys])  # U' (r × n)
    V = ca.vertcat(*[Y.blocks[k] for k in keys])  # r × n
    Vx = ca.vertcat(*[X.blocks.get(k, ca.DM.zeros(C[k].shape)) for k in keys])  # X = gx X0 + gi I + U Vx
    beta = Y.gi
    r = Ut.size1()
    VU = ca.mtimes(V, Ut.T)  # r × r
    # X U = gx X0 U + gi U + U (Vx U);   X0 U = [C_k X0]'  (X0 symmetric)
    X0U = ca.vertcat(*[CX0[k] for k in keys]).T
    XU = X.gx * X0U + X.gi * Ut.T + ca.mtimes(Ut.T, ca.mtimes(Vx, Ut.T))  # n × r
    # LAPACK LU (partial pivoting). CasADi's built-in sparse "qr" returned NaN on a 12 × 12 βI + VU whose
    # entries underflowed (1e-182: sensors far from every grid point) — the kernel cut-off now prevents
    # that, but LU is also the cheaper factorisation. (For C code generation use "qr": no LAPACK codegen.)
    inner = beta * ca.DM.eye(r) + VU
    T = ca.solve(inner, V, LINEAR_SOLVER) if isinstance(inner, ca.MX) else ca.solve(inner, V)  # (βI + VU)⁻¹ V
    low = ca.mtimes(ca.horzcat(Ut.T, -XU), ca.vertcat(Vx, T))  # U Vx − XU T   (n × n)
    Znew = (X.gx * Z + low) / beta
    Znew = Znew + (X.gi / beta) * type(Z).eye(n)
    return 0.5 * (Znew + Znew.T)
