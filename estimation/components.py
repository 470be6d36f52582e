"""Small matrices stored entry by entry ("structure of arrays"), for very many tiny Kalman problems at once.

A :class:`ComponentMatrix` of shape ``(n, m)`` holds ``n·m`` entries, each either a numpy array over the
batch (all entries broadcast together, e.g. ``(K, B)`` for B runs and K steps) or a Python ``float``
constant. The kernels of :mod:`mobisense.estimation.kalman` evaluate on it unchanged (``@``, ``+``,
``transpose``, ``solve``, ``inverse``): every scalar formula of a 3 × 3 recursion becomes one numpy
operation over the whole batch, instead of one LAPACK call per tiny matrix, and float entries ``0.0``
and ``1.0`` are structural — products with them are skipped, as CasADi skips its structural zeros (the
transition ``[[1, Δr'], [0, I]]`` costs 4 operations, not 27). Why: numpy's batched ``matmul``/``solve``
on ``(B, 3, 3)`` stacks loop over the tiny matrices one call each and take ≈ 0.2–1 µs per matrix; here
each operation streams contiguous arrays.

``solve`` and ``inverse`` assume a symmetric positive definite matrix (Cholesky), as
:func:`mobisense.estimation.kalman.solve` documents; a non-positive pivot gives NaN entries.

Example
-------
>>> import numpy as np
>>> from mobisense.estimation.components import ComponentMatrix
>>> S = ComponentMatrix.from_array(np.array([[[4.0, 2.0], [2.0, 3.0]]] * 5))  # five 2 × 2 matrices
>>> np.allclose(S.inverse().to_array() @ S.to_array(), np.eye(2))
True
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["ComponentMatrix"]

Entry = Any  # numpy array over the batch, or a Python float (0.0 and 1.0 are structural)


def _mul(a: Entry, b: Entry) -> Entry:
    if type(a) is float:
        if a == 0.0:
            return 0.0
        if a == 1.0:
            return b
    if type(b) is float:
        if b == 0.0:
            return 0.0
        if b == 1.0:
            return a
    return a * b


def _add(a: Entry, b: Entry) -> Entry:
    if type(a) is float and a == 0.0:
        return b
    if type(b) is float and b == 0.0:
        return a
    return a + b


def _sub(a: Entry, b: Entry) -> Entry:
    if type(b) is float and b == 0.0:
        return a
    return -b if type(a) is float and a == 0.0 else a - b


def _dot(row: Sequence[Entry], col: Sequence[Entry]) -> Entry:
    acc: Entry = 0.0
    for a, b in zip(row, col, strict=True):
        acc = _add(acc, _mul(a, b))
    return acc


def _entry(value: Any) -> Entry:
    """Python floats for scalars (so 0 and 1 are structural), arrays otherwise."""
    if np.ndim(value) == 0:
        return float(value)
    return value


class ComponentMatrix:
    """An ``(n, m)`` matrix whose entries are batch arrays or float constants (see the module docstring).

    Parameters
    ----------
    rows : sequence of sequences
        ``rows[i][j]`` is entry ``(i, j)``: an ndarray (any batch shape, broadcastable with the other
        entries) or a float.
    """

    __slots__ = ("rows", "transpose_of")
    __array_ufunc__ = None  # ndarray ⊕ ComponentMatrix defers to our reflected operators

    def __init__(self, rows: Sequence[Sequence[Entry]]) -> None:
        self.rows = [[_entry(e) for e in row] for row in rows]
        self.transpose_of: ComponentMatrix | None = None  # set by .T: W.T @ W is computed as symmetric

    # ------------------------------------------------------------------ construction and conversion
    @classmethod
    def from_array(cls, array: np.ndarray, constant: bool = False) -> ComponentMatrix:
        """Matrices ``(..., n, m)`` → entries ``array[..., i, j]``.

        An entry equal over the whole batch becomes a float (structural when 0 or 1), the others
        contiguous copies; with ``constant`` the matrices are all equal and only the first is read.
        """
        array = np.asarray(array, dtype=float)
        if constant or array.ndim == 2:
            return cls([[float(v) for v in row] for row in array.reshape((-1,) + array.shape[-2:])[0]])
        n, m = array.shape[-2:]
        rows = []
        for i in range(n):
            row = []
            for j in range(m):
                e = np.ascontiguousarray(array[..., i, j])
                first = e.flat[0]
                row.append(float(first) if np.all(e == first) else e)
            rows.append(row)
        return cls(rows)

    @classmethod
    def identity(cls, n: int) -> ComponentMatrix:
        """``I_n`` with structural entries."""
        return cls([[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)])

    def to_array(self, batch: tuple[int, ...] | None = None) -> np.ndarray:
        """The matrices as one array ``(*batch, n, m)`` (batch shape broadcast from the entries by default)."""
        if batch is None:
            batch = np.broadcast_shapes(*(np.shape(e) for row in self.rows for e in row))
        out = np.empty(tuple(batch) + self.shape)
        for i, row in enumerate(self.rows):
            for j, e in enumerate(row):
                out[..., i, j] = e
        return out

    def index(self, key: Any) -> ComponentMatrix:
        """Every array entry indexed by ``key`` (e.g. one step ``k`` of ``(K, B)`` entries); floats kept."""
        return ComponentMatrix([[e if type(e) is float else e[key] for e in row] for row in self.rows])

    # ------------------------------------------------------------------ shape and slicing
    @property
    def shape(self) -> tuple[int, int]:
        """``(n, m)``."""
        return len(self.rows), len(self.rows[0])

    @property
    def T(self) -> ComponentMatrix:  # noqa: N802  (numpy's name)
        """Transpose."""
        out = ComponentMatrix([list(col) for col in zip(*self.rows, strict=True)])
        out.transpose_of = self
        return out

    def __getitem__(self, key: Any) -> ComponentMatrix:
        """``M[..., cols]`` or ``M[rows, cols]`` with slices (the matrix axes only)."""
        key = key if isinstance(key, tuple) else (key,)
        if key and key[0] is Ellipsis:
            key = (slice(None),) * (3 - len(key)) + key[1:]
        rows, cols = key
        return ComponentMatrix([row[cols] for row in self.rows[rows]])

    @staticmethod
    def hcat(a: ComponentMatrix, b: ComponentMatrix) -> ComponentMatrix:
        """``[a | b]``."""
        return ComponentMatrix([ra + rb for ra, rb in zip(a.rows, b.rows, strict=True)])

    # ------------------------------------------------------------------ arithmetic
    def __matmul__(self, other: Any) -> ComponentMatrix:
        if not isinstance(other, ComponentMatrix):
            other = ComponentMatrix.from_array(other, True)  # a constant matrix
        cols = list(zip(*other.rows, strict=True))
        if self.transpose_of is other:  # W' W: symmetric, one triangle
            return _symmetric(lambda i, j: _dot(self.rows[i], cols[j]), len(cols))
        return ComponentMatrix([[_dot(row, col) for col in cols] for row in self.rows])

    def congruence(self, M: Any) -> ComponentMatrix:
        """``self M self'`` for a symmetric ``M``: the lower triangle, mirrored (same entry objects)."""
        AM = (self @ M).rows
        return _symmetric(lambda i, j: _dot(AM[i], self.rows[j]), len(AM))

    def symmetrize(self) -> ComponentMatrix:
        """``(M + M')/2``; entries already equal by construction (the same object) are kept as they are."""
        n = self.shape[0]
        return _symmetric(lambda i, j: self.rows[i][j] if self.rows[i][j] is self.rows[j][i] or i == j
                          else _mul(0.5, _add(self.rows[i][j], self.rows[j][i])), n)  # fmt: skip

    def __rmatmul__(self, other: Any) -> ComponentMatrix:
        return ComponentMatrix.from_array(other, True) @ self

    def _elementwise(self, other: Any, op: Any) -> ComponentMatrix:
        if isinstance(other, ComponentMatrix):
            pairs = zip(self.rows, other.rows, strict=True)
            return ComponentMatrix([[op(a, b) for a, b in zip(ra, rb, strict=True)] for ra, rb in pairs])
        return self._elementwise(ComponentMatrix.from_array(np.broadcast_to(other, self.shape), True), op)

    def __add__(self, other: Any) -> ComponentMatrix:
        return self._elementwise(other, _add)

    __radd__ = __add__

    def __sub__(self, other: Any) -> ComponentMatrix:
        return self._elementwise(other, _sub)

    def __rsub__(self, other: Any) -> ComponentMatrix:
        return (-self) + other

    def __neg__(self) -> ComponentMatrix:
        return ComponentMatrix([[_mul(-1.0, e) if type(e) is float else -e for e in row] for row in self.rows])

    def __mul__(self, scalar: float) -> ComponentMatrix:
        s = float(scalar)
        return ComponentMatrix([[_mul(s, e) for e in row] for row in self.rows])

    __rmul__ = __mul__

    # ------------------------------------------------------------------ SPD algebra
    def cholesky(self) -> ComponentMatrix:
        """Lower ``L`` with ``L L' = self`` (symmetric positive definite; only the lower triangle is read)."""
        n = self.shape[0]
        L: list[list[Entry]] = [[0.0] * n for _ in range(n)]
        for j in range(n):
            d = self.rows[j][j]
            for k in range(j):
                d = _sub(d, _mul(L[j][k], L[j][k]))
            d = np.sqrt(d)
            L[j][j] = float(d) if np.ndim(d) == 0 else d
            inv = 1.0 / d
            for i in range(j + 1, n):
                s = self.rows[i][j]
                for k in range(j):
                    s = _sub(s, _mul(L[i][k], L[j][k]))
                L[i][j] = _mul(s, inv)
        return ComponentMatrix(L)

    def whiten(self, rhs: ComponentMatrix, factor: ComponentMatrix | None = None) -> ComponentMatrix:
        """``L⁻¹ rhs`` with ``L L' = self`` (symmetric positive definite; forward substitution)."""
        L = (factor or self.cholesky()).rows
        n = len(L)
        inv_diag = [1.0 / L[i][i] for i in range(n)]
        out = []
        for col in zip(*rhs.rows, strict=True):  # one right-hand side at a time
            z: list[Entry] = []
            for i in range(n):
                s = col[i]
                for k in range(i):
                    s = _sub(s, _mul(L[i][k], z[k]))
                z.append(_mul(s, inv_diag[i]))
            out.append(z)
        return ComponentMatrix([list(r) for r in zip(*out, strict=True)])

    def solve(self, rhs: ComponentMatrix) -> ComponentMatrix:
        """``self⁻¹ rhs`` for a symmetric positive definite ``self`` (Cholesky, forward and back substitution)."""
        factor = self.cholesky()
        L, z = factor.rows, self.whiten(rhs, factor).rows
        n = len(L)
        out = []
        for col in zip(*z, strict=True):
            x: list[Entry] = [0.0] * n
            for i in reversed(range(n)):  # L' x = z
                s = col[i]
                for k in range(i + 1, n):
                    s = _sub(s, _mul(L[k][i], x[k]))
                x[i] = _mul(s, 1.0 / L[i][i])
            out.append(x)
        return ComponentMatrix([list(r) for r in zip(*out, strict=True)])

    def inverse(self) -> ComponentMatrix:
        """``self⁻¹ = L⁻ᵀ L⁻¹`` of a symmetric positive definite matrix (symmetric by construction)."""
        W = self.whiten(ComponentMatrix.identity(self.shape[0]))  # L⁻¹ (lower triangular)
        return W.T @ W


def _symmetric(entry: Any, n: int) -> ComponentMatrix:
    """The ``n × n`` matrix with ``entry(i, j)`` for ``j ≤ i``, mirrored to the upper triangle."""
    rows: list[list[Entry]] = [[0.0] * n for _ in range(n)]
    for i in range(n):
        for j in range(i + 1):
            rows[i][j] = rows[j][i] = entry(i, j)
    return ComponentMatrix(rows)
