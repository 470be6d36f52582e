"""The global NLP from the interval kernels: index maps and derivatives assembled by constant maps.

Nothing of size K is differentiated symbolically (docs/theory/direct.md §1.7): the kernel functions are mapped
over the K intervals inside one MX graph, and the global objective gradient, constraint Jacobian and
Lagrangian Hessian are assembled from the local ones by constant index maps — the Jacobian's rows are
disjoint per interval (its nonzeros are a selection of the local ones), the Hessian's blocks overlap only on
the variables two neighbouring intervals share (a constant sparse 0/1 summation). These are handed to Ipopt
as its ``grad_f``, ``jac_g`` and ``hess_lag``, so the build time does not grow with the work.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from .kernels import IntervalKernels

__all__ = ["IndexMaps", "index_maps", "assemble", "with_step"]


@dataclass
class IndexMaps:
    """Where every local kernel variable lives in the decision vector ``w`` (positions ≥ nw: x̃_0, a parameter).

    Attributes
    ----------
    nw : int
        Decision variables.
    local : ndarray, shape (K, na)
        Global position of each local variable of each interval.
    z, nxt : ndarray, shapes (K, nz), (K, nn)
        Internal and end variables of each interval.
    boundary : ndarray, shape (K + 1, nx)
        The scaled state at every interval boundary (row 0: x̃_0; in the eliminated layout the positions
        ``nw … nw + nx − 1`` stand for the parameter ``x0(P)/D_x``).
    x0_is_variable : bool
        True in the stage layout (x̃_0 is a variable fixed by its bounds).
    """

    nw: int
    local: np.ndarray
    z: np.ndarray
    nxt: np.ndarray
    boundary: np.ndarray
    x0_is_variable: bool


def index_maps(k: IntervalKernels, K: int) -> IndexMaps:
    """The layout of ``w`` for K intervals (see :mod:`mobisense.ocp.direct.kernels`)."""
    nx, nz, nn, ns, d = k.nx, k.nz, k.nn, k.ns, k.d
    if k.layout == "stage":
        stride = nx + nz
        nw = K * stride + nx
        start = np.arange(K + 1)[:, None] * stride
        boundary = start + np.arange(nx)
        z = start[:-1] + nx + np.arange(nz)
        nxt = boundary[1:]
        starts = boundary[:-1]
    else:
        stride = nz + nn
        nw = K * stride
        start = np.arange(K)[:, None] * stride
        z = start + np.arange(nz)
        nxt = start + nz + np.arange(nn)
        sigma_end = z[:, (d - 1) * ns : d * ns]  # covariance at node d (= the interval end for Radau)
        starts = np.empty((K, nx), dtype=int)
        starts[0] = nw + np.arange(nx)
        if k.short_next:
            starts[1:, :ns], starts[1:, ns:] = sigma_end[:-1], nxt[:-1]
            final = np.concatenate([sigma_end[-1], nxt[-1]])
        else:
            starts[1:] = nxt[:-1]
            final = nxt[-1]
        boundary = np.vstack([starts, final])
    return IndexMaps(nw, np.hstack([starts, z, nxt]), z, nxt, boundary, k.layout == "stage")


def with_step(P: Any, k: IntervalKernels, K: int) -> Any:
    """``[P; h]`` with the interval length h = (tf − t0)/K: the kernels' parameter input."""
    offsets = k.model.layout.offsets
    i0, itf = offsets["t0"][0], offsets["tf"][0]
    if isinstance(P, np.ndarray):
        return np.append(P, (P[itf] - P[i0]) / K)
    return ca.vertcat(P, (P[itf] - P[i0]) / K)


def _ccs(nrow: int, ncol: int, rows: np.ndarray, cols: np.ndarray) -> ca.Sparsity:
    """Sparsity from entries sorted by (column, row) without duplicates."""
    colind = np.zeros(ncol + 1, dtype=np.int64)
    np.cumsum(np.bincount(cols, minlength=ncol), out=colind[1:])
    return ca.Sparsity(nrow, ncol, colind.tolist(), np.asarray(rows, dtype=np.int64).tolist())


def _nonzeros(x: ca.MX) -> ca.MX:
    return ca.sparsity_cast(x, ca.Sparsity.dense(x.nnz(), 1))


@dataclass
class Assembled:
    """The NLP of K intervals: ``nlp`` (x, p, f, g), the derivative functions for nlpsol, ``cost_terms``."""

    nlp: dict[str, ca.MX]
    derivatives: dict[str, ca.Function]
    cost_terms: ca.Function
    ng: int


