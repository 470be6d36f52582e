"""Concrete smooth fields (docs/theory/cooperative.md §6) and their YAML form.

Each is registered in :data:`mobisense.estimation.fields.base.FIELDS`:

* ``quadratic`` — ``z = z0 + g'(r − r0) + ½ (r − r0)' H (r − r0)``, the analytic test case;
* ``two_charges`` — potential of two identical positive point charges (Zhang & Leonard (2010), §VII, Fig. 3);
* ``ocean_temperature`` — synthetic ocean-like temperature (°C over km): a meandering front, warm and
  cold eddies and a gentle meridional gradient, with the 13 °C isotherm crossing the domain
  (Zhang & Leonard (2010), §VII, Figs. 4-6, whose Monterey Bay snapshot is not public);
* ``gridded`` — a field read from a netCDF file (:mod:`mobisense.estimation.fields.gridded`);
* ``advection_diffusion`` — docs/theory/distributed.md §1, registered by
  :mod:`mobisense.estimation.fields.advection_diffusion` when present.

Derivatives are written by hand and tested against finite differences (``tests/test_estimation_fields.py``).
In YAML a field is a flat mapping ``{kind: ocean_temperature, front_width: 5.0}`` validated by
:class:`FieldSpec` (unknown parameter names are reported with a suggestion).
"""

from __future__ import annotations

import difflib
import importlib
import inspect
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ConfigDict, PrivateAttr, ValidationInfo, model_validator

from ...core.config import MAX_MAGNITUDE, InvalidValue, StrictModel, number_error
from ...core.errors import brief
from .base import FIELDS, Field, make_field, register_field

__all__ = ["QuadraticField", "TwoChargesField", "OceanTemperatureField", "FieldSpec", "grid_dataset", "load_fields"]


def _points(r: np.ndarray) -> np.ndarray:
    r = np.asarray(r, dtype=float)
    if r.shape[-1:] != (2,):
        raise ValueError(f"positions r: expected shape (..., 2), got {r.shape}")
    return r


