r"""The text of an input file: its bytes read within bounds, decoded, and what its strings may hold.

:func:`read_bytes` reads at most :data:`MAX_BYTES` bytes of a regular file, a pipe or a device (waiting at most
:data:`PIPE_TIMEOUT` for a writer), refusing directories, missing and unreadable files; :func:`decode_text`
decodes UTF-8 (UTF-16/32 with a byte-order mark) and refuses binary data. :func:`first_nul` finds a NUL
character that a YAML or JSON escape (``"\0"``, ``"\x00"``, ``"\u0000"``) put into a parsed string or key:
no output format (HDF5 strings, netCDF attributes, file names) can carry it, and no input needs it.
:mod:`mobisense.core.reader` builds the documents on these.
"""

from __future__ import annotations

import codecs
import os
import select
import stat
import time
from pathlib import Path
from typing import Any

from .errors import ConfigError, brief

__all__ = ["MAX_BYTES", "PIPE_TIMEOUT", "read_bytes", "decode_text", "first_nul"]

#: largest input file read (bytes); a problem with 150 states is ~0.5 MB
MAX_BYTES = 8 * 1024 * 1024
#: longest wait (s) for a pipe or device given as an input file to deliver all its data
PIPE_TIMEOUT = 10.0

_BOMS = (  # longest first: the UTF-32-LE BOM starts with the UTF-16-LE one
    (codecs.BOM_UTF32_LE, "utf-32-le"),
    (codecs.BOM_UTF32_BE, "utf-32-be"),
    (codecs.BOM_UTF8, "utf-8"),
    (codecs.BOM_UTF16_LE, "utf-16-le"),
    (codecs.BOM_UTF16_BE, "utf-16-be"),
)


def missing_file(path: str | Path) -> str:
    """Why ``path`` is not a regular file to read: ``"file not found"``, a broken link, a folder, a device or pipe."""
    path = Path(path)
    if path.is_symlink() and not path.exists():
        return "broken symbolic link"
    if path.is_dir():
        return "is a directory, expected a file"
    if path.exists():
        return "is not a regular file (a device, pipe or socket), expected a file"
    return "file not found"


def read_bytes(path: str | Path, limit: int = MAX_BYTES, what: str = "file") -> bytes:
    """The bytes of an input file, refusing directories, missing files and files larger than ``limit``.

    Non-regular files (pipes, ``/dev/…``) are read up to ``limit`` + 1 bytes, so ``/dev/zero`` is refused
    as too large instead of filling the memory; a pipe with no writer reads as empty.
    """
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        if path.is_symlink():
            raise ConfigError(f"{path}: broken symbolic link") from None
        from .examples import example_hint

        raise ConfigError(f"{path}: file not found{example_hint(path)}") from None
    except IsADirectoryError:
        raise ConfigError(f"{path}: is a directory, expected a {what}") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read ({exc.strerror})") from None
    try:
        info = os.fstat(fd)
        if stat.S_ISDIR(info.st_mode):
            raise ConfigError(f"{path}: is a directory, expected a {what}")
        if stat.S_ISREG(info.st_mode) and info.st_size > limit:
            raise ConfigError(
                f"{path}: {info.st_size / 2**20:.1f} MiB is larger than the {limit / 2**20:g} MiB an input {what} "
                "may have"
            )
        os.set_blocking(fd, stat.S_ISREG(info.st_mode))  # a pipe or device: read without blocking, waits bounded
        deadline = time.monotonic() + PIPE_TIMEOUT
        chunks, size = [], 0
        while size <= limit:
            try:
                chunk = os.read(fd, min(1 << 20, limit + 1 - size))
            except BlockingIOError:  # a writer that has sent nothing yet, or not everything
                if not select.select([fd], [], [], max(0.0, deadline - time.monotonic()))[0]:
                    raise ConfigError(f"{path}: no end of the data within {PIPE_TIMEOUT:g} s (a pipe or device "
                                      "whose writer does not finish); expected a file") from None  # fmt: skip
                continue
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read ({exc.strerror})") from None
    finally:
        os.close(fd)
    data = b"".join(chunks)
    if len(data) > limit:
        raise ConfigError(f"{path}: larger than the {limit / 2**20:g} MiB an input {what} may have")
    return data


def decode_text(data: bytes, path: Path) -> str:
    """UTF-8 (or UTF-16/32 with a BOM) text of ``data``; ``ConfigError`` naming the first bad byte."""
    for bom, encoding in _BOMS:
        if data.startswith(bom):
            try:
                text = data[len(bom) :].decode(encoding)
            except UnicodeDecodeError as exc:
                raise ConfigError(
                    f"{path}: starts with a {encoding.upper()} byte-order mark but is not valid {encoding.upper()} "
                    f"(byte {exc.start}); save it as UTF-8"
                ) from None
            break
    else:
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError as exc:
            line = data.count(b"\n", 0, exc.start) + 1
            raise ConfigError(
                f"{path}: line {line}: not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start}); "
                "save the file as UTF-8"
            ) from None
    nul = text.find("\x00")
    if nul >= 0:
        line = text.count("\n", 0, nul) + 1
        raise ConfigError(f"{path}: line {line}: binary data (a NUL character), expected a text file")
    return text


def first_nul(data: Any) -> tuple[str, tuple[Any, ...]] | None:
    """``(what is wrong, key path)`` of the first string or key of parsed ``data`` holding a NUL, or None."""
    stack: list[tuple[tuple[Any, ...], Any]] = [((), data)]
    while stack:
        path, value = stack.pop()
        if isinstance(value, str) and "\x00" in value:
            return f"a NUL character in {brief(value.replace(chr(0), chr(0x2400)), 40)}; expected text without it", path
        if isinstance(value, dict):
            for key, item in value.items():
                if "\x00" in key:
                    return "a NUL character in a key; expected a name without it", path
                stack.append(((*path, key), item))
        elif isinstance(value, list):
            stack.extend(((*path, i), item) for i, item in enumerate(value))
    return None
