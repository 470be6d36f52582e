"""The errors every command turns into an exit status, and the one-line, bounded text of a value in a message.

- :class:`ConfigError` — invalid input (a file, a key, a command-line option, an output folder that cannot be
  used, a problem too large for the memory budget): exit status 2, nothing written.
- :class:`ComputationError` — a solve or a simulation failed numerically (NaN/inf, a singular matrix, an
  integrator that gave up, memory exhausted): exit status 1, results already complete are kept.
- :class:`OutputError` — an output file could not be written (disk full, I/O error): exit status 1, the
  previous complete version of the file is kept.

:func:`numerical_failures` converts the exceptions numerical libraries raise into :class:`ComputationError`;
:func:`brief` is how a value appears in any message (at most ~80 characters, never a full ``repr``).
"""

from __future__ import annotations

import math
import reprlib
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["ConfigError", "ComputationError", "OutputError", "brief", "one_line", "numerical_failures"]

#: longest text of a value in a message (characters)
VALUE_CHARS = 80


class ConfigError(ValueError):
    """A configuration file (or dict, option, output folder) is invalid; ``str(err)`` is one user-facing line."""


class ComputationError(RuntimeError):
    """A solve or simulation failed numerically; ``str(err)`` is one line (exit status 1)."""


class OutputError(OSError):
    """An output file could not be written (the previous complete file is kept); exit status 1."""


_REPR = reprlib.Repr()
_REPR.maxlevel = 3
_REPR.maxlist = _REPR.maxtuple = _REPR.maxset = _REPR.maxdeque = _REPR.maxarray = 6
_REPR.maxdict = 4
_REPR.maxstring = 60
_REPR.maxlong = 30
_REPR.maxother = 60


def brief(value: Any, limit: int = VALUE_CHARS) -> str:
    """The text of ``value`` for a message: a bounded ``repr`` (nested lists elided), at most ``limit`` characters.

    Never builds the full ``repr`` of a large or self-referencing value (an expanded YAML alias bomb, a
    10⁶-element list), so writing an error message costs O(limit).
    """
    if isinstance(value, float):
        text = repr(value) if math.isfinite(value) else str(value)
    elif _is_array(value):
        np = sys.modules["numpy"]
        text = f"array of shape {value.shape}" if value.size > 6 else np.array2string(value.ravel(), threshold=6)
    else:
        try:
            text = _REPR.repr(value)
        except Exception:  # noqa: BLE001  (a value whose repr fails must not hide the error being reported)
            text = f"<{type(value).__name__}>"
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _is_array(value: Any) -> bool:
    """Whether ``value`` is a numpy array, without importing numpy (``--help`` and ``validate`` need none)."""
    np = sys.modules.get("numpy")
    return np is not None and isinstance(value, np.ndarray)


def one_line(text: str, limit: int = 300) -> str:
    """``text`` on one line (whitespace runs collapsed), at most ``limit`` characters."""
    flat = " ".join(str(text).split())
    return flat if len(flat) <= limit else flat[: limit - 1] + "…"


def _describe(exc: BaseException) -> str:
    if isinstance(exc, MemoryError):
        return "out of memory (lower the problem size or raise --max-memory only if the machine has the memory)"
    text = str(exc).strip()
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    # CasADi errors end with the useful sentence after a long C++ stack of ".../file.cpp:123:" lines
    useful = [line for line in lines if ".cpp:" not in line and not line.startswith(("Error in", "at "))]
    text = (useful or lines or [type(exc).__name__])[-1]
    if type(exc).__name__ == "LinAlgError":  # numpy.linalg's (without importing numpy): name the failure, not the type
        return one_line(
            f"linear algebra failed ({text}): a covariance or gain matrix is singular or not positive definite in "
            "double precision; check that the noise levels and scales are not extreme"
        )
    if text.endswith("Evaluation failed"):  # CasADi's, with the stack only: what failed inside a graph
        return one_line(
            "a CasADi function failed to evaluate (a linear solve on a singular matrix, or a NaN or infinity in the "
            "covariance propagation): check that the noise levels, covariances and scales are not extreme"
        )
    plain = isinstance(exc, RuntimeError) or type(exc).__name__ in text  # our own and CasADi's need no type
    return one_line(text if plain else f"{type(exc).__name__}: {text}")


@contextmanager
def numerical_failures(what: str) -> Iterator[None]:
    """Turn the exceptions of numerical code inside the block into one :class:`ComputationError`.

    ``ArithmeticError`` (overflow, division by zero, ``FloatingPointError``), ``ValueError`` (which includes
    ``numpy.linalg.LinAlgError`` and the value errors of scipy and numpy on non-finite or ill-shaped data),
    ``RuntimeError`` (CasADi, integrators) and ``MemoryError`` become ``ComputationError("{what}: …")``;
    :class:`ConfigError`, :class:`ComputationError`, :class:`OutputError` and ``KeyboardInterrupt`` pass through
    unchanged.

    Parameters
    ----------
    what : str
        What was being computed, for the message (``"solving problems/x.yaml"``).
    """
    try:
        yield
    except (ConfigError, ComputationError, OutputError):
        raise
    except (ArithmeticError, RuntimeError, MemoryError, ValueError) as exc:  # numpy's LinAlgError is a ValueError
        raise ComputationError(f"{what}: {_describe(exc)}") from exc
