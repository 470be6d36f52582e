"""The state vector of the mobile-sensor problem, defined once: ``x = [σ, p_1, …, p_N, v_1, …, v_N]``.

``σ`` is the upper triangle of the error covariance Σ, row by row (n(n+1)/2 entries), ``p_i`` (L) and
``v_i`` (L/T) the planar position and velocity of sensor i; the controls are ``u = [u_1, …, u_N]``
(L/T²). The costate of x has the same layout; for the off-diagonal entries σ_ij, which stand for both
Σ_ij and Σ_ji, the costate is twice the matrix costate: ``μ_σij = 2 Λ_ij`` (docs/theory/indirect.md §1.5).
Every method (direct, indirect), the solution and the replay read and write x through
:class:`StateLayout`, never by slicing it by hand.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["StateLayout", "sym_to_vec", "vec_to_sym", "triangle_labels", "diagonal_indices"]


def _triangle(n: int) -> list[tuple[int, int]]:
    return [(i, j) for i in range(n) for j in range(i, n)]


@functools.lru_cache(maxsize=64)
def _triangle_indices(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.triu_indices(n)``, made once per n (read-only): a solve unpacks Σ several times per task."""
    rows, cols = np.triu_indices(n)
    rows.setflags(write=False)
    cols.setflags(write=False)
    return rows, cols


def diagonal_indices(n: int) -> list[int]:
    """Positions of the diagonal entries Σ[i,i] in the upper-triangle vector."""
    return [k for k, (i, j) in enumerate(_triangle(n)) if i == j]


def triangle_labels(n: int) -> list[str]:
    """Names of the upper-triangle entries, ``['Σ[0,0]', 'Σ[0,1]', …]``."""
    return [f"Σ[{i},{j}]" for i, j in _triangle(n)]


def sym_to_vec(S: Any, n: int) -> Any:
    """Upper triangle (row-major) of a symmetric n×n matrix as a vector.

    Parameters
    ----------
    S : ndarray, shape (..., n, n), or CasADi matrix (n, n)
    n : int

    Returns
    -------
    ndarray, shape (..., n(n+1)/2), or CasADi column
    """
    if isinstance(S, np.ndarray):
        rows, cols = _triangle_indices(n)
        return S[..., rows, cols]
    import casadi as ca

    return ca.vertcat(*[S[i, j] for i, j in _triangle(n)])


def vec_to_sym(s: Any, n: int) -> Any:
    """Symmetric n×n matrix from its upper-triangle vector.

    Parameters
    ----------
    s : ndarray, shape (..., n(n+1)/2), or CasADi column
    n : int

    Returns
    -------
    ndarray, shape (..., n, n), or CasADi matrix (n, n)
    """
    if isinstance(s, np.ndarray):
        out = np.zeros(s.shape[:-1] + (n, n))
        rows, cols = _triangle_indices(n)
        out[..., rows, cols] = s
        out[..., cols, rows] = s
        return out
    import casadi as ca

    entries = [[None] * n for _ in range(n)]
    for k, (i, j) in enumerate(_triangle(n)):
        entries[i][j] = s[k]
        entries[j][i] = s[k]
    return ca.vertcat(*[ca.horzcat(*row) for row in entries])


