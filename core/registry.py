"""Registries of named implementations: the one list behind a YAML choice, a CLI ``choices=`` and a lookup.

A :class:`Registry` maps names (what a user writes in a problem file) to implementations. Built-in entries
can be given lazily as :class:`Lazy` ``"module:attribute"`` references, so that listing the names (for
``--help`` or validation) imports nothing heavy; packages installed next to mobisense add entries through
an entry-point group (``[project.entry-points."mobisense.noise_models"]``), read once, on the first lookup
of a name that is not built in. :meth:`Registry.choice` is the pydantic type of a field that must name an
entry: it is validated against the registry when a file is read, so an entry registered later (by
:meth:`Registry.register` or an entry point) is accepted from YAML too.
"""

from __future__ import annotations

import difflib
import importlib
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Annotated, Any, Generic, TypeVar

__all__ = ["Lazy", "Registry"]

T = TypeVar("T")


@dataclass(frozen=True)
class Lazy:
    """A reference ``"package.module:attribute"`` resolved when the entry is first looked up."""

    target: str

    def load(self) -> Any:
        """Import the module and return the attribute."""
        module_name, _, attribute = self.target.partition(":")
        return getattr(importlib.import_module(module_name), attribute)


class Registry(Mapping[str, T], Generic[T]):
    """Named implementations of one kind (``"noise model"``, ``"collocation scheme"``, …).

    Parameters
    ----------
    kind : str
        What an entry is, for messages (``"unknown noise model 'x'"``).
    entries : dict, optional
        Built-in entries: name -> implementation or :class:`Lazy` reference.
    entry_point_group : str, optional
        Entry-point group scanned (once) for names that are not registered.
    """

    def __init__(self, kind: str, entries: dict[str, T | Lazy] | None = None, entry_point_group: str | None = None):
        self.kind = kind
        self._entries: dict[str, T | Lazy] = dict(entries or {})
        self._group = entry_point_group
        self._scanned = entry_point_group is None

    # ------------------------------------------------------------------ registration
    def register(self, name: str, implementation: T) -> T:
        """Add (or replace) ``name``; returns ``implementation`` so it can end a decorator."""
        if not isinstance(name, str) or not name:
            raise TypeError(f"a {self.kind} needs a non-empty string name, got {name!r}")
        self._entries[name] = implementation
        return implementation

    def decorator(self, name_of: Callable[[Any], str]) -> Callable[[T], T]:
        """A class decorator registering each class under ``name_of(cls)``."""

        def register(cls: T) -> T:
            return self.register(name_of(cls), cls)

        return register

    def _scan_entry_points(self) -> None:
        if self._scanned:
            return
        self._scanned = True
        from importlib.metadata import entry_points

        for entry in entry_points(group=self._group or ""):
            self._entries.setdefault(entry.name, Lazy(entry.value))

    # ------------------------------------------------------------------ lookup
    def names(self) -> list[str]:
        """Sorted names of the built-in and registered entries (entry points once scanned; no import)."""
        return sorted(self._entries)

    def __contains__(self, name: object) -> bool:
        if not isinstance(name, str):  # a list or mapping from a file is no name (and unhashable)
            return False
        if name not in self._entries:
            self._scan_entry_points()
        return name in self._entries

    def __getitem__(self, name: str) -> T:
        if name not in self:
            raise KeyError(self.unknown(name))
        entry = self._entries[name]
        if isinstance(entry, Lazy):
            entry = self._entries[name] = entry.load()
        return entry  # type: ignore[return-value]

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __len__(self) -> int:
        return len(self._entries)

    def unknown(self, name: object) -> str:
        """The message for a name that is not registered, with a suggestion when one is close."""
        self._scan_entry_points()
        names = self.names()
        hint = difflib.get_close_matches(str(name), names, n=1) if isinstance(name, str) else []
        suggestion = f"did you mean '{hint[0]}'? " if hint else ""
        listing = ", ".join(f"'{n}'" for n in names)
        shown = repr(name) if len(repr(name)) <= 40 else repr(name)[:37] + "..."
        return f"unknown {self.kind} {shown}; {suggestion}expected one of {listing}"

    # ------------------------------------------------------------------ schema
    def check(self, name: str) -> str:
        """Return ``name`` if registered, else raise ``ValueError`` with :meth:`unknown`'s message."""
        if name not in self:
            raise ValueError(self.unknown(name))
        return name

    def choice(self) -> Any:
        """The pydantic type of a string field naming an entry (JSON schema: an ``enum`` of the names)."""
        from pydantic import AfterValidator, Field  # here: listing names (``--help``) must not import pydantic

        def enum(schema: dict[str, Any]) -> None:
            self._scan_entry_points()
            schema["enum"] = self.names()

        return Annotated[str, AfterValidator(self.check), Field(json_schema_extra=enum)]