def assemble(k: IntervalKernels, functions: dict[str, ca.Function], maps: IndexMaps, K: int) -> Assembled:
    """Objective, constraints and their exact derivatives as MX functions of (w, P).

    Parameters
    ----------
    k : IntervalKernels
    functions : dict
        ``k.functions`` or their compiled versions.
    maps : IndexMaps
    K : int
    """
    nw, na, nr, nx = maps.nw, k.na, k.nr, k.nx
    ng = K * nr + k.n_term
    local, final = maps.local, maps.boundary[-1]
    w = ca.MX.sym("w", nw)
    P = ca.MX.sym("P", k.n_parameters)
    w_ext = ca.vertcat(w, k.x0_scaled(P))  # x̃_0 appended: local positions ≥ nw refer to it
    A = ca.reshape(w_ext[local.T.ravel(order="F").tolist()], na, K)
    xK = w_ext[final.tolist()]
    Ph = ca.repmat(with_step(P, k, K), 1, K)

    rows, q, energy = functions["k_eval"].map(K, "serial")(A, Ph)
    term, phi, phi_raw = functions["t_eval"](xK, P)
    f = ca.sum2(q) + phi
    g = ca.vertcat(ca.vec(rows), term)
    b = k.model.layout.unpack(P)
    cost_terms = ca.Function("cost_terms", [w, P], [phi_raw, ca.sum2(q) * b["cost_scale"], ca.sum2(energy)])

    # gradient: sum of the local gradients (shared variables receive two contributions)
    q_g, grad_local = functions["k_grad"].map(K, "serial")(A, Ph)
    phi_g, grad_T = functions["t_grad"](xK, P)
    valid = local < nw
    rows_g = np.concatenate([local[valid], final[final < nw]])
    cols_g = np.concatenate([(np.arange(K)[:, None] * na + np.arange(na))[valid], K * na + np.flatnonzero(final < nw)])
    S_g = ca.DM(_ccs(nw, K * na + nx, rows_g, cols_g), 1.0)
    grad = ca.mtimes(S_g, ca.vertcat(ca.vec(grad_local), grad_T))
    grad_f = ca.Function("grad_f", [w, P], [ca.sum2(q_g) + phi_g, grad], ["x", "p"], ["f", "grad_f_x"])

    # Jacobian: interval k owns rows k·nr … (k+1)·nr − 1, so the global nonzeros are a selection of the local ones
    rows_j, jac_local = functions["k_jac"].map(K, "serial")(A, Ph)
    term_j, jac_T = functions["t_jac"](xK, P)
    jr, jc = (np.array(v, dtype=int) for v in functions["k_jac"].sparsity_out(1).get_triplet())
    tr_, tc_ = (np.array(v, dtype=int) for v in functions["t_jac"].sparsity_out(1).get_triplet())
    R = np.concatenate([(np.arange(K)[:, None] * nr + jr).ravel(), K * nr + tr_])
    C = np.concatenate([local[:, jc].ravel(), final[tc_]])
    source = np.flatnonzero(C < nw)
    order = np.lexsort((R[source], C[source]))  # column-major (CCS) order
    sp_J = _ccs(ng, nw, R[source][order], C[source][order])
    nonzeros = ca.vertcat(_nonzeros(jac_local), _nonzeros(jac_T))
    jac = ca.sparsity_cast(nonzeros[source[order].tolist()], sp_J)
    jac_g = ca.Function("jac_g", [w, P], [ca.vertcat(ca.vec(rows_j), term_j), jac], ["x", "p"], ["g", "jac_g_x"])

    # Hessian (upper triangle): the local upper triangles summed into the global one
    hr, hc = (np.array(v, dtype=int) for v in functions["k_hess"].sparsity_out(0).get_triplet())
    htr, htc = (np.array(v, dtype=int) for v in functions["t_hess"].sparsity_out(0).get_triplet())
    gi = np.concatenate([local[:, hr].ravel(), final[htr]])
    gj = np.concatenate([local[:, hc].ravel(), final[htc]])
    source = np.flatnonzero((gi < nw) & (gj < nw))
    r_, c_ = np.minimum(gi[source], gj[source]), np.maximum(gi[source], gj[source])
    unique, inverse = np.unique(c_ * nw + r_, return_inverse=True)  # sorted by column, then row: CCS order
    sp_H = _ccs(nw, nw, unique % nw, unique // nw)
    S_h = ca.DM(_ccs(unique.size, K * hr.size + htr.size, inverse.ravel(), source), 1.0)
    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", ng)
    hess_local = functions["k_hess"].map(K, "serial")(A, Ph, ca.reshape(lam_g[: K * nr], nr, K), ca.repmat(lam_f, 1, K))
    hess_T = functions["t_hess"](xK, P, lam_g[K * nr :], lam_f)
    hess = ca.sparsity_cast(ca.mtimes(S_h, ca.vertcat(_nonzeros(hess_local), _nonzeros(hess_T))), sp_H)
    hess_lag = ca.Function(
        "hess_lag", [w, P, lam_f, lam_g], [hess], ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"]
    )
    return Assembled(
        nlp={"x": w, "p": P, "f": f, "g": g},
        derivatives={"grad_f": grad_f, "jac_g": jac_g, "hess_lag": hess_lag},
        cost_terms=cost_terms,
        ng=ng,
    )
