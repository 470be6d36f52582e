"""Validated configuration files: strict pydantic models, matrix types, and one-line error reports.

Every YAML file the toolkit reads (problems, formations, scenarios, sweeps) is read by
:func:`mobisense.core.reader.read_document` (size, encoding, nesting, alias and duplicate-key limits) and
validated with :func:`load_config` into a subclass of :class:`StrictModel`. Models are *strict*: a boolean
is not a number, ``"0.1"`` is not a number, ``1.0`` is not an integer. Every number is finite and, unless
it is 0, between :data:`MIN_MAGNITUDE` and :data:`MAX_MAGNITUDE` in magnitude, so that the products the
solvers form (Σ S Σ, B Q B', scales) cannot overflow or underflow. Any failure — missing file, YAML syntax,
unknown key, wrong shape, non-finite number — raises :class:`ConfigError`, whose message is ONE line
naming the file, the key path (``sensors[0].p0``), what was expected and what was found (at most ~80
characters of it). The CLI turns it into exit status 2 without a traceback.
"""

from __future__ import annotations

import difflib
import functools
import math
import types
import typing
from pathlib import Path
from typing import Annotated, Any, TypeVar

import numpy as np
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError

from .errors import ConfigError, brief
from .plain_data import plain_data
from .reader import read_document

__all__ = [
    "ConfigError",
    "InvalidValue",
    "StrictModel",
    "FiniteFloat",
    "number_error",
    "PositiveFloat",
    "NonNegativeFloat",
    "Vector2",
    "Matrix",
    "Seed",
    "MAX_MAGNITUDE",
    "MIN_MAGNITUDE",
    "check_square",
    "check_shape",
    "check_spd",
    "check_psd",
    "format_location",
    "load_config",
    "parse_config",
    "read_yaml",
]

#: largest magnitude of any number in a file: cubes of it stay finite (1e300 < 1.8e308)
MAX_MAGNITUDE = 1e100
#: smallest magnitude of a nonzero number: cubes of it stay normal doubles (1e-300 > 2.2e-308)
MIN_MAGNITUDE = 1e-100


class InvalidValue(ValueError):
    """Raised by cross-field validators: ``path`` is relative to the model raising it (``"Sigma0"``)."""

    def __init__(self, path: str, message: str) -> None:
        super().__init__(f"{path}: {message}")
        self.path = path
        self.message = message


