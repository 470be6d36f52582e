"""The YAML text of a mapping of plain data, each top-level entry's text emitted once per distinct value.

Every solution file carries its problem as YAML (``problem_yaml``), and a sweep writes one per task: tasks that
differ in one or two entries of a problem (``cost``, ``sensors``) share the text of all the others. The block
mapping PyYAML emits is the concatenation of its top-level entries, each emitted as a one-entry mapping (every
entry starts at column 0, and nothing but an alias ties two entries together), so :func:`dump_mapping` keeps
the text of each entry it has emitted, keyed by the entry's key and the ``repr`` of its value, and emits only
the entries it has not seen. The result is ``yaml.safe_dump(data, sort_keys=False, allow_unicode=True)``
character for character (tests/core/test_yaml_text.py holds it to that on thousands of random documents);
whatever the fast path cannot vouch for — a value other than dicts with string keys, lists, str, int, float,
bool and None, a container that occurs twice (PyYAML would emit an anchor and an alias) — is emitted whole.
"""

from __future__ import annotations

from typing import Any

import yaml

__all__ = ["dump_mapping", "ENTRY_MEMO"]

#: entries (key, value) whose text is kept; the oldest is forgotten first
ENTRY_MEMO = 512
#: libyaml's emitter when PyYAML has it: the same text as the pure-Python one, ≈ 5× faster
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
_SCALARS = (str, int, float, bool, type(None))
_entries: dict[tuple[str, str], str] = {}


def _dump(data: Any) -> str:
    return yaml.dump(data, Dumper=_DUMPER, sort_keys=False, allow_unicode=True)


def _plain(value: Any, seen: set[int]) -> bool:
    """True when ``value`` is plain data (see the module docstring) in which no container occurs twice.

    The ``repr`` of such a value is injective (strings are quoted, ``True`` is not ``1``, ``1.0`` is not ``1``),
    so it identifies the entry's text.
    """
    kind = type(value)
    if kind in _SCALARS:
        return True
    if kind is dict:
        if id(value) in seen:
            return False
        seen.add(id(value))
        return all(type(k) is str and _plain(v, seen) for k, v in value.items())
    if kind is list:
        if id(value) in seen:
            return False
        seen.add(id(value))
        return all(_plain(v, seen) for v in value)
    return False


def dump_mapping(data: dict[str, Any]) -> str:
    """``yaml.safe_dump(data, sort_keys=False, allow_unicode=True)``, re-using the text of entries seen before.

    Parameters
    ----------
    data : dict
        The mapping (e.g. :meth:`mobisense.ocp.problem.Problem.normalised`).

    Returns
    -------
    str
        Its YAML text (block style, keys in the mapping's order).
    """
    if type(data) is not dict or not data or not _plain(data, set()):
        return _dump(data)
    parts = []
    for key, value in data.items():
        ident = (key, repr(value))
        text = _entries.get(ident)
        if text is None:
            text = _dump({key: value})
            if len(_entries) >= ENTRY_MEMO:
                del _entries[next(iter(_entries))]
            _entries[ident] = text
        parts.append(text)
    return "".join(parts)
