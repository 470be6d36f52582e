"""Key paths into nested problem data: ``cost.alpha``, ``sensors[0].p0`` (the names used in error messages)."""

from __future__ import annotations

import copy
import difflib
import re
from functools import lru_cache
from typing import Any

__all__ = ["parse_key_path", "get_path", "set_path", "with_values"]

_TOKEN = re.compile(r"([^.\[\]]+)|\[(\d+)\]")


def parse_key_path(path: str) -> list[str | int]:
    """Split ``"sensors[0].p0"`` into ``["sensors", 0, "p0"]``; raise ``ValueError`` if malformed."""
    return list(_parsed(path))


@lru_cache(maxsize=256)
def _parsed(path: str) -> tuple[str | int, ...]:
    parts: list[str | int] = []
    position = 0
    for match in _TOKEN.finditer(path):
        gap = path[position : match.start()]
        if gap not in ("", "."):
            raise ValueError(f"malformed key path {path!r}")
        parts.append(match.group(1) if match.group(1) is not None else int(match.group(2)))
        position = match.end()
    if not parts or position != len(path) or path.startswith(".") or path.endswith("."):
        raise ValueError(f"malformed key path {path!r}")
    return tuple(parts)


def get_path(data: Any, path: str) -> Any:
    """The value at ``path``; ``KeyError`` with a suggestion when a key or index does not exist."""
    current = data
    walked = ""
    for part in parse_key_path(path):
        if isinstance(part, int):
            if not isinstance(current, list) or part >= len(current):
                size = len(current) if isinstance(current, list) else 0
                raise KeyError(f"{walked or '(top level)'} has no item [{part}] (it has {size})")
            current = current[part]
            walked += f"[{part}]"
        else:
            if not isinstance(current, dict) or part not in current:
                keys = sorted(current) if isinstance(current, dict) else []
                hint = difflib.get_close_matches(part, keys, n=1)
                suggestion = f"; did you mean '{hint[0]}'?" if hint else ""
                raise KeyError(f"{walked or '(top level)'} has no key '{part}'{suggestion}")
            current = current[part]
            walked += f".{part}" if walked else part
    return current


def set_path(data: dict[str, Any], path: str, value: Any) -> dict[str, Any]:
    """A deep copy of ``data`` with the value at ``path`` (which must exist) replaced by ``value``."""
    get_path(data, path)
    out = _deep_copy(data)
    parts = parse_key_path(path)
    target: Any = out
    for part in parts[:-1]:
        target = target[part]
    target[parts[-1]] = _deep_copy(value)
    return out


def with_values(data: dict[str, Any], values: dict[str, Any]) -> dict[str, Any]:
    """``data`` with the value at each path of ``values`` (paths that exist in ``data``) replaced, sharing the rest.

    Only the dicts and lists on the way to a replaced value are copied; every other sub-tree — and each new
    value itself — is the very object of ``data`` (or ``values``). So neither may be changed while the result
    is in use: it is for reading (a sweep validates each task's problem from it), where :func:`set_path`'s
    deep copy of the whole tree per task and key cost more than the validation.
    """
    for path in values:
        get_path(data, path)
    out = dict(data)
    copied = {id(out)}  # the containers made here (two paths through one container copy it once)
    for path, value in values.items():
        parts = _parsed(path)
        target: Any = out
        for part in parts[:-1]:
            child = target[part]
            if id(child) not in copied:
                child = list(child) if isinstance(child, list) else dict(child)
                target[part] = child
                copied.add(id(child))
            target = child
        target[parts[-1]] = value
    return out


def _deep_copy(value: Any) -> Any:
    """``copy.deepcopy`` for YAML data: dicts and lists copied, immutable scalars shared, anything else deepcopied.

    About 5x faster than ``copy.deepcopy`` on a problem (a sweep copies its base once per task and key). Unlike
    it, a sub-tree that appears twice (a YAML alias) is copied twice rather than kept shared.
    """
    if isinstance(value, dict):
        return {key: _deep_copy(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_deep_copy(item) for item in value]
    if value is None or isinstance(value, (str, int, float, bool)):
        return value
    return copy.deepcopy(value)