@register_field
class QuadraticField(Field):
    """``z(r) = z0 + g'(r − r0) + ½ (r − r0)' H (r − r0)``: exact second-order Taylor model.

    Parameters
    ----------
    hessian : array_like, shape (2, 2)
        Symmetric ``H`` (field unit / L²).
    gradient : array_like, shape (2,)
        ``∇z(r0)`` (field unit / L).
    value : float
        ``z(r0)``.
    center : array_like, shape (2,)
        ``r0`` (L).
    """

    kind = "quadratic"

    def __init__(
        self,
        hessian: Sequence[Sequence[float]] = ((1.0, 0.0), (0.0, 1.0)),
        gradient: Sequence[float] = (0.0, 0.0),
        value: float = 0.0,
        center: Sequence[float] = (0.0, 0.0),
    ) -> None:
        self.H = np.asarray(hessian, dtype=float)
        self.g = np.asarray(gradient, dtype=float)
        self.z0 = float(value)
        self.r0 = np.asarray(center, dtype=float)
        if self.H.shape != (2, 2) or not np.allclose(self.H, self.H.T):
            raise ValueError(f"hessian: expected a symmetric 2x2 matrix, got {self.H.tolist()}")
        if self.g.shape != (2,) or self.r0.shape != (2,):
            raise ValueError(f"gradient, center: expected length-2 vectors, got {self.g.shape}, {self.r0.shape}")

    def value(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Field value, shape ``r.shape[:-1]``."""
        d = _points(r) - self.r0
        return self.z0 + d @ self.g + 0.5 * np.einsum("...i,ij,...j->...", d, self.H, d)

    def gradient(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Gradient ``g + H (r − r0)``, shape ``r.shape``."""
        return self.g + (_points(r) - self.r0) @ self.H.T

    def hessian(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Constant Hessian, shape ``r.shape + (2,)``."""
        return np.broadcast_to(self.H, _points(r).shape + (2,)).copy()


@register_field
class TwoChargesField(Field):
    """Potential of identical point charges: ``z = q Σ_j (‖r − c_j‖² + ε²)^(−1/2)`` (Zhang & Leonard (2010), §VII).

    Parameters
    ----------
    charges : array_like, shape (M, 2)
        Charge positions (L); two by default, at (±3, 0).
    strength : float
        ``q`` (field unit · L).
    softening : float
        Plummer length ``ε`` (L) removing the singularity at the charges (0 = exact Coulomb potential,
        smooth everywhere except at the charges).
    """

    kind = "two_charges"

    def __init__(
        self,
        charges: Sequence[Sequence[float]] = ((-3.0, 0.0), (3.0, 0.0)),
        strength: float = 10.0,
        softening: float = 0.0,
    ) -> None:
        self.charges = np.asarray(charges, dtype=float)
        if self.charges.ndim != 2 or self.charges.shape[1] != 2:
            raise ValueError(f"charges: expected a list of [x, y] positions, got {self.charges.tolist()}")
        if not strength > 0 or not softening >= 0:
            raise ValueError(f"strength must be > 0 and softening >= 0, got {strength}, {softening}")
        self.q, self.eps2 = float(strength), float(softening) ** 2

    def _parts(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = _points(r)[..., None, :] - self.charges  # (..., M, 2)
        inv_rho = 1.0 / np.sqrt(np.sum(d**2, axis=-1) + self.eps2)  # (..., M)
        return d, inv_rho

    def value(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Potential, shape ``r.shape[:-1]``."""
        return self.q * np.sum(self._parts(r)[1], axis=-1)

    def gradient(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """``−q Σ d_j / ρ_j³``, shape ``r.shape``."""
        d, inv_rho = self._parts(r)
        return -self.q * np.sum(d * inv_rho[..., None] ** 3, axis=-2)

    def hessian(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """``q Σ (3 d d' / ρ⁵ − I / ρ³)``, shape ``r.shape + (2,)``."""
        d, inv_rho = self._parts(r)
        outer = d[..., :, None] * d[..., None, :]
        terms = 3.0 * outer * inv_rho[..., None, None] ** 5 - np.eye(2) * inv_rho[..., None, None] ** 3
        return self.q * np.sum(terms, axis=-3)


#: default eddies of the synthetic ocean field: (x km, y km, amplitude °C, radius km)
DEFAULT_EDDIES: tuple[tuple[float, float, float, float], ...] = (
    (20.0, 44.0, 1.2, 6.0),  # warm-core eddy north of the front
    (55.0, 16.0, -1.0, 7.0),  # cold-core eddy south of the front
    (68.0, 40.0, 0.6, 4.0),  # small warm eddy
)


@register_field
class OceanTemperatureField(Field):
    """Synthetic ocean temperature (°C) over a km domain: a meandering front plus eddies.

    ``T(x, y) = T0 + ½ΔT tanh((y_f(x) − y)/w) − γ (y − y0) + Σ_e A_e exp(−‖r − c_e‖² / (2 R_e²))`` with
    the front ``y_f(x) = y0 + A sin(2π x/λ + φ)``: warm water south of the front, cold north. With the
    defaults the 13 °C isotherm follows the front across the whole ``[0, 80] × [0, 60]`` km domain.

    Parameters
    ----------
    mean_temperature : float
        ``T0`` (°C), the temperature on the front.
    front_contrast : float
        ``ΔT`` (°C) across the front.
    front_width : float
        ``w`` (km).
    front_latitude : float
        ``y0`` (km).
    meander_amplitude, meander_wavelength, meander_phase : float
        ``A`` (km), ``λ`` (km), ``φ`` (rad).
    background_gradient : float
        ``γ`` (°C/km), cooling northward.
    eddies : sequence of (x, y, amplitude, radius)
        Gaussian eddies (km, km, °C, km).
    """

    kind = "ocean_temperature"

    def __init__(
        self,
        mean_temperature: float = 13.0,
        front_contrast: float = 3.0,
        front_width: float = 6.0,
        front_latitude: float = 30.0,
        meander_amplitude: float = 8.0,
        meander_wavelength: float = 50.0,
        meander_phase: float = 0.0,
        background_gradient: float = 0.02,
        eddies: Sequence[Sequence[float]] = DEFAULT_EDDIES,
    ) -> None:
        if not (front_width > 0 and meander_wavelength > 0):
            raise ValueError(f"front_width and meander_wavelength must be > 0, got {front_width}, {meander_wavelength}")
        self.T0, self.dT, self.w, self.y0 = mean_temperature, front_contrast, front_width, front_latitude
        self.A, self.k, self.phase = meander_amplitude, 2 * np.pi / meander_wavelength, meander_phase
        self.gamma = background_gradient
        self.eddies = np.asarray(eddies, dtype=float).reshape(-1, 4)
        if np.any(self.eddies[:, 3] <= 0):
            raise ValueError(f"eddies: radii must be > 0, got {self.eddies[:, 3].tolist()}")

    def _front(self, r: np.ndarray) -> tuple[np.ndarray, ...]:
        """``t = tanh ξ``, ``ξ_x``, ``ξ_xx`` with ``ξ = (y_f(x) − y)/w`` (``ξ_y = −1/w``)."""
        x, y = r[..., 0], r[..., 1]
        arg = self.k * x + self.phase
        xi = (self.y0 + self.A * np.sin(arg) - y) / self.w
        xi_x = self.A * self.k * np.cos(arg) / self.w
        xi_xx = -self.A * self.k**2 * np.sin(arg) / self.w
        return np.tanh(xi), xi_x, xi_xx

    def _eddies(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per-eddy offsets ``d`` (..., E, 2), values ``G`` (..., E) and ``1/R²`` (E,)."""
        d = r[..., None, :] - self.eddies[:, :2]
        inv_R2 = 1.0 / self.eddies[:, 3] ** 2
        G = self.eddies[:, 2] * np.exp(-0.5 * np.sum(d**2, axis=-1) * inv_R2)
        return d, G, inv_R2

    def value(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Temperature (°C), shape ``r.shape[:-1]``."""
        r = _points(r)
        tanh_xi = self._front(r)[0]
        _, G, _ = self._eddies(r)
        return self.T0 + 0.5 * self.dT * tanh_xi - self.gamma * (r[..., 1] - self.y0) + G.sum(axis=-1)

    def gradient(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Gradient (°C/km), shape ``r.shape``."""
        r = _points(r)
        tanh_xi, xi_x, _ = self._front(r)
        c = 0.5 * self.dT * (1.0 - tanh_xi**2)  # ½ΔT tanh'(ξ)
        front = np.stack([c * xi_x, -c / self.w - self.gamma], axis=-1)
        d, G, inv_R2 = self._eddies(r)
        return front - np.sum((G * inv_R2)[..., None] * d, axis=-2)

    def hessian(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Hessian (°C/km²), shape ``r.shape + (2,)``."""
        r = _points(r)
        tanh_xi, xi_x, xi_xx = self._front(r)
        sech2 = 1.0 - tanh_xi**2
        c1 = 0.5 * self.dT * sech2  # ½ΔT tanh'
        c2 = -self.dT * tanh_xi * sech2  # ½ΔT tanh'' = −ΔT tanh sech²
        xi_y = -1.0 / self.w
        H = np.empty(r.shape + (2,))
        H[..., 0, 0] = c2 * xi_x**2 + c1 * xi_xx
        H[..., 0, 1] = H[..., 1, 0] = c2 * xi_x * xi_y
        H[..., 1, 1] = c2 * xi_y**2
        d, G, inv_R2 = self._eddies(r)
        outer = d[..., :, None] * d[..., None, :] * inv_R2[:, None, None] ** 2 - np.eye(2) * inv_R2[:, None, None]
        return H + np.sum(G[..., None, None] * outer, axis=-3)


def load_fields() -> dict[str, type[Field]]:
    """Import every module that registers fields (optional ones only if present); return :data:`FIELDS`."""
    for module in ("mobisense.estimation.fields.gridded", "mobisense.estimation.fields.advection_diffusion"):
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as err:
            if err.name != module:
                raise
    return FIELDS


def _bad_number(value: Any, path: str, numeric: bool) -> tuple[str, str] | None:
    """The key path and the error of the first number in a nested parameter value that a file may not hold.

    Every number follows the rule of every file (:func:`mobisense.core.config.number_error`: finite, a magnitude
    in [1e-100, 1e100] or 0); with ``numeric`` (a parameter annotated as numbers) every leaf must be a number,
    not a boolean or a string. None if the value is acceptable.
    """
    if isinstance(value, (list, tuple)):
        for i, item in enumerate(value):
            found = _bad_number(item, f"{path}[{i}]", numeric)
            if found is not None:
                return found
        return None
    if isinstance(value, dict):
        for key, item in value.items():
            found = _bad_number(item, f"{path}.{key}", False)
            if found is not None:
                return found
        return None
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        try:
            error = number_error(float(value))
        except OverflowError:  # an integer beyond any double
            digits = len(str(abs(value)))
            error = f"expected a magnitude of at most {MAX_MAGNITUDE:g}, got an integer of {digits} digits"
        return None if error is None else (path, error)
    if numeric:
        return path, f"expected a number, got {brief(value)}"
    return None


#: a constructor annotation that holds only numbers: float, int, Sequence[float], Sequence[Sequence[float]], …
_NUMERIC = re.compile(r"^(Sequence\[)*(float|int)\]*$")


def _numeric(annotation: Any) -> bool:
    """Whether a field constructor's parameter annotation (a string, or a type) asks for numbers only."""
    text = annotation if isinstance(annotation, str) else getattr(annotation, "__name__", "")
    return bool(_NUMERIC.match(text.replace(" ", "").replace("typing.", "").replace("collections.abc.", "")))


def _scenario_folder(info: ValidationInfo) -> Path | None:
    """The folder of the file being validated: ``context={"source": FILE}`` of ``model_validate``, if a file."""
    context = info.context if isinstance(info.context, dict) else {}
    source = context.get("source")
    try:
        if isinstance(source, (str, Path)) and str(source) and Path(source).is_file():
            return Path(source).parent
    except (OSError, ValueError):  # a name too long, a NUL character: not a file
        pass
    return None


class FieldSpec(StrictModel):
    """A field in a YAML file: ``{kind: NAME, <constructor parameters>…}``, validated by constructing it.

    Parameters naming files (``path`` of a ``gridded`` field, listed in the field class's ``file_parameters``)
    are relative to the folder of the file being validated, named by the validation context
    (``model_validate(data, context={"source": FILE})``); without a source file they are relative to the
    working directory. Absolute paths are used as they are. An error of a parameter is reported at its key
    (``field.path: …``).
    """

    model_config = ConfigDict(extra="allow")

    kind: str
    _field: Field | None = PrivateAttr(default=None)

    @model_validator(mode="after")
    def _build(self, info: ValidationInfo) -> FieldSpec:
        kinds = load_fields()
        if self.kind not in kinds:
            hint = difflib.get_close_matches(self.kind, list(kinds), n=1)
            raise InvalidValue(
                "kind",
                f"unknown field kind {self.kind!r}{f'; did you mean {hint[0]!r}?' if hint else ''} "
                f"(expected one of {', '.join(sorted(kinds))})",
            )
        signature = inspect.signature(kinds[self.kind].__init__).parameters
        allowed = [p for p in signature if p != "self"]
        for key in self.parameters():
            if key not in allowed:
                hint = difflib.get_close_matches(key, allowed, n=1)
                raise InvalidValue(
                    key,
                    f"unknown parameter of field {self.kind!r}{f'; did you mean {hint[0]!r}?' if hint else ''} "
                    f"(allowed: {', '.join(allowed)})",
                )
        parameters = self.parameters()
        for key, value in parameters.items():  # NaN, ±inf, 1e200 in a field's numbers: refused, as everywhere else
            found = _bad_number(value, key, False)
            if found is not None:
                raise InvalidValue(*found)
        folder = _scenario_folder(info)
        for key in getattr(kinds[self.kind], "file_parameters", ()):
            value = parameters.get(key)
            if isinstance(value, str) and value and not Path(value).is_absolute():
                parameters[key] = str(folder / value) if folder is not None else value
        try:
            self._field = make_field(self.kind, **parameters)
        except (TypeError, ValueError) as err:
            message = str(err)
            key, _, rest = message.partition(": ")
            if rest and re.split(r"[.\[]", key, maxsplit=1)[0] in allowed:  # "degree: expected …" → field.degree
                raise InvalidValue(key, rest) from None
            raise InvalidValue(self.kind, message) from None
        for key, value in parameters.items():  # a boolean or string the constructor turned into a number silently
            found = _bad_number(value, key, True) if _numeric(signature[key].annotation) else None
            if found is not None:
                raise InvalidValue(*found)
        return self

    def parameters(self) -> dict[str, Any]:
        """The constructor parameters (every key but ``kind``)."""
        return dict(self.model_extra or {})

    def build(self) -> Field:
        """The validated :class:`Field` instance."""
        return self._field  # type: ignore[return-value]  # always set by the validator


def grid_dataset(field: Field, x: np.ndarray, y: np.ndarray, t: float = 0.0, name: str = "z", units: str = "") -> Any:
    """Sample ``field`` on the grid ``x × y`` as an ``xarray.Dataset`` with variable ``name(y, x)``.

    The result can be written with :func:`mobisense.core.files.write_netcdf` and read back as a ``gridded`` field.
    """
    import xarray as xr

    X, Y = np.meshgrid(np.asarray(x, float), np.asarray(y, float))
    values = field.value(np.stack([X, Y], axis=-1), t)
    ds = xr.Dataset({name: (("y", "x"), values)}, coords={"x": np.asarray(x, float), "y": np.asarray(y, float)})
    ds[name].attrs.update({"units": units, "source_field": field.kind or type(field).__name__})
    return ds
