r"""The one reader of every input file: bounded, strict, and one-line errors naming the key path.

:func:`read_document` reads a YAML (or JSON) file into plain Python data — dicts with string keys, lists,
``str``, ``int``, ``float``, ``bool``, ``None`` — or raises :class:`~mobisense.core.errors.ConfigError`:

- **size**: at most :data:`~mobisense.core.input_text.MAX_BYTES` bytes; directories, missing and unreadable
  files are refused (:mod:`mobisense.core.input_text`);
- **encoding**: UTF-8 (a UTF-8 BOM is dropped); UTF-16 and UTF-32 with a BOM are decoded; anything else —
  other encodings, binary data, NUL bytes — is refused, naming the offending byte's line; a NUL character put
  into a string or key by an escape (``"\0"``, ``"\u0000"``) is refused, naming its key path;
- **structure**: the composer counts nodes *with aliases expanded* (:data:`MAX_NODES`) and bounds nesting
  (:data:`MAX_DEPTH`) while it composes, before any Python object exists, so a 200-byte alias bomb or
  50 000 nested ``[`` cost microseconds; recursive aliases are refused;
- **keys**: duplicate keys are refused with their key path (``cost.alpha: duplicate key (lines 3 and 5)``);
  every key is a plain string (``on:``, ``1:`` are the strings ``"on"``, ``"1"``);
- **scalars**: the YAML 1.2 core schema — ``true/false`` are booleans, ``1e-3`` and ``.inf`` are floats,
  ``yes``/``no``/``010``/``1:30`` are not numbers or booleans; integers must fit in 64 bits and float
  literals in the double range; tags other than the core ones (``!!python/…``, ``!!binary``) are refused.

Errors read ``FILE: key.path: what (line L, column C)``. The events come from libyaml when it is available
(``yaml.CParser``), so large valid files are read at C speed.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import yaml
from yaml.composer import Composer
from yaml.constructor import BaseConstructor, ConstructorError
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode
from yaml.resolver import BaseResolver

from .errors import ConfigError, brief
from .input_text import decode_text, first_nul, read_bytes

try:  # libyaml's event parser (the composer below stays in Python to count nodes)
    from yaml._yaml import CParser as _EventParser  # type: ignore[import-not-found]

    _C_EVENTS = True
except ImportError:  # pragma: no cover - pure-Python PyYAML
    _C_EVENTS = False

__all__ = ["MAX_NODES", "MAX_DEPTH", "read_document", "parse_document"]

#: most nodes (scalars, lists, mappings) of a document, counted with every alias expanded
MAX_NODES = 250_000
#: deepest nesting of lists and mappings, aliases expanded (the schemas need < 10)
MAX_DEPTH = 64
_INT64 = 2**63 - 1

_STR, _INT, _FLOAT = "tag:yaml.org,2002:str", "tag:yaml.org,2002:int", "tag:yaml.org,2002:float"
_BOOL, _NULL = "tag:yaml.org,2002:bool", "tag:yaml.org,2002:null"
_SEQ, _MAP, _MERGE = "tag:yaml.org,2002:seq", "tag:yaml.org,2002:map", "tag:yaml.org,2002:merge"


class _DocumentError(Exception):
    """A problem found while reading, with the key path and the position where it was found."""

    def __init__(self, message: str, path: tuple[Any, ...] = (), mark: Any = None) -> None:
        super().__init__(message)
        self.message, self.path, self.mark = message, path, mark


def _key_path(parts: tuple[Any, ...], limit: int = 80) -> str:
    out = ""
    for part in parts:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out if len(out) <= limit else f"{out[: limit // 2]}…{out[-limit // 2 :]}"


def _where(mark: Any) -> str:
    return "" if mark is None else f"line {mark.line + 1}, column {mark.column + 1}"


# ----------------------------------------------------------------------------------------- YAML: scalars
class _CoreResolver(BaseResolver):
    """Implicit tags of the YAML 1.2 core schema (no ``yes``/``on`` booleans, no octal ``010``, no ``1:30``)."""


_CoreResolver.add_implicit_resolver(_BOOL, re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$"), list("tTfF"))
_CoreResolver.add_implicit_resolver(
    _INT, re.compile(r"^(?:[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+)$"), list("-+0123456789")
)
_CoreResolver.add_implicit_resolver(
    _FLOAT,
    re.compile(
        r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$"
    ),
    list("-+0123456789."),
)
_CoreResolver.add_implicit_resolver(_NULL, re.compile(r"^(?:~|null|Null|NULL|)$"), ["~", "n", "N", ""])
_CoreResolver.add_implicit_resolver(_MERGE, re.compile(r"^<<$"), ["<"])


# ---------------------------------------------------------------------------------------- YAML: composer
class _LimitedComposer(Composer):
    """PyYAML's composer, counting expanded nodes and depth and recording each node's key path."""

    def __init__(self) -> None:
        super().__init__()
        self._path: list[Any] = []
        self._size: dict[int, int] = {}  # id(node) -> nodes with aliases expanded
        self._height: dict[int, int] = {}  # id(node) -> nesting below it, aliases expanded
        self._total = 0  # nodes of the document so far, aliases expanded
        self.node_paths: dict[int, tuple[Any, ...]] = {}

    def compose_node(self, parent: Node | None, index: Any) -> Node:
        if parent is not None:
            self._path.append(index.value if isinstance(index, ScalarNode) else index if isinstance(index, int)
                              else "(key)")  # fmt: skip
        depth = len(self._path)
        if depth > MAX_DEPTH:
            raise _DocumentError(f"nested more than {MAX_DEPTH} levels deep", tuple(self._path), self._mark())
        alias = self.check_event(yaml.AliasEvent)
        mark = self._mark()
        self._total += 0 if alias else 1
        node = super().compose_node(parent, index)
        key = id(node)
        if alias:
            if key not in self._size:
                raise _DocumentError("recursive alias (a value that contains itself)", tuple(self._path), mark)
            self._total += self._size[key]
        else:
            self.node_paths.setdefault(key, tuple(self._path))
            children = (
                [c for pair in node.value for c in pair] if isinstance(node, MappingNode)
                else node.value if isinstance(node, SequenceNode) else []
            )  # fmt: skip
            self._size[key] = 1 + sum(self._size[id(c)] for c in children)
            self._height[key] = 1 + max((self._height[id(c)] for c in children), default=0)
        if self._total > MAX_NODES or self._size[key] > MAX_NODES:
            raise _DocumentError(
                f"more than {MAX_NODES} values with aliases expanded (an alias bomb?)", tuple(self._path), mark
            )
        if depth - 1 + self._height[key] > MAX_DEPTH:
            raise _DocumentError(
                f"nested more than {MAX_DEPTH} levels deep (aliases expanded)", tuple(self._path), mark
            )
        if parent is not None:
            self._path.pop()
        return node

    def _mark(self) -> Any:
        try:
            return self.peek_event().start_mark
        except Exception:  # noqa: BLE001  (only for the position in a message)
            return None


# ------------------------------------------------------------------------------------- YAML: constructor
class _StrictConstructor(BaseConstructor):
    """Core-schema scalars, string keys, no duplicate keys, no tags beyond the core ones."""

    node_paths: dict[int, tuple[Any, ...]]

    def _fail(self, node: Node, message: str, extra: tuple[Any, ...] = (), mark: Any = None) -> None:
        raise _DocumentError(message, self.node_paths.get(id(node), ()) + extra, mark or node.start_mark)

    def construct_str(self, node: Node) -> str:
        if not isinstance(node, ScalarNode):
            self._fail(node, f"expected a text value for tag {node.tag}")
        return node.value

    def construct_null(self, node: Node) -> None:
        return None

    def construct_bool(self, node: Node) -> bool:
        value = self.construct_str(node)
        if value.lower() not in ("true", "false"):
            self._fail(node, f"expected true or false, got {brief(value)}")
        return value.lower() == "true"

    def construct_int(self, node: Node) -> int:
        text = self.construct_str(node)
        match = re.fullmatch(r"([-+]?)(?:0o([0-7]+)|0x([0-9a-fA-F]+)|([0-9]+))", text)
        if match is None:
            self._fail(node, f"expected an integer, got {brief(text)}")
        sign, octal, hexa, decimal = match.groups()  # type: ignore[union-attr]
        digits = octal or hexa or decimal
        if len(digits) > 20:
            self._fail(node, f"integer {brief(text, 30)} is out of range (at most {_INT64})")
        value = int(digits, 8 if octal else 16 if hexa else 10) * (-1 if sign == "-" else 1)
        if abs(value) > _INT64:
            self._fail(node, f"integer {brief(text, 30)} is out of range (at most {_INT64})")
        return value

    def construct_float(self, node: Node) -> float:
        text = self.construct_str(node)
        lowered = text.lower().lstrip("+")
        if lowered in (".inf", "-.inf", ".nan"):
            return float(lowered.replace(".", ""))
        try:
            value = float(text)
        except ValueError:
            self._fail(node, f"expected a number, got {brief(text)}")
        if value in (float("inf"), float("-inf")):
            self._fail(node, f"number {brief(text, 30)} is out of the floating-point range (|x| < 1.8e308)")
        return value

    def construct_list(self, node: Node) -> Any:
        if not isinstance(node, SequenceNode):
            self._fail(node, f"expected a list for tag {node.tag}")
        data: list[Any] = []
        yield data
        data.extend(self.construct_object(child) for child in node.value)

    def construct_dict(self, node: Node) -> Any:
        if not isinstance(node, MappingNode):
            self._fail(node, f"expected a mapping for tag {node.tag}")
        data: dict[str, Any] = {}
        yield data
        seen: dict[str, Node] = {}
        for key_node, _ in node.value:
            if key_node.tag == _MERGE:
                continue
            key = self._key(key_node)
            if key in seen:
                where = f"lines {seen[key].start_mark.line + 1} and {key_node.start_mark.line + 1}"
                self._fail(node, f"duplicate key ({where}); each key may appear once", (key,), key_node.start_mark)
            seen[key] = key_node
        for key_node, value_node in self._merged(node):
            data[self._key(key_node)] = self.construct_object(value_node)

    def _key(self, node: Node) -> str:
        if not isinstance(node, ScalarNode):
            self._fail(node, "expected a name as key, got a list or mapping")
        return node.value

    def _merged(self, node: MappingNode) -> list[tuple[Node, Node]]:
        """``node``'s pairs with YAML merge keys (``<<: *defaults``) applied: explicit keys win."""
        merged: list[tuple[Node, Node]] = []
        explicit = []
        for key_node, value_node in node.value:
            if key_node.tag != _MERGE:
                explicit.append((key_node, value_node))
                continue
            sources = value_node.value if isinstance(value_node, SequenceNode) else [value_node]
            for source in sources:
                if not isinstance(source, MappingNode):
                    self._fail(source, "expected a mapping (or list of mappings) to merge with '<<'")
                merged.extend(self._merged(source))
        return merged + explicit

    def construct_undefined(self, node: Node) -> None:
        self._fail(node, f"unsupported tag {brief(node.tag, 40)} (only plain YAML values are read)")


