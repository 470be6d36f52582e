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

from ...core.registry import Lazy, Registry

__all__ = ["Field", "FIELDS", "register_field", "make_field", "level_curve_frame"]


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


#: field kind -> Field subclass; the built-in kinds are imported when first looked up (``make_field("quadratic")``
#: works in a fresh interpreter), fields of other packages are added by :func:`register_field`
FIELDS: Registry[type[Field]] = Registry(
    "field kind",
    {
        "quadratic": Lazy("mobisense.estimation.fields.library:QuadraticField"),
        "two_charges": Lazy("mobisense.estimation.fields.library:TwoChargesField"),
        "ocean_temperature": Lazy("mobisense.estimation.fields.library:OceanTemperatureField"),
        "advection_diffusion": Lazy("mobisense.estimation.fields.advection_diffusion:AdvectionDiffusionField"),
        "gridded": Lazy("mobisense.estimation.fields.gridded:GriddedField"),
    },
)


def register_field(cls: type[Field]) -> type[Field]:
    """Class decorator adding a :class:`Field` subclass to :data:`FIELDS` under ``cls.kind``."""
    if not cls.kind:
        raise TypeError(f"{cls.__name__} needs a non-empty 'kind' to be registered")
    return FIELDS.register(cls.kind, cls)


def make_field(kind: str, **params: Any) -> Field:
    """Instantiate the registered field ``kind`` with keyword parameters."""
    if kind not in FIELDS:
        raise ValueError(FIELDS.unknown(kind))
    return FIELDS[kind](**params)


def level_curve_frame(gradient: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The frame of the level curve through a point, from the field's gradient there.

    Parameters
    ----------
    gradient : ndarray, shape (..., 2)
        ∇z at the point (field unit per length unit); must be non-zero.

    Returns
    -------
    x1 : ndarray, shape (..., 2)
        Unit tangent of the level curve, oriented so that ``x1 × y1`` points out of the page.
    y1 : ndarray, shape (..., 2)
        Unit normal ``∇z/‖∇z‖``.
    norm : ndarray, shape (...)
        ``‖∇z‖``.
    """
    norm = np.linalg.norm(gradient, axis=-1)
    y1 = gradient / norm[..., None]
    x1 = np.stack([y1[..., 1], -y1[..., 0]], axis=-1)
    return x1, y1, norm
