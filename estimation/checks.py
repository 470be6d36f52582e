"""Checks of the numbers and arrays given to the estimation and formation classes, with one-line messages.

Each check raises ``ValueError`` with ``"<argument>: expected <what>, got <value>"`` (the value at most ~80
characters, :func:`mobisense.core.errors.brief`) and returns the value converted (``float`` or a float array).
They are meant for constructors and for the arguments whose shape can change between calls, not for the
inner loop of a filter step. Symmetric positive semidefinite matrices are checked by
:func:`mobisense.core.config.check_psd` (one matrix) or
:func:`mobisense.estimation.cooperative.rollouts.check_prior` (a batch of 3 × 3 priors).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from ..core.errors import brief

__all__ = ["check_finite", "check_positive", "check_non_negative", "check_finite_array"]


def _number(name: str, value: Any, expected: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected {expected}, got {brief(value)}") from None
    return number


def check_finite(name: str, value: Any) -> float:
    """``value`` as a float, raising ``ValueError`` unless it is a finite number (of any sign)."""
    number = _number(name, value, "a finite number")
    if not math.isfinite(number):
        raise ValueError(f"{name}: expected a finite number, got {brief(number)}")
    return number


def check_positive(name: str, value: Any, allow_inf: bool = False) -> float:
    """``value`` as a float, raising ``ValueError`` unless it is a number > 0 (finite unless ``allow_inf``).

    Parameters
    ----------
    name : str
        The argument's name, first in the message.
    value : Any
        A real number (a Python or numpy scalar).
    allow_inf : bool
        Accept ``+inf`` (e.g. a limit that is no limit).

    Returns
    -------
    float
    """
    expected = "a number > 0" if allow_inf else "a finite number > 0"
    number = _number(name, value, expected)
    if not (number > 0 and (allow_inf or math.isfinite(number))):
        raise ValueError(f"{name}: expected {expected}, got {brief(number)}")
    return number


def check_non_negative(name: str, value: Any) -> float:
    """``value`` as a float, raising ``ValueError`` unless it is a finite number >= 0."""
    number = _number(name, value, "a finite number >= 0")
    if not (number >= 0 and math.isfinite(number)):
        raise ValueError(f"{name}: expected a finite number >= 0, got {brief(number)}")
    return number


def check_finite_array(
    name: str, value: Any, shape: str, accept: Callable[[tuple[int, ...]], bool] | None = None
) -> np.ndarray:
    """``value`` as a float array, raising ``ValueError`` unless ``accept`` takes its shape and it is finite.

    Parameters
    ----------
    name : str
        The argument's name, first in the message.
    value : array_like
        The array (already converted or not).
    shape : str
        The expected shape as it appears in the message, e.g. ``"(..., N, 2) with N >= 1"``.
    accept : callable, optional
        ``shape -> bool``: whether the array's shape is the expected one (any shape when omitted).

    Returns
    -------
    ndarray
    """
    array = np.asarray(value, dtype=float)
    if accept is not None and not accept(array.shape):
        raise ValueError(f"{name}: expected an array of shape {shape}, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        bad = int(array.size - np.count_nonzero(np.isfinite(array)))
        raise ValueError(f"{name}: expected finite numbers, got {bad} non-finite of {array.size}")
    return array
