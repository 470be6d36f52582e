"""Parametric sensitivities dJ*/d(number) of a direct optimum (docs/theory/path_constraints.md §4).

Every number of the problem is an NLP parameter, so by the envelope theorem (eq. path.6) the derivative of
the optimal cost is the parameter gradient of the Lagrangian at the converged primal–dual point, times
``cost_scale``. :func:`parameter_gradient` evaluates it with one reverse sweep over the kernels (the SX
versions: compiled kernels carry no derivatives in P); :func:`leaf_sensitivities` chains it to every
numeric leaf of the problem file, named by key path.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from ..problem import Problem
from .assembly import assemble

__all__ = ["parameter_gradient", "leaf_sensitivities", "solution_sensitivities"]

_GRADIENTS: dict[tuple, ca.Function] = {}


def _gradient_function(tr: Any) -> ca.Function:
    """``(w, P, λ_g) -> c_s ∇_P (f + λ_g·g)``, built once per transcription layout."""
    key = tr.signature
    if key not in _GRADIENTS:
        nlp = assemble(tr.kernels, tr.kernels.functions, tr.maps, tr.intervals).nlp
        w, P = nlp["x"], nlp["p"]
        lam = ca.MX.sym("lam_g", nlp["g"].numel())
        lagrangian = nlp["f"] + ca.dot(lam, nlp["g"])
        cost_scale = tr.layout.unpack(P)["cost_scale"]
        _GRADIENTS[key] = ca.Function("dJ_dP", [w, P, lam], [cost_scale * ca.gradient(lagrangian, P)])
    return _GRADIENTS[key]


def parameter_gradient(tr: Any, w: np.ndarray, lam_g: np.ndarray, P: np.ndarray) -> dict[str, np.ndarray]:
    """dJ*/dP by blocks of the parameter layout (eq. path.6), at a converged point ``(w, λ_g)`` with ε = 1.

    Parameters
    ----------
    tr : DirectCollocation
    w, lam_g : ndarray
        Converged decision vector (nw,) and constraint multipliers (ng,).
    P : ndarray
        Its parameters (ε = 1).

    Returns
    -------
    dict
        Block name -> gradient, shaped like the block (matrices row-major as in the layout).
    """
    grad = np.asarray(_gradient_function(tr)(w, P, lam_g)).ravel()
    return tr.layout.unpack(grad)


def _symmetric(G: np.ndarray) -> np.ndarray:
    """(G + G')/2, the derivative of J by each entry of a symmetric matrix of the file.

    The file can only change (i, j) and (j, i) together, so each is given half the derivative of that change.
    Before, Σ0 gave it all to the upper entry (its lower one read 0.0), M and K halves and Q an uneven split
    depending on B (random-problem audit).
    """
    G = np.atleast_2d(np.asarray(G, float))
    return 0.5 * (G + G.T)


def _matrix_leaves(prefix: str, G: np.ndarray) -> dict[str, float]:
    G = np.atleast_2d(G)
    return {f"{prefix}[{i}][{j}]": float(G[i, j]) for i in range(G.shape[0]) for j in range(G.shape[1])}


def _vector_leaves(prefix: str, g: Any) -> dict[str, float]:
    return {f"{prefix}[{j}]": float(v) for j, v in enumerate(np.ravel(g))}


def _noise_names(noise: Any) -> list[str]:
    """Field names of the noise model's parameters, in the order of ``parameters()``, or ``theta[j]``."""
    values = noise.parameters()
    fields = [name for name in type(noise).model_fields if name != "model"]
    if len(fields) == len(values) and all(getattr(noise, f) == v for f, v in zip(fields, values, strict=True)):
        return fields
    return [f"theta[{j}]" for j in range(len(values))]


def leaf_sensitivities(problem: Problem, blocks: dict[str, np.ndarray]) -> dict[str, float]:
    """``{key path: dJ*/d(value)}`` for every numeric leaf of the problem (chain rule of path_constraints.md §4).

    ``sensors[i].measures`` (when given as rows) moves ``C_i`` and the rows' locations (eq. path.8).
    """
    mats = problem.matrices()
    out: dict[str, float] = {"horizon.t0": float(blocks["t0"][0]), "horizon.tf": float(blocks["tf"][0])}
    field = problem.process.field is not None  # A, B, Q, the locations (and Σ0 unless given) derived from it
    if not field:
        B, Q = np.asarray(problem.process.B, float), np.asarray(problem.process.Q, float)
        G = np.asarray(blocks["BQB"])
        out |= _matrix_leaves("process.A", blocks["A"])
        out |= _matrix_leaves("process.B", (G + G.T) @ B @ Q)
        out |= _matrix_leaves("process.Q", _symmetric(B.T @ G @ B))
    if problem.process.Sigma0 is not None:
        out |= _matrix_leaves("process.Sigma0", _symmetric(blocks["Sigma0"]))
    d_loc = np.zeros_like(mats["locations"])
    for i, sensor in enumerate(problem.sensors):
        if not field:  # a field's locations are its grid's: no numbers of the file
            rows = np.abs(problem.measurement_rows(i))
            d_loc += (rows / rows.sum(axis=1, keepdims=True)).T @ np.asarray(blocks[f"rowloc_{i}"])
        key = f"sensors[{i}]"
        if sensor.measures is not None and not problem.is_point(i):
            out |= _matrix_leaves(f"{key}.measures", _measures_gradient(problem, i, blocks))
        out |= _vector_leaves(f"{key}.p0", blocks[f"p0_{i}"]) | _vector_leaves(f"{key}.v0", blocks[f"v0_{i}"])
        for name, value in zip(_noise_names(sensor.noise), np.ravel(blocks[f"theta_{i}"]), strict=True):
            out[f"{key}.noise.{name}"] = float(value)
        if f"pT_{i}" in blocks:
            out |= _vector_leaves(f"{key}.terminal.p", blocks[f"pT_{i}"])
        if f"vT_{i}" in blocks:
            out |= _vector_leaves(f"{key}.terminal.v", blocks[f"vT_{i}"])
        if f"umax_{i}" in blocks:
            out[f"{key}.u_max"] = float(blocks[f"umax_{i}"][0])
    if not field:
        out |= _matrix_leaves("process.locations", d_loc)
    for key in ("M", "K"):  # a named weight (mean, sum, zero) has no numbers in the file
        if isinstance(getattr(problem.cost, key), list):
            out |= _matrix_leaves(f"cost.{key}", _symmetric(blocks[key]))
    out["cost.alpha"] = float(blocks["alpha"][0])
    out |= _constraint_leaves(problem, blocks)
    return out


def _measures_gradient(problem: Problem, i: int, blocks: dict[str, np.ndarray]) -> np.ndarray:
    """dJ*/dC of sensor ``i``'s measurement rows C (m, n): directly and through the rows' locations (eq. path.8).

    The location of row r is ``ℓ_r = Σ_j |c_rj| s_j / S_r`` with ``S_r = Σ_j |c_rj|``, so
    ``∂ℓ_r/∂c_rj = sign(c_rj) (s_j − ℓ_r) / S_r``; at ``c_rj = 0`` the two one-sided derivatives differ and
    their mean (``sign 0 = 0``, what a central difference converges to) is reported.
    """
    C = problem.measurement_rows(i)
    locations = problem.matrices()["locations"]  # (n, 2)
    S = np.abs(C).sum(axis=1, keepdims=True)  # (m, 1)
    ell = problem.row_locations(i)  # (m, 2)
    G_loc = np.asarray(blocks[f"rowloc_{i}"])  # (m, 2)
    through = np.einsum("rk,rjk->rj", G_loc, locations[None, :, :] - ell[:, None, :])
    return np.asarray(blocks[f"C_{i}"]) + np.sign(C) * through / S


def _constraint_leaves(problem: Problem, blocks: dict[str, np.ndarray]) -> dict[str, float]:
    c = problem.constraints
    if c is None:
        return {}
    out: dict[str, float] = {}
    for k, zone in enumerate(c.keep_out):
        b = np.asarray(blocks[f"keep_out[{k}]"])
        if hasattr(zone, "radius"):
            out |= _vector_leaves(f"constraints.keep_out[{k}].center", b.ravel()[:2])
            out[f"constraints.keep_out[{k}].radius"] = float(b.ravel()[2])
        else:
            out |= _matrix_leaves(f"constraints.keep_out[{k}].polygon", b)
    for name in ("min_separation", "max_speed"):
        if name in blocks:
            out[f"constraints.{name}"] = float(np.ravel(blocks[name])[0])
    if "workspace" in blocks:
        w = np.ravel(blocks["workspace"])
        out |= _vector_leaves("constraints.workspace.x", w[:2]) | _vector_leaves("constraints.workspace.y", w[2:])
    return out


def solution_sensitivities(tr: Any, solution: Any) -> dict[str, float]:
    """``{key path: dJ*/d(value)}`` of a solved direct :class:`~mobisense.ocp.solution.Solution`."""
    nlp = solution.nlp
    return leaf_sensitivities(solution.problem, parameter_gradient(tr, nlp["w"], nlp["lam_g"], nlp["P"]))