for _tag, _method in (
    (_STR, _StrictConstructor.construct_str),
    (_NULL, _StrictConstructor.construct_null),
    (_BOOL, _StrictConstructor.construct_bool),
    (_INT, _StrictConstructor.construct_int),
    (_FLOAT, _StrictConstructor.construct_float),
    (_SEQ, _StrictConstructor.construct_list),
    (_MAP, _StrictConstructor.construct_dict),
    (None, _StrictConstructor.construct_undefined),
):
    _StrictConstructor.add_constructor(_tag, _method)


if _C_EVENTS:

    class _Loader(_LimitedComposer, _EventParser, _StrictConstructor, _CoreResolver):  # type: ignore[misc]
        def __init__(self, text: str) -> None:
            _EventParser.__init__(self, text)
            _LimitedComposer.__init__(self)
            _StrictConstructor.__init__(self)
            _CoreResolver.__init__(self)

else:  # pragma: no cover
    from yaml.parser import Parser
    from yaml.reader import Reader
    from yaml.scanner import Scanner

    class _Loader(Reader, Scanner, Parser, _LimitedComposer, _StrictConstructor, _CoreResolver):  # type: ignore[misc,no-redef]
        def __init__(self, text: str) -> None:
            Reader.__init__(self, text)
            Scanner.__init__(self)
            Parser.__init__(self)
            _LimitedComposer.__init__(self)
            _StrictConstructor.__init__(self)
            _CoreResolver.__init__(self)


