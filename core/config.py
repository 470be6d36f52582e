"""Validated configuration files: strict pydantic models, matrix types, and one-line error reports.

Every YAML file the toolkit reads (problems, formations, scenarios, sweeps) is parsed with
:func:`load_config` into a subclass of :class:`StrictModel`. Any failure — missing file, YAML syntax,
unknown key, wrong shape, non-finite number — raises :class:`ConfigError`, whose message is ONE line
naming the file, the key path (``sensors[0].p0``), what was expected and what was found. The CLI turns
it into exit status 2 without a traceback.
"""

from __future__ import annotations

import difflib
import math
from pathlib import Path
from typing import Annotated, Any, TypeVar

import numpy as np
import yaml
from pydantic import AfterValidator, BaseModel, ConfigDict, ValidationError

__all__ = [
    "ConfigError",
    "InvalidValue",
    "StrictModel",
    "FiniteFloat",
    "PositiveFloat",
    "NonNegativeFloat",
    "Vector2",
    "Matrix",
    "check_square",
    "check_shape",
    "check_spd",
    "check_psd",
    "format_location",
    "load_config",
    "parse_config",
]


class ConfigError(ValueError):
    """A configuration file (or dict) is invalid; ``str(err)`` is a one-line user-facing message."""


class InvalidValue(ValueError):
    """Raised by cross-field validators: ``path`` is relative to the model raising it (``"Sigma0"``)."""

    def __init__(self, path: str, message: str) -> None:
        super().__init__(f"{path}: {message}")
        self.path = path
        self.message = message


