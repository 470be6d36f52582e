"""Optional dependencies (extras): a clear one-line error when a feature's extra is not installed.

``pip install mobisense`` installs what solving, simulating and plotting need; sweeps and multi-start
(dask, distributed, pyarrow) come with ``pip install "mobisense[sweep]"``. A feature calls
:func:`require_extra` before it starts, so a missing extra is reported before anything runs (exit 2 on
the command line, like any invalid input).
"""

from __future__ import annotations

import importlib.util

from .config import ConfigError

__all__ = ["EXTRAS", "MissingExtra", "require_extra"]

#: extra -> the importable modules it provides
EXTRAS: dict[str, tuple[str, ...]] = {"sweep": ("dask", "distributed", "pyarrow")}


class MissingExtra(ConfigError):
    """A feature needs an extra that is not installed; ``str(err)`` says what to install."""


def require_extra(extra: str, feature: str) -> None:
    """Raise :class:`MissingExtra` unless every module of ``extra`` can be imported.

    Parameters
    ----------
    extra : str
        A key of :data:`EXTRAS`.
    feature : str
        What needs it, for the message (``"mobisense sweep"``).
    """
    missing = [name for name in EXTRAS[extra] if importlib.util.find_spec(name) is None]
    if missing:
        raise MissingExtra(
            f"{feature} needs {', '.join(missing)} (not installed): pip install \"mobisense[{extra}]\" "
            f"(from a clone of the repository: pip install \".[{extra}]\")"
        )
