"""The pre-flight budget: estimate the memory and time a command will need from its input's sizes, refuse early.

Each kind of work describes itself as :class:`Estimate` items next to the code it describes (the
transcription in :mod:`mobisense.ocp.sizes`, simulations in :mod:`mobisense.formation.sizes`, sweeps in
:mod:`mobisense.ocp.batch.sweep`); a command adds them up and calls :func:`check_budget` before it allocates
anything. Too large → :class:`~mobisense.core.errors.ConfigError` (exit 2) with one line: what is too large,
the estimate, the limit and how to proceed.

The memory limit is ``--max-memory`` when given, else :func:`default_memory_limit`: half of the machine's RAM
(or of its cgroup's memory limit), and never more than the address space left under ``RLIMIT_AS``. The time
limit is ``--max-time`` (default :data:`DEFAULT_MAX_SECONDS`); time estimates are deliberately low (per-unit
costs measured on a fast core), so only work that certainly takes longer is refused.
"""

from __future__ import annotations

import argparse
import numbers
import os
import re
import resource
from dataclasses import dataclass
from pathlib import Path

from .errors import ConfigError

__all__ = [
    "Estimate",
    "PROCESS_BYTES",
    "DEFAULT_MAX_SECONDS",
    "parse_duration",
    "format_duration",
    "add_budget_argument",
    "check_budget",
    "check_limits",
    "MEMORY_LIMITS",
    "TIME_LIMITS",
    "default_memory_limit",
    "format_bytes",
    "parse_size",
]

#: resident memory of a command's process before it computes (Python, numpy, CasADi, xarray; measured ~250 MB)
PROCESS_BYTES = 300 * 2**20
#: default of ``--max-time``: work estimated to take longer is refused unless asked for
DEFAULT_MAX_SECONDS = 3600.0
#: the memory limits (bytes) and time limits (s) a budget takes: ``--max-memory`` 1M … 1E, ``--max-time`` 1s … 1000d
MEMORY_LIMITS = (2**20, 2**60)
TIME_LIMITS = (1.0, 1e8)
_UNITS = {"": 1, "B": 1, "K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40}


@dataclass(frozen=True)
class Estimate:
    """Memory one part of a command will need.

    Attributes
    ----------
    what : str
        The part, in the user's terms (``"the direct-collocation NLP: 2.6e6 variables (K = 100000, d = 9)"``).
    bytes : float
        Estimated peak memory (bytes).
    hint : str
        How to make it smaller (``"use fewer intervals (--intervals) or a lower degree (--degree)"``).
    seconds : float
        Estimated computing time (s), a lower estimate.
    """

    what: str
    bytes: float
    hint: str = ""
    seconds: float = 0.0


def parse_size(text: str) -> int:
    """``"4G"``, ``"512M"``, ``"2.5GiB"``, ``"1e9"`` → bytes (binary units); ``ValueError`` if malformed."""
    match = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*([KMGTkmgt]?)(?:i?[Bb])?\s*", text)
    if match is None:
        raise ValueError(f"expected a size such as 4G, 512M or 2.5GiB, got {text[:40]!r}")
    value = float(match.group(1)) * _UNITS[match.group(2).upper()]
    if not MEMORY_LIMITS[0] <= value <= MEMORY_LIMITS[1]:
        raise ValueError(f"expected a size between 1M and 1E, got {text[:40]!r}")
    return int(value)


def parse_duration(text: str) -> float:
    """``"90"``, ``"90s"``, ``"30m"``, ``"2h"``, ``"1d"`` → seconds; ``ValueError`` if malformed."""
    match = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*([smhd]?)\s*", text)
    if match is None:
        raise ValueError(f"expected a duration such as 90s, 30m or 2h, got {text[:40]!r}")
    value = float(match.group(1)) * {"": 1, "s": 1, "m": 60, "h": 3600, "d": 86400}[match.group(2)]
    if not TIME_LIMITS[0] <= value <= TIME_LIMITS[1]:
        raise ValueError(f"expected a duration between 1s and 1000d, got {text[:40]!r}")
    return value


def format_duration(seconds: float) -> str:
    """``3.2 h``, ``15 min``, ``40 s``."""
    if seconds >= 86400:
        return f"{seconds / 86400:.3g} days"
    if seconds >= 3600:
        return f"{seconds / 3600:.3g} h"
    return f"{seconds / 60:.3g} min" if seconds >= 60 else f"{seconds:.3g} s"


def format_bytes(value: float) -> str:
    """``3.2 GiB``, ``512 MiB``: the size for messages."""
    for unit, size in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20)):
        if value >= size:
            return f"{value / size:.3g} {unit}"
    return f"{value / 2**10:.3g} KiB"


def _physical_memory() -> int | None:
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return None


def _cgroup_limit() -> int | None:
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(path).read_text().strip()
        except OSError:
            continue
        if text.isdigit() and int(text) < 2**60:
            return int(text)
    return None


