"""Lazy public names for package ``__init__`` files: ``import mobisense`` stays fast.

A package lists its public names with the module that defines each; the module is imported on first
attribute access (PEP 562), so importing the package costs nothing until a name is used::

    __getattr__, __dir__, __all__ = lazy_exports(__name__, {"solve": "mobisense.ocp.solving"})
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(
    package: str, names: dict[str, str]
) -> tuple[Callable[[str], Any], Callable[[], list[str]], list[str]]:
    """Module-level ``__getattr__``, ``__dir__`` and ``__all__`` for ``package``.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    names : dict
        Public name -> module that defines it (the attribute has the same name there), or
        ``"module:attribute"`` for a public name that differs from the definition's.
    """
    import sys

    def __getattr__(name: str) -> Any:
        if name not in names:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        module_name, _, attribute = names[name].partition(":")
        value = getattr(importlib.import_module(module_name), attribute or name)
        setattr(sys.modules[package], name, value)  # later lookups skip __getattr__
        return value

    def __dir__() -> list[str]:
        return sorted(set(names) | set(vars(sys.modules[package])))

    return __getattr__, __dir__, sorted(names)
