"""Numeric evaluations of the transcription, made cheap: buffered CasADi calls and a memory per parameter vector.

:class:`BufferedFunction` evaluates a CasADi Function on numpy arrays without converting them to ``DM``
(``Function.buffer``); :class:`ParameterMemo` remembers what depends on the parameter vector alone.

CasADi's Python call converts every numpy argument to a ``DM`` and every result back, element by element:
≈ 80–110 ns per number here, so 0.1 ms for a vector of 1000 and ≈ 0.9 ms for the eight arguments and six
results of one Ipopt call of a K = 60 transcription — as much as a whole warm-started solve's function
evaluations. :meth:`casadi.Function.buffer` evaluates the function on memory it is pointed at instead;
:class:`BufferedFunction` keeps one such buffer per thread, copies the arguments into it with numpy and returns
copies of the results, in the shapes ``np.asarray(f(*args))`` has (``(rows, cols)``), so it replaces the plain
call where the arguments are numbers. The results are the same bits (tests/ocp/test_numeric_calls.py).

The scales of the NLP's variables and constraints, x̃_0 and the kernels' parameter input depend on the parameter
vector ``P`` alone; the ε steps of one solve, a warm start's source and target and consecutive tasks of a sweep
chain ask for them again and again, so :class:`ParameterMemo` keeps them for the last few vectors.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import casadi as ca
import numpy as np

__all__ = ["BufferedFunction", "ParameterMemo"]


class BufferedFunction:
    """A CasADi Function evaluated through a buffer of contiguous numpy arrays (see the module docstring).

    Parameters
    ----------
    function : casadi.Function
        Any Function; one with a sparse input or output is called the plain way (its results as numpy arrays).
    """

    def __init__(self, function: ca.Function) -> None:
        self.function = function
        n_in, n_out = function.n_in(), function.n_out()
        self.names_in = [function.name_in(i) for i in range(n_in)]
        self.shapes_in = [tuple(function.size_in(i)) for i in range(n_in)]
        self.shapes_out = [tuple(function.size_out(i)) for i in range(n_out)]
        self.dense = all(function.sparsity_in(i).is_dense() for i in range(n_in)) and all(
            function.sparsity_out(i).is_dense() for i in range(n_out)
        )
        self._defaults = [float(function.default_in(i)) for i in range(n_in)]
        self._local = threading.local()

    def _buffer(self) -> tuple[Any, Any, list[np.ndarray], list[np.ndarray]]:
        """The calling thread's buffer, its evaluation, and the arrays it reads arguments from and writes results to."""
        state = getattr(self._local, "state", None)
        if state is None:
            buffer, evaluate = self.function.buffer()
            args = [np.zeros(r * c) for r, c in self.shapes_in]
            results = [np.zeros(r * c) for r, c in self.shapes_out]
            for i, array in enumerate(args):
                buffer.set_arg(i, memoryview(array))
            for i, array in enumerate(results):
                buffer.set_res(i, memoryview(array))
            state = self._local.state = (buffer, evaluate, args, results)
        return state  # type: ignore[no-any-return]

    def __call__(self, *args: Any) -> Any:
        """``f(*args)`` on numbers: one array ``(rows, cols)`` for one result, a tuple of them for several."""
        results = self.evaluate(list(args))
        return results[0] if len(results) == 1 else tuple(results)

    def call(self, named: dict[str, Any]) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """``f(**named)`` on numbers (missing inputs take the Function's defaults), and the call's ``stats``."""
        unknown = set(named) - set(self.names_in)
        if unknown:
            raise ValueError(f"{self.function.name()}: unknown inputs {sorted(unknown)}; expected {self.names_in}")
        args = [named.get(name) for name in self.names_in]
        results = self.evaluate(args)
        stats = self._buffer()[0].stats() if self.dense else self.function.stats()
        names = [self.function.name_out(i) for i in range(len(results))]
        return dict(zip(names, results, strict=True)), stats

    def evaluate(self, args: list[Any]) -> list[np.ndarray]:
        """The results of ``f`` at ``args`` (``None``: the input's default), as arrays ``(rows, cols)``."""
        if len(args) != len(self.shapes_in):
            raise ValueError(f"{self.function.name()}: expected {len(self.shapes_in)} arguments, got {len(args)}")
        if not self.dense:
            return self._plain(args)
        buffer, evaluate, inputs, outputs = self._buffer()
        for i, (value, target, (rows, cols)) in enumerate(zip(args, inputs, self.shapes_in, strict=True)):
            if value is None:
                target[:] = self._defaults[i]
                continue
            array = np.asarray(value, float)
            if array.size != rows * cols or (array.ndim == 2 and array.shape != (rows, cols)):
                raise ValueError(
                    f"{self.function.name()}: input {self.names_in[i]} has shape {array.shape}, "
                    f"expected {rows} × {cols}"
                )
            # CasADi stores matrices column by column
            target[:] = array.reshape(rows, cols).ravel(order="F") if cols > 1 and rows > 1 else array.ravel()
        evaluate()
        if buffer.ret() != 0:  # an evaluation error: the plain call raises CasADi's own message
            return self._plain(args)
        return [o.reshape(cols, rows).T.copy() for o, (rows, cols) in zip(outputs, self.shapes_out, strict=True)]

    def _plain(self, args: list[Any]) -> list[np.ndarray]:
        """CasADi's own call (through ``DM``), the results as arrays ``(rows, cols)``."""
        out = self.function.call([self._defaults[i] if a is None else a for i, a in enumerate(args)])
        return [np.asarray(v, float).reshape(shape) for v, shape in zip(out, self.shapes_out, strict=True)]


class ParameterMemo:
    """Quantities that depend on a parameter vector alone, remembered for the last ``size`` vectors.

    Parameters
    ----------
    size : int
        How many parameter vectors are remembered (per quantity and vector one entry; the oldest is forgotten
        first).
    """

    def __init__(self, size: int = 32) -> None:
        self.size = size
        self._values: dict[tuple[str, bytes], Any] = {}

    def get(self, what: str, P: np.ndarray, compute: Callable[[np.ndarray], Any]) -> Any:
        """``compute(P)`` for the quantity named ``what``, computed once per distinct ``P``.

        Arrays (alone or in a tuple) are returned read-only, so that no caller can change what the next one
        receives.
        """
        P = np.asarray(P, float)
        key = (what, P.tobytes())
        value = self._values.get(key)
        if value is None:
            value = compute(P)
            for array in value if isinstance(value, tuple) else (value,):
                array.setflags(write=False)
            if len(self._values) >= self.size:
                del self._values[next(iter(self._values))]
            self._values[key] = value
        return value
