"""Registries of named implementations (mobisense.core.registry)."""

from __future__ import annotations

import pytest

from mobisense.core.registry import Lazy, Registry


def test_names_are_strings_and_anything_else_is_simply_not_registered() -> None:
    registry: Registry[object] = Registry("thing", {"lazy": Lazy("math:pi"), "plain": 1})
    assert "plain" in registry and registry["lazy"] == pytest.approx(3.141592653589793)
    for odd in (["plain"], {"plain": 1}, 3, None):  # from a YAML file: unhashable or not a name
        assert odd not in registry
    with pytest.raises(KeyError, match=r"unknown thing \['plain'\]; expected one of 'lazy', 'plain'"):
        registry[["plain"]]  # type: ignore[index]
    assert "did you mean 'plain'" in registry.unknown("plian")