class StrictModel(BaseModel):
    """Base of every configuration model: unknown keys are rejected, values validated on assignment."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True, frozen=False)


def _finite(value: float) -> float:
    if not math.isfinite(value):
        raise ValueError(f"expected a finite number, got {value!r}")
    return float(value)


def _positive(value: float) -> float:
    if not value > 0:
        raise ValueError(f"expected a number > 0, got {value!r}")
    return value


def _non_negative(value: float) -> float:
    if not value >= 0:
        raise ValueError(f"expected a number >= 0, got {value!r}")
    return value


def _matrix(value: list[list[float]]) -> list[list[float]]:
    if len(value) == 0 or any(len(row) != len(value[0]) for row in value) or len(value[0]) == 0:
        raise ValueError(f"expected a non-empty rectangular matrix (list of equal-length rows), got {value!r}")
    return value


def _vector2(value: list[float]) -> list[float]:
    if len(value) != 2:
        raise ValueError(f"expected a planar vector of length 2, got length {len(value)}: {value!r}")
    return value


FiniteFloat = Annotated[float, AfterValidator(_finite)]
PositiveFloat = Annotated[float, AfterValidator(_finite), AfterValidator(_positive)]
NonNegativeFloat = Annotated[float, AfterValidator(_finite), AfterValidator(_non_negative)]
Vector2 = Annotated[list[FiniteFloat], AfterValidator(_vector2)]
Matrix = Annotated[list[list[FiniteFloat]], AfterValidator(_matrix)]


def check_shape(name: str, value: list[list[float]], shape: tuple[int, int]) -> np.ndarray:
    """Return ``value`` as an array, raising ``ValueError`` unless its shape is ``shape``."""
    arr = np.asarray(value, dtype=float)
    if arr.shape != shape:
        raise InvalidValue(name, f"expected shape {shape[0]}x{shape[1]}, got {arr.shape[0]}x{arr.shape[1]}")
    return arr


def check_square(name: str, value: list[list[float]]) -> np.ndarray:
    """Return ``value`` as an array, raising ``ValueError`` unless it is square."""
    arr = np.asarray(value, dtype=float)
    if arr.shape[0] != arr.shape[1]:
        raise InvalidValue(name, f"expected a square matrix, got {arr.shape[0]}x{arr.shape[1]}")
    return arr


def _check_symmetric(name: str, arr: np.ndarray) -> None:
    if not np.allclose(arr, arr.T, rtol=1e-12, atol=1e-12 * max(1.0, float(np.abs(arr).max()))):
        raise InvalidValue(name, f"expected a symmetric matrix, got {arr.tolist()}")


def check_spd(name: str, arr: np.ndarray) -> np.ndarray:
    """Raise ``ValueError`` unless ``arr`` is symmetric positive definite."""
    _check_symmetric(name, arr)
    lam_min = float(np.linalg.eigvalsh(arr).min())
    if lam_min <= 0:
        raise InvalidValue(name, f"expected a symmetric positive definite matrix, smallest eigenvalue {lam_min:g}")
    return arr


def check_psd(name: str, arr: np.ndarray) -> np.ndarray:
    """Raise ``ValueError`` unless ``arr`` is symmetric positive semidefinite."""
    _check_symmetric(name, arr)
    lam_min = float(np.linalg.eigvalsh(arr).min())
    if lam_min < -1e-12 * max(1.0, float(np.abs(arr).max())):
        raise InvalidValue(name, f"expected a symmetric positive semidefinite matrix, smallest eigenvalue {lam_min:g}")
    return arr


def format_location(loc: tuple[Any, ...]) -> str:
    """Format a pydantic error location as a key path: ``('sensors', 0, 'p0')`` -> ``sensors[0].p0``."""
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif isinstance(part, str) and part.startswith(("function-", "tagged-union")):
            continue  # pydantic-internal validator names, not keys
        else:
            out += f".{part}" if out else str(part)
    return out or "(top level)"


def _model_at(model: type[BaseModel], loc: tuple[Any, ...]) -> type[BaseModel] | None:
    """Walk the model tree along ``loc`` (all but the last item) to find the model owning that key."""
    current: Any = model
    for part in loc[:-1]:
        if isinstance(part, int):
            continue
        if not (isinstance(current, type) and issubclass(current, BaseModel)) or part not in current.model_fields:
            return None
        annotation = current.model_fields[part].annotation
        current = _innermost_model(annotation)
    return current if isinstance(current, type) and issubclass(current, BaseModel) else None


def _innermost_model(annotation: Any) -> Any:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in getattr(annotation, "__args__", ()) or ():
        found = _innermost_model(arg)
        if found is not None:
            return found
    return None


def _describe(error: dict[str, Any], model: type[BaseModel]) -> str:
    loc = tuple(error["loc"])
    path = format_location(loc)
    kind = error["type"]
    if kind == "extra_forbidden":
        owner = _model_at(model, loc)
        allowed = sorted(owner.model_fields) if owner is not None else []
        key = str(loc[-1])
        hint = difflib.get_close_matches(key, allowed, n=1)
        suggestion = f"; did you mean '{hint[0]}'?" if hint else ""
        listing = f" (allowed keys: {', '.join(allowed)})" if allowed else ""
        return f"{path}: unknown key{suggestion}{listing}"
    if kind == "missing":
        return f"{path}: required key is missing"
    cause = (error.get("ctx") or {}).get("error")
    if isinstance(cause, InvalidValue):
        prefix = format_location(loc) if loc else ""
        return f"{prefix + '.' if prefix else ''}{cause.path}: {cause.message}"
    message = error["msg"]
    for prefix in ("Value error, ", "Assertion failed, "):
        if message.startswith(prefix):
            message = message[len(prefix) :]
    if message.startswith("Input should be "):
        message = "expected " + message[len("Input should be ") :]
    got = error.get("input")
    got_text = "" if kind.startswith("value_error") or isinstance(got, dict) else f" (got {got!r})"
    return f"{path}: {message}{got_text}"


T = TypeVar("T", bound=BaseModel)


def parse_config(data: Any, model: type[T], source: str = "<dict>") -> T:
    """Validate ``data`` (a parsed YAML document) against ``model``; raise :class:`ConfigError` on failure."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: (top level): expected a mapping of keys, got {type(data).__name__}")
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        errors = exc.errors()
        first = _describe(errors[0], model)
        more = f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''})" if len(errors) > 1 else ""
        raise ConfigError(f"{source}: {first}{more}") from None


def read_yaml(path: str | Path) -> Any:
    """Read a YAML file, raising :class:`ConfigError` (file, line, column) on any failure."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read file ({exc.strerror})") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise ConfigError(f"{path}:{where}: invalid YAML: {problem}") from None


def load_config(path: str | Path, model: type[T]) -> T:
    """Read and validate a YAML configuration file.

    Parameters
    ----------
    path : str or Path
        The YAML file.
    model : type
        A :class:`StrictModel` subclass describing the file.

    Returns
    -------
    model instance

    Raises
    ------
    ConfigError
        One-line message ``FILE: key.path: what was expected (got …)``.
    """
    return parse_config(read_yaml(path), model, source=str(path))