def _load_yaml(text: str) -> Any:
    loader = _Loader(text)
    try:
        node = loader.get_single_node()
        return None if node is None else loader.construct_document(node)
    finally:
        loader.dispose()


# ------------------------------------------------------------------------------------------------ JSON
def _load_json(text: str) -> Any:
    def pairs(items: list[tuple[str, Any]]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for key, value in items:
            if key in out:
                raise _DocumentError("duplicate key; each key may appear once", (key,))
            out[key] = value
        return out

    def constant(name: str) -> float:
        raise _DocumentError(f"{name} is not a JSON number")

    def number(text: str) -> float:
        value = float(text)
        if value in (float("inf"), float("-inf")):
            raise _DocumentError(f"number {brief(text, 30)} is out of the floating-point range")
        return value

    def integer(text: str) -> int | _OutOfRange:
        # as YAML, 64 bits; digits counted before int() (which refuses 4300+); reported with its key path below
        if len(text.lstrip("-")) > 20 or abs(value := int(text)) > _INT64:
            return _OutOfRange(text)
        return value

    try:
        data = json.loads(text, object_pairs_hook=pairs, parse_constant=constant, parse_float=number,
                          parse_int=integer)  # fmt: skip
    except json.JSONDecodeError as exc:
        raise _DocumentError(f"invalid JSON: {exc.msg}", (), _JsonMark(exc.lineno - 1, exc.colno - 1)) from None
    except RecursionError:
        raise _DocumentError(f"nested more than {MAX_DEPTH} levels deep") from None
    nodes, stack = 0, [(data, ())]
    while stack:  # JSON has no aliases: count what was parsed
        value, path = stack.pop()
        nodes += 1
        if len(path) >= MAX_DEPTH or nodes > MAX_NODES:
            deep, many = f"nested more than {MAX_DEPTH} levels deep", f"more than {MAX_NODES} values"
            raise _DocumentError(deep if len(path) >= MAX_DEPTH else many)
        if isinstance(value, _OutOfRange):
            raise _DocumentError(f"integer {brief(str(value), 30)} is out of range (at most {_INT64})", path)
        if isinstance(value, dict):
            stack.extend((v, (*path, k)) for k, v in value.items())
            nodes += len(value)
        elif isinstance(value, list):
            stack.extend((v, (*path, i)) for i, v in enumerate(value))
    return data


class _OutOfRange(str):
    """A JSON integer literal outside the 64-bit range (reported with its key path after parsing)."""


class _JsonMark:
    def __init__(self, line: int, column: int) -> None:
        self.line, self.column = line, column


# ---------------------------------------------------------------------------------------------- public
def parse_document(text: str, source: str = "<text>", json_syntax: bool = False) -> Any:
    """Parse YAML (or, with ``json_syntax``, JSON) text with the limits and strict scalars of this module.

    Raises
    ------
    ConfigError
        ``SOURCE: key.path: problem (line L, column C)``.
    """
    try:
        data = _load_json(text) if json_syntax else _load_yaml(text)
        nul = first_nul(data)  # an escape "\0" or "\u0000" in a string (raw NUL bytes are refused as binary)
        if nul is not None:
            raise _DocumentError(*nul)
        return data
    except _DocumentError as exc:
        path = _key_path(exc.path)
        where = _where(exc.mark)
        where = f" ({where})" if where else ""
        raise ConfigError(f"{source}: {path + ': ' if path else ''}{exc.message}{where}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" {_where(mark)}:" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        context = getattr(exc, "context", None)
        problem = f"{context}, {problem}" if context and "another document" in str(problem) else problem
        raise ConfigError(f"{source}:{where} invalid YAML: {' '.join(str(problem).split())}") from None
    except ConstructorError as exc:  # pragma: no cover - every tag has a constructor above
        raise ConfigError(f"{source}: invalid YAML: {exc.problem}") from None
    except RecursionError:
        raise ConfigError(f"{source}: nested too deeply") from None


def read_document(path: str | Path) -> Any:
    """Read a YAML or JSON (``*.json``) input file with every limit of this module.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Any
        Plain data: dict (string keys), list, str, int, float, bool or None (an empty file).

    Raises
    ------
    ConfigError
        One line naming the file, the key path where known, what is wrong and where.
    """
    path = Path(path)
    text = decode_text(read_bytes(path), path)
    return parse_document(text, str(path), json_syntax=path.suffix.lower() == ".json")
