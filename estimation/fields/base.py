"""Scalar fields z(r, t) with exact value, gradient and Hessian, and a registry mapping names to them.

Shapes: positions ``r`` have shape ``(..., 2)`` (km or m, as the field documents); ``value`` returns
``(...)``, ``gradient`` ``(..., 2)`` and ``hessian`` ``(..., 2, 2)``. Time ``t`` (s) is ignored by static
fields. A new field subclasses :class:`Field` and is registered with :func:`register_field`, so
scenario files can name it (``field: {kind: two_charges, ...}``).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np

__all__ = ["Field", "FIELDS", "register_field", "make_field"]


class Field(ABC):
    """A smooth scalar field with exact derivatives (the contract every field implements)."""

    #: registry key used in configuration files
    kind: str = ""

    @abstractmethod
    def value(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Field value z(r, t), shape ``r.shape[:-1]``."""

    @abstractmethod
    def gradient(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Gradient ∇z(r, t), shape ``r.shape``."""

    @abstractmethod
    def hessian(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Hessian ∇²z(r, t), shape ``r.shape + (2,)``."""


#: field kind -> Field subclass
FIELDS: dict[str, type[Field]] = {}


def register_field(cls: type[Field]) -> type[Field]:
    """Class decorator adding a :class:`Field` subclass to :data:`FIELDS` under ``cls.kind``."""
    if not cls.kind:
        raise TypeError(f"{cls.__name__} needs a non-empty 'kind' to be registered")
    FIELDS[cls.kind] = cls
    return cls


def make_field(kind: str, **params: Any) -> Field:
    """Instantiate the registered field ``kind`` with keyword parameters."""
    try:
        cls = FIELDS[kind]
    except KeyError:
        raise ValueError(f"unknown field kind {kind!r}; expected one of {sorted(FIELDS)}") from None
    return cls(**params)