def _address_space_left() -> int | None:
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY:
        return None
    try:
        status = Path("/proc/self/status").read_text()
        used = int(re.search(r"VmSize:\s+(\d+) kB", status).group(1)) * 1024  # type: ignore[union-attr]
    except (OSError, AttributeError):
        used = PROCESS_BYTES
    # threads started later (BLAS, dask) reserve address space beyond what they touch
    return max(0, soft - used - 512 * 2**20)


def default_memory_limit() -> int:
    """Half of the RAM (or of the cgroup limit, if lower), capped by the address space ``RLIMIT_AS`` leaves."""
    candidates = [v // 2 for v in (_physical_memory(), _cgroup_limit()) if v]
    left = _address_space_left()
    if left is not None:
        candidates.append(left)
    return int(min(candidates)) if candidates else 4 * 2**30


def add_budget_argument(parser: argparse.ArgumentParser, time_limit: str | None = None) -> None:
    """Add ``--max-memory SIZE`` and ``--max-time DURATION`` (the budget checked before any work) to a command.

    ``time_limit`` names what does stop the command's solver while it runs (e.g. ``solver.time_limit in the
    problem file``), said in the help of ``--max-time``; None for a command that has no such limit.
    """

    def size(text: str) -> int:
        try:
            return parse_size(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    def duration(text: str) -> float:
        try:
            return parse_duration(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    parser.add_argument(
        "--max-memory",
        type=size,
        default=None,
        metavar="SIZE",
        help="refuse to start when the estimated memory exceeds SIZE (e.g. 8G; default: half of the RAM)",
    )
    parser.add_argument(
        "--max-time",
        type=duration,
        default=None,
        metavar="DURATION",
        help="refuse to start when a lower bound of the computing time exceeds DURATION (e.g. 6h; default 1h); "
        + ("not a time limit once started" if time_limit is None else f"not a time limit: {time_limit} stops Ipopt"),
    )


def check_limits(max_memory: int | None, max_time: float | None, caller: str) -> None:
    """Refuse the limits ``--max-memory`` and ``--max-time`` would refuse, given to ``caller`` in Python.

    Parameters
    ----------
    max_memory : int, optional
        Bytes, in :data:`MEMORY_LIMITS` (None: the default).
    max_time : float, optional
        Seconds, in :data:`TIME_LIMITS` (None: the default).
    caller : str
        The function taking them, for the message.

    Raises
    ------
    TypeError
        A limit that is not a number.
    ConfigError
        A limit outside its range (NaN included): ``run_sweep: max_time: expected seconds in 1 … 1e8, got -1``.
    """
    for name, value, (low, high), what in (("max_memory", max_memory, MEMORY_LIMITS, "bytes in 1 MiB … 1 EiB"),
                                           ("max_time", max_time, TIME_LIMITS, "seconds in 1 … 1e8")):  # fmt: skip
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise TypeError(f"{caller}: {name}: expected a number of {what}, got {type(value).__name__}")
        if not low <= value <= high:
            raise ConfigError(f"{caller}: {name}: expected {what}, got {value:g}")


def check_budget(
    estimates: list[Estimate], limit: int | None = None, source: str = "", max_seconds: float | None = None
) -> float:
    """Refuse (``ConfigError``) when the estimates exceed the memory or time limit; return the memory (bytes).

    Parameters
    ----------
    estimates : list of Estimate
        The parts of the work (the process itself is added here).
    limit : int, optional
        Bytes (``--max-memory``); default :func:`default_memory_limit`.
    source : str
        The input file, for the message.
    max_seconds : float, optional
        Seconds (``--max-time``); default :data:`DEFAULT_MAX_SECONDS`.
    """
    prefix = f"{source}: " if source else ""
    total = PROCESS_BYTES + sum(max(0.0, e.bytes) for e in estimates)
    allowed = default_memory_limit() if limit is None else limit
    if total > allowed:
        largest = max(estimates, key=lambda e: e.bytes) if estimates else Estimate("the process", total)
        option = "--max-memory" if limit is not None else "--max-memory; default half of the RAM"
        hint = f"; {largest.hint}" if largest.hint else ""
        raise ConfigError(
            f"{prefix}too large: {largest.what} needs about {format_bytes(total)} of memory, more than the "
            f"{format_bytes(allowed)} allowed ({option}){hint}"
        )
    seconds = sum(max(0.0, e.seconds) for e in estimates)
    allowed_seconds = DEFAULT_MAX_SECONDS if max_seconds is None else max_seconds
    if seconds > allowed_seconds:
        longest = max(estimates, key=lambda e: e.seconds)
        hint = f"; {longest.hint}" if longest.hint else ""
        raise ConfigError(
            f"{prefix}too long: {longest.what} would compute for at least {format_duration(seconds)}, more than "
            f"the {format_duration(allowed_seconds)} allowed (--max-time){hint}"
        )
    return total
