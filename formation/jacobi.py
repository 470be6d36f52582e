"""Jacobi transform of an N-platform formation (docs/theory/formation_control.md §1), for any N ≥ 2.

Source: Zhang & Leonard (2010), §V-A, eqs. 38-40 (for N = 4).

Positions ``r`` of shape ``(..., N, 2)`` map to the centre ``r_c`` ``(..., 2)`` and the Jacobi vectors
``q`` ``(..., N−1, 2)`` by ``[r_c, q_1, …, q_{N−1}] = [r_1, …, r_N] Ψ`` with ``Ψ = [1/N, Q]``, where the
columns of ``Q`` (N × (N−1)) are orthonormal and orthogonal to ``1``. Then ``Ψ⁻¹ = [1, Q]'`` and for unit
masses the kinetic energy splits exactly (docs/theory/formation_control.md, eq. formation_control.3):

    ½ Σ_i ‖r_i'‖² = ½ N ‖r_c'‖² + ½ Σ_j ‖q_j'‖² ,

Newton's equations ``r_i'' = f_i`` become ``N r_c'' = f_c`` and ``q_j'' = u_j`` with
``[f_c, u_1, …] = [f_1, …, f_N] Ψ^{-T} = [f_1, …, f_N] [1, Q]``, i.e. ``f_c = Σ_i f_i`` and
``u_j = Σ_i Q_ij f_i``; back, ``f_i = f_c/N + Σ_j Q_ij u_j``. Shape forces (``f_c = 0``) sum to zero and
leave the centre's motion untouched.

Construction of ``Q`` (choice; the paper only requires that Ψ decouple the kinetic energy): a binary
*cluster tree* over the platforms. Each internal node joining clusters A (m platforms) and B (n
platforms) contributes the Jacobi vector ``q = √(mn/(m+n)) (mean_B r − mean_A r)``; the N − 1 internal
nodes, in post-order (left subtree, right subtree, node), are ``q_1 … q_{N−1}``. These columns are
orthonormal and orthogonal to ``1`` for every tree. The default tree bisects the platform list and
mirrors the second half, which for N = 4 is ``((1, 2), (4, 3))`` and reproduces the paper's eq. 38
exactly: ``q1 = (r2 − r1)/√2``, ``q2 = (r3 − r4)/√2``, ``q3 = ½(r4 + r3 − r2 − r1)``; for N = 2 it is
``q1 = (r2 − r1)/√2``. Any other tree (nested tuples of 0-based indices) can be passed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.errors import brief

__all__ = ["ClusterTree", "MAX_PLATFORMS", "default_tree", "jacobi_matrix", "JacobiTransform"]

#: a platform index or a pair of sub-trees
ClusterTree = int | tuple["ClusterTree", "ClusterTree"]

#: most platforms a Jacobi transform accepts. ``Ψ`` is a dense N × N matrix, built from N − 1 columns of length
#: N (2 N² floats at the peak: 270 MB at 4096) and applied at every right-hand-side evaluation of a simulation
#: (N² multiply-adds). Formations in the literature and in scenario files have 2–64 platforms (a scenario's
#: ``platforms.count`` is at most 64), :func:`~mobisense.estimation.cooperative.steady_state.steady_state` takes
#: up to 5000; 4096 leaves room for any realistic formation while a typo (10⁶) fails at once instead of
#: allocating 16 TB until MemoryError.
MAX_PLATFORMS = 4096


def _check_count(n_platforms: int) -> int:
    """``n_platforms`` if it is an integer in 2 … :data:`MAX_PLATFORMS`, else ``ValueError`` (before any allocation)."""
    if isinstance(n_platforms, bool) or not isinstance(n_platforms, (int, np.integer)):
        raise ValueError(f"n_platforms: expected an integer, got {brief(n_platforms)}")
    if not 2 <= n_platforms <= MAX_PLATFORMS:
        raise ValueError(
            f"n_platforms: expected 2 … {MAX_PLATFORMS} platforms (a formation needs at least 2; Ψ is a dense N × N "
            f"matrix), got {n_platforms}"
        )
    return int(n_platforms)


def default_tree(n_platforms: int) -> ClusterTree:
    """Balanced bisection of ``0 … N−1`` with the second half mirrored (N = 4: ``((0, 1), (3, 2))``).

    ``n_platforms`` is an integer in 2 … :data:`MAX_PLATFORMS` (``ValueError`` otherwise).
    """
    n_platforms = _check_count(n_platforms)

    def build(indices: list[int]) -> ClusterTree:
        if len(indices) == 1:
            return indices[0]
        half = len(indices) // 2
        return (build(indices[:half]), build(indices[half:][::-1]))

    return build(list(range(n_platforms)))


def _leaves(tree: ClusterTree) -> list[int]:
    return [tree] if isinstance(tree, int) else _leaves(tree[0]) + _leaves(tree[1])


def jacobi_matrix(n_platforms: int, tree: ClusterTree | None = None) -> np.ndarray:
    """The Jacobi transform ``Ψ = [1/N, Q]`` of a cluster tree (eqs. formation_control.1–2).

    Parameters
    ----------
    n_platforms : int
        N ≥ 2.
    tree : ClusterTree, optional
        Nested pairs of 0-based platform indices covering each platform once (default
        :func:`default_tree`).

    Returns
    -------
    ndarray, shape (N, N)
        Column 0 is ``1/N``; columns 1 … N−1 are the orthonormal Jacobi directions.

    Raises
    ------
    ValueError
        For ``n_platforms`` outside 2 … :data:`MAX_PLATFORMS` (checked before anything is allocated), or a
        tree that does not cover each platform once.
    """
    n_platforms = _check_count(n_platforms)
    tree = default_tree(n_platforms) if tree is None else tree
    leaves = _leaves(tree)
    if sorted(leaves) != list(range(n_platforms)):
        raise ValueError(
            f"tree: expected each platform 0 … {n_platforms - 1} exactly once, got leaves {leaves}"
        )
    columns: list[np.ndarray] = []

    def visit(node: ClusterTree) -> list[int]:
        if isinstance(node, int):
            return [node]
        A, B = visit(node[0]), visit(node[1])
        m, n = len(A), len(B)
        column = np.zeros(n_platforms)
        column[A] = -1.0 / m
        column[B] = 1.0 / n
        columns.append(np.sqrt(m * n / (m + n)) * column)  # q = √(mn/(m+n)) (mean_B − mean_A)
        return A + B

    visit(tree)
    return np.column_stack([np.full(n_platforms, 1.0 / n_platforms), *columns])


@dataclass(frozen=True)
class JacobiTransform:
    """Centre and Jacobi vectors of a formation, and the equivalent forces (docs/theory/formation_control.md §1).

    Parameters
    ----------
    n_platforms : int
        2 ≤ N ≤ :data:`MAX_PLATFORMS`.
    tree : ClusterTree, optional
        Cluster tree defining the Jacobi vectors (default :func:`default_tree`).

    Examples
    --------
    >>> import numpy as np
    >>> jt = JacobiTransform(4)
    >>> r = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, 2.0], [0.0, -2.0]])
    >>> center, q = jt.to_jacobi(r)
    >>> np.round(q / np.sqrt(2), 12).tolist()  # q1 = √2 a e1, q2 = √2 b e2, q3 = 0 for the cross
    [[1.0, 0.0], [0.0, 2.0], [0.0, 0.0]]
    """

    n_platforms: int
    tree: ClusterTree | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "_Psi", jacobi_matrix(self.n_platforms, self.tree))

    @property
    def matrix(self) -> np.ndarray:
        """``Ψ``, shape (N, N)."""
        return self._Psi  # type: ignore[attr-defined]

    @property
    def directions(self) -> np.ndarray:
        """``Q`` (N, N−1): orthonormal columns orthogonal to ``1``."""
        return self.matrix[:, 1:]

    def _check(self, x: np.ndarray, rows: int, name: str) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        if x.shape[-2:] != (rows, 2):
            raise ValueError(f"{name}: expected shape (..., {rows}, 2), got {x.shape}")
        return x

    def to_jacobi(self, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``[r_c, q] = [r] Ψ`` (eq. formation_control.1): ``(..., N, 2)`` → ``r_c (..., 2)``, ``q (..., N−1, 2)``.

        Linear, so it maps velocities and accelerations the same way.
        """
        r = self._check(positions, self.n_platforms, "positions")
        X = np.swapaxes(self.matrix, 0, 1) @ r  # rows: r_c, q_1, …  (eq. formation_control.1, [r_c, q] = [r] Ψ)
        return X[..., 0, :], X[..., 1:, :]

    def from_jacobi(self, center: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Inverse map ``r_i = r_c + Σ_j Q_ij q_j``, shape ``(..., N, 2)``."""
        q = self._check(q, self.n_platforms - 1, "q")
        return np.asarray(center, dtype=float)[..., None, :] + self.directions @ q  # [r] = [r_c, q] Ψ⁻¹

    def forces_to_jacobi(self, forces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``[f_c, u] = [f] Ψ^{-T}`` (eq. formation_control.4): total force (..., 2), ``u`` (..., N−1, 2)."""
        f = self._check(forces, self.n_platforms, "forces")
        return f.sum(axis=-2), np.swapaxes(self.directions, 0, 1) @ f  # f_c = Σ f_i, u_j = Σ_i Q_ij f_i

    def forces_from_jacobi(self, center_force: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Platform forces ``f_i = f_c/N + Σ_j Q_ij u_j`` (inverse of eq. 40), shape ``(..., N, 2)``."""
        u = self._check(u, self.n_platforms - 1, "u")
        return np.asarray(center_force, dtype=float)[..., None, :] / self.n_platforms + self.directions @ u

    def kinetic_energy(self, velocities: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Centre and shape parts ``(½ N ‖r_c'‖², ½ Σ_j ‖q_j'‖²)`` of the kinetic energy (unit masses)."""
        vc, dq = self.to_jacobi(velocities)
        return 0.5 * self.n_platforms * np.sum(vc**2, axis=-1), 0.5 * np.sum(dq**2, axis=(-2, -1))