class StrictModel(BaseModel):
    """Base of every configuration model: unknown keys rejected, strict types, validated on assignment."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True, frozen=False, strict=True)


def number_error(value: float) -> str | None:
    """Why ``value`` cannot be a number of a file (not finite, or a magnitude outside the bounds), or None if it can.

    The rule of every number read from a file: finite, and 0 or of a magnitude in
    [:data:`MIN_MAGNITUDE`, :data:`MAX_MAGNITUDE`].
    """
    if not math.isfinite(value):
        return f"expected a finite number, got {brief(value)}"
    if value != 0 and not MIN_MAGNITUDE <= abs(value) <= MAX_MAGNITUDE:
        return (
            f"expected a magnitude in [{MIN_MAGNITUDE:g}, {MAX_MAGNITUDE:g}] (or 0 where allowed), got {value:g} "
            "(products of such numbers overflow or underflow; change the units)"
        )
    return None


def _finite(value: float) -> float:
    error = number_error(value)
    if error is not None:
        raise ValueError(error)
    return float(value)


def _positive(value: float) -> float:
    if not value > 0:
        raise ValueError(f"expected a number > 0, got {brief(value)}")
    return value


def _non_negative(value: float) -> float:
    if not value >= 0:
        raise ValueError(f"expected a number >= 0, got {brief(value)}")
    return value


def _matrix(value: list[list[float]]) -> list[list[float]]:
    if len(value) == 0 or any(len(row) != len(value[0]) for row in value) or len(value[0]) == 0:
        raise ValueError(f"expected a non-empty rectangular matrix (list of equal-length rows), got {brief(value)}")
    return value


def _vector2(value: list[float]) -> list[float]:
    if len(value) != 2:
        raise ValueError(f"expected a planar vector of length 2, got length {len(value)}: {brief(value)}")
    return value


FiniteFloat = Annotated[float, AfterValidator(_finite)]
PositiveFloat = Annotated[float, AfterValidator(_finite), AfterValidator(_positive)]
NonNegativeFloat = Annotated[float, AfterValidator(_finite), AfterValidator(_non_negative)]
Vector2 = Annotated[list[FiniteFloat], AfterValidator(_vector2)]
Matrix = Annotated[list[list[FiniteFloat]], AfterValidator(_matrix)]
#: a random seed: what ``numpy.random.default_rng`` accepts (0 … 2⁶³ − 1)
Seed = Annotated[int, Field(ge=0, le=2**63 - 1)]


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


def _symmetric(arr: np.ndarray) -> bool:
    # np.allclose(arr, arr.T, rtol=1e-12, atol=…) spelt out (equal infinities count as close, NaN never does):
    # the same test at a tenth of its cost, which every task of a sweep pays for each of its matrices
    atol = 1e-12 * max(1.0, float(np.abs(arr).max()))
    with np.errstate(invalid="ignore", over="ignore"):
        within = np.abs(arr - arr.T) <= atol + 1e-12 * np.abs(arr.T)
    finite = np.isfinite(arr) & np.isfinite(arr.T)
    return bool(np.all(np.where(finite, within, arr == arr.T)))


#: matrices of at most this many entries have their spectrum facts cached (a sweep's tasks repeat the base
#: problem's M, K, Q and Σ0: 4 checks of 21 µs each per task, a fifth of a task's validation, measured)
CACHED_MATRIX_ENTRIES = 4096


@functools.lru_cache(maxsize=256)
def _cached_facts(shape: tuple[int, ...], data: bytes) -> tuple[bool, float, float]:
    return _facts(np.frombuffer(data).reshape(shape))


def _facts(arr: np.ndarray) -> tuple[bool, float, float]:
    """(symmetric within round-off, smallest eigenvalue, largest magnitude) of a square float matrix."""
    if not _symmetric(arr):
        return False, math.nan, math.nan
    return True, float(np.linalg.eigvalsh(arr).min()), float(np.abs(arr).max())


def _spectrum(name: str, arr: np.ndarray) -> tuple[float, float]:
    """The smallest eigenvalue and largest magnitude of the symmetric ``arr`` (``InvalidValue`` if not symmetric)."""
    if arr.size <= CACHED_MATRIX_ENTRIES:
        symmetric, lam_min, largest = _cached_facts(arr.shape, np.ascontiguousarray(arr, dtype=float).tobytes())
    else:
        symmetric, lam_min, largest = _facts(arr)
    if not symmetric:
        raise InvalidValue(name, f"expected a symmetric matrix, got {brief(arr.tolist())}")
    return lam_min, largest


def check_spd(name: str, arr: np.ndarray) -> np.ndarray:
    """Raise ``ValueError`` unless ``arr`` is symmetric positive definite."""
    lam_min, _ = _spectrum(name, arr)
    if lam_min <= 0:
        raise InvalidValue(name, f"expected a symmetric positive definite matrix, smallest eigenvalue {lam_min:g}")
    return arr


def check_psd(name: str, arr: np.ndarray) -> np.ndarray:
    """Raise ``ValueError`` unless ``arr`` is symmetric positive semidefinite."""
    lam_min, largest = _spectrum(name, arr)
    if lam_min < -1e-12 * max(1.0, largest):
        raise InvalidValue(name, f"expected a symmetric positive semidefinite matrix, smallest eigenvalue {lam_min:g}")
    return arr


_INTERNAL_LOC = ("function-", "tagged-union", "union[", "lax-or-strict", "json-or-python", "chain[", "nullable")


def _unwrap(annotation: Any) -> Any:
    """Strip ``Annotated`` and ``Optional`` from a field annotation."""
    while True:
        origin = typing.get_origin(annotation)
        if origin is Annotated:
            annotation = typing.get_args(annotation)[0]
        elif origin in (typing.Union, types.UnionType):
            members = [a for a in typing.get_args(annotation) if a is not type(None)]
            if len(members) != 1:
                return annotation
            annotation = members[0]
        else:
            return annotation


def _is_model(annotation: Any) -> bool:
    return isinstance(annotation, type) and issubclass(annotation, BaseModel)


def _union_member(annotation: Any, label: Any) -> Any:
    """The member of a union a pydantic location part (a discriminator tag or a type name) designates."""
    for member in typing.get_args(annotation):
        member = _unwrap(member)
        if not _is_model(member):
            continue
        if member.__name__ == label:
            return member
        for field in member.model_fields.values():
            if typing.get_origin(field.annotation) is typing.Literal and label in typing.get_args(field.annotation):
                return member
    return None


def _key_parts(loc: tuple[Any, ...], model: type[BaseModel] | None) -> list[Any]:
    """The user's keys in a pydantic location: union tags and validator names are dropped.

    ``('reference', 'constant', 'bearing')`` of a discriminated union is ``['reference', 'bearing']``.
    """
    parts: list[Any] = []
    current: Any = model
    for part in loc:
        current = _unwrap(current) if current is not None else None
        if isinstance(part, str) and part.startswith(_INTERNAL_LOC):
            continue
        origin = typing.get_origin(current)
        if origin in (typing.Union, types.UnionType):
            current = _union_member(current, part)  # the part names a member: not a key
            continue
        parts.append(part)
        if _is_model(current):
            field = current.model_fields.get(part) if isinstance(part, str) else None
            current = None if field is None else field.annotation
        elif origin in (list, tuple) and isinstance(part, int):
            current = (typing.get_args(current) or (None,))[0]
        elif origin is dict:
            current = (typing.get_args(current) or (None, None))[-1]
        else:
            current = None
    return parts


def format_location(loc: tuple[Any, ...], model: type[BaseModel] | None = None) -> str:
    """Format a pydantic error location as a key path: ``('sensors', 0, 'p0')`` -> ``sensors[0].p0``.

    With ``model`` (the validated model), union tags and member names pydantic inserts are dropped.
    """
    out = ""
    for part in _key_parts(tuple(loc), model):
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            name = str(part) if len(str(part)) <= 60 else f"{str(part)[:40]}…({len(str(part))} characters)"
            out += f".{name}" if out else name
    return out or "(top level)"


def _model_at(model: type[BaseModel], parts: list[Any]) -> type[BaseModel] | None:
    """Walk the model tree along the key ``parts`` (all but the last) to find the model owning that key."""
    current: Any = model
    for part in parts[:-1]:
        current = _unwrap(current)
        if isinstance(part, int):
            args = typing.get_args(current)
            current = _unwrap(args[0]) if args else current
            continue
        if not _is_model(current) or part not in current.model_fields:
            return None
        current = _innermost_model(current.model_fields[part].annotation)
    current = _unwrap(current)
    return current if _is_model(current) else None


def _innermost_model(annotation: Any) -> Any:
    if _is_model(annotation):
        return annotation
    for arg in typing.get_args(annotation) or ():
        found = _innermost_model(arg)
        if found is not None:
            return found
    return None


_KINDS = {bool: "a boolean", str: "a string", int: "an integer", float: "a number", list: "a list", dict: "a mapping"}


def _got(value: Any) -> str:
    kind = next((name for t, name in _KINDS.items() if type(value) is t), None)
    if value is None:
        return "got null"
    if isinstance(value, str):
        hint = " — remove the quotes" if _numeric(value) else ""
        return f"got the string {brief(value)}{hint}"
    return f"got {brief(value)}" + (f", {kind}" if kind in ("a boolean", "a list", "a mapping") else "")


def _numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _describe(error: dict[str, Any], model: type[BaseModel], suggestion_for: dict[tuple, str]) -> str:
    loc = tuple(error["loc"])
    parts = _key_parts(loc, model)
    path = format_location(loc, model)
    kind = error["type"]
    if kind == "extra_forbidden":
        owner = _model_at(model, parts)
        allowed = sorted(owner.model_fields) if owner is not None else []
        key = str(parts[-1]) if parts else str(loc[-1])
        hint = suggestion_for.get(tuple(parts)) or next(iter(difflib.get_close_matches(key, allowed, n=1)), None)
        suggestion = f"; did you mean '{hint}'?" if hint else ""
        listing = f" (allowed keys: {', '.join(allowed)})" if allowed and not hint else ""
        return f"{path}: unknown key{suggestion}{listing}"
    if kind == "missing":
        return f"{path}: required key is missing"
    cause = (error.get("ctx") or {}).get("error")
    if isinstance(cause, InvalidValue):
        prefix = path if parts else ""
        return f"{prefix + '.' if prefix else ''}{cause.path}: {cause.message}"
    message = str(error["msg"])
    for prefix in ("Value error, ", "Assertion failed, "):
        if message.startswith(prefix):
            message = message[len(prefix) :]
    if message.startswith("Input should be "):
        message = "expected " + message[len("Input should be ") :]
    if kind == "model_type":  # "a valid dictionary or instance of PathConstraints": the class is not the user's word
        message = "expected a mapping of keys to values"
    got = error.get("input")
    if kind in ("too_long", "too_short"):  # "List should have at most 2 items after validation, not 3"
        bound = (error.get("ctx") or {}).get("max_length" if kind == "too_long" else "min_length")
        if bound is not None and isinstance(got, (list, tuple, str, dict)):
            noun = "character" if isinstance(got, str) else "item"
            most = "at most" if kind == "too_long" else "at least"
            message = f"expected {most} {bound} {noun}{'s' if bound != 1 else ''}, not {len(got)}"
    if kind.startswith("value_error") or (isinstance(got, dict) and kind in ("model_type", "dict_type")):
        got_text = ""
    else:
        got_text = " (got a mapping)" if isinstance(got, dict) else f" ({_got(got)})"
    return f"{path}: {message}{got_text}"


def _alternatives(messages: list[str]) -> str:
    """One message from those of a union's branches at one key path.

    ``cost.M: expected a valid list (got the string 'median')`` and ``cost.M: expected 'mean', 'sum' or 'zero'
    (got …)`` become ``cost.M: expected a valid list, or 'mean', 'sum' or 'zero' (got the string 'median')``.
    """
    if len(messages) == 1:
        return messages[0]
    path, _, _ = messages[0].partition(": ")
    expected, got = [], ""
    for message in messages:
        body = message.partition(": ")[2]
        if " (got " in body and body.endswith(")"):
            body, got = body[: body.rindex(" (got ")], body[body.rindex(" (got ") :]
        body = body.removeprefix("expected ")
        if body not in expected:
            expected.append(body)
    return f"{path}: expected {', or '.join(expected)}{got}"


def _misspellings(errors: list[dict[str, Any]], model: type[BaseModel]) -> dict[tuple, str]:
    """Unknown keys that are a misspelling of a missing required key of the same mapping: key path -> that key."""
    missing: dict[tuple, list[str]] = {}
    for error in errors:
        if error["type"] == "missing":
            parts = _key_parts(tuple(error["loc"]), model)
            if parts and isinstance(parts[-1], str):
                missing.setdefault(tuple(parts[:-1]), []).append(parts[-1])
    found: dict[tuple, str] = {}
    for error in errors:
        if error["type"] == "extra_forbidden":
            parts = _key_parts(tuple(error["loc"]), model)
            candidates = missing.get(tuple(parts[:-1]), [])
            hint = difflib.get_close_matches(str(parts[-1]), candidates, n=1, cutoff=0.6) if parts else []
            if hint:
                found[tuple(parts)] = hint[0]
    return found


T = TypeVar("T", bound=BaseModel)


def parse_config(data: Any, model: type[T], source: str = "<dict>") -> T:
    """Validate ``data`` (a parsed YAML document) against ``model``; raise :class:`ConfigError` on failure.

    The message reports one problem (a misspelled required key first, as "unknown key; did you mean …",
    not as the missing key it causes) and how many more there are. Numpy arrays, numpy scalars and tuples are
    validated as the lists and numbers they hold (:func:`mobisense.core.plain_data.plain_data`).
    """
    try:
        data = plain_data(data)
    except RecursionError:
        raise ConfigError(f"{source}: nested too deeply") from None
    if data is None:
        raise ConfigError(f"{source}: (top level): the file is empty; expected a mapping of keys")
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: (top level): expected a mapping of keys, got {_KINDS.get(type(data), 'a value')}")
    try:
        # the file's name reaches the validators (a field's ``path`` is relative to the file that names it)
        return model.model_validate(data, context={"source": source})
    except ValidationError as exc:
        errors = exc.errors()
        misspelled = _misspellings(errors, model)
        explained = {(*key[:-1], name) for key, name in misspelled.items()}

        def rank(error: dict[str, Any]) -> int:
            parts = tuple(_key_parts(tuple(error["loc"]), model))
            return 0 if parts in misspelled else 1

        shown = [e for e in errors if not (e["type"] == "missing" and tuple(_key_parts(tuple(e["loc"]), model))
                                           in explained)]  # fmt: skip
        shown.sort(key=rank)
        places = [tuple(_key_parts(tuple(e["loc"]), model)) for e in shown]
        # the branches of a union (a matrix or a name) fail at one key path: one message with every alternative
        first = _alternatives([_describe(e, model, misspelled) for e, at in zip(shown, places, strict=True)
                               if at == places[0]])  # fmt: skip
        rest = len(set(places)) - 1
        more = f" (and {rest} more problem{'s' if rest > 1 else ''})" if rest else ""
        raise ConfigError(f"{source}: {first}{more}") from None
    except RecursionError:
        raise ConfigError(f"{source}: nested too deeply") from None


def read_yaml(path: str | Path) -> Any:
    """Read an input file with :func:`mobisense.core.reader.read_document` (raises :class:`ConfigError`)."""
    return read_document(path)


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
    return parse_config(read_document(path), model, source=str(path))