@dataclass(frozen=True)
class StateLayout:
    """Where each piece of the state vector sits, and how to split and join it.

    Parameters
    ----------
    n : int
        Number of process states (Σ is n×n).
    N : int
        Number of sensors.
    """

    n: int
    N: int

    @property
    def n_sigma(self) -> int:
        """Number of covariance entries n(n+1)/2."""
        return self.n * (self.n + 1) // 2

    @property
    def nx(self) -> int:
        """State dimension n(n+1)/2 + 4N."""
        return self.n_sigma + 4 * self.N

    @property
    def nu(self) -> int:
        """Control dimension 2N."""
        return 2 * self.N

    @property
    def sigma(self) -> slice:
        """The upper triangle σ of Σ."""
        return slice(0, self.n_sigma)

    @property
    def positions(self) -> slice:
        """All sensor positions ``[p_1, …, p_N]``."""
        return slice(self.n_sigma, self.n_sigma + 2 * self.N)

    @property
    def velocities(self) -> slice:
        """All sensor velocities ``[v_1, …, v_N]``."""
        return slice(self.n_sigma + 2 * self.N, self.nx)

    def position(self, i: int) -> slice:
        """Position ``p_i`` of sensor ``i`` (2 entries)."""
        start = self.n_sigma + 2 * i
        return slice(start, start + 2)

    def velocity(self, i: int) -> slice:
        """Velocity ``v_i`` of sensor ``i`` (2 entries)."""
        start = self.n_sigma + 2 * self.N + 2 * i
        return slice(start, start + 2)

    def control(self, i: int) -> slice:
        """Control ``u_i`` of sensor ``i`` in the control vector (2 entries)."""
        return slice(2 * i, 2 * i + 2)

    @property
    def groups(self) -> dict[str, slice]:
        """The three blocks by name: ``Sigma``, ``p``, ``v``."""
        return {"Sigma": self.sigma, "p": self.positions, "v": self.velocities}

    # ------------------------------------------------------------------ numbers
    def split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Σ (..., n, n), p (..., N, 2) and v (..., N, 2) from states x (..., nx)."""
        x = np.asarray(x, dtype=float)
        lead = x.shape[:-1]
        return (
            vec_to_sym(x[..., self.sigma], self.n),
            x[..., self.positions].reshape(*lead, self.N, 2),
            x[..., self.velocities].reshape(*lead, self.N, 2),
        )

    def join(self, Sigma: np.ndarray, p: np.ndarray, v: np.ndarray) -> np.ndarray:
        """States x (..., nx) from Σ (..., n, n), p (..., N, 2) and v (..., N, 2)."""
        Sigma, p, v = (np.asarray(a, dtype=float) for a in (Sigma, p, v))
        lead = p.shape[:-2]
        return np.concatenate(
            [sym_to_vec(Sigma, self.n), p.reshape(*lead, 2 * self.N), v.reshape(*lead, 2 * self.N)], axis=-1
        )

    def split_costate(self, lam: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Matrix costate Λ (..., n, n), λ_p and λ_v (..., N, 2) from a costate of x (..., nx).

        Off-diagonal σ_ij stands for Σ_ij and Σ_ji, so ``Λ_ij = μ_σij / 2`` there.
        """
        Lam, lam_p, lam_v = self.split(lam)
        off = ~np.eye(self.n, dtype=bool)
        Lam[..., off] *= 0.5
        return Lam, lam_p, lam_v

    def join_costate(self, Lam: np.ndarray, lam_p: np.ndarray, lam_v: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`split_costate`."""
        lam = self.join(Lam, lam_p, lam_v)
        rows, cols = _triangle_indices(self.n)
        lam[..., self.sigma] *= np.where(rows == cols, 1.0, 2.0)
        return lam

    # ------------------------------------------------------------------ symbols
    def symbolic(self, x: Any) -> tuple[Any, list[Any], list[Any]]:
        """Σ (n×n), the positions ``[p_i]`` and the velocities ``[v_i]`` of a CasADi state column."""
        return (
            vec_to_sym(x[self.sigma], self.n),
            [x[self.position(i)] for i in range(self.N)],
            [x[self.velocity(i)] for i in range(self.N)],
        )

    def join_symbolic(self, Sigma: Any, positions: Any, velocities: Any) -> Any:
        """A CasADi state column from Σ (n×n) and the sensors' positions and velocities (columns of 2N, or lists)."""
        import casadi as ca

        def column(parts: Any) -> Any:
            return ca.vertcat(*parts) if isinstance(parts, (list, tuple)) else parts

        return ca.vertcat(sym_to_vec(Sigma, self.n), column(positions), column(velocities))

    def labels(self, sensor_names: list[str]) -> list[str]:
        """Readable name of every state component (used to report violated constraints)."""
        names = triangle_labels(self.n)
        names += [f"sensor {name} position {c}" for name in sensor_names for c in "xy"]
        names += [f"sensor {name} velocity {c}" for name in sensor_names for c in "xy"]
        return names
