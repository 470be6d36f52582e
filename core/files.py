"""Atomic output files: nothing is ever half-written.

Each writer produces a temporary file ``.NAME.XXXXXXXX.tmp`` in the destination folder and renames it into
place (``os.replace`` is atomic on POSIX), so an interrupted run leaves either the previous file or the new
one. A write that fails — disk full, I/O error, read-only file system — removes its temporary file and
raises :class:`~mobisense.core.errors.OutputError` (one line; the previous file is intact). Temporary files
of a run killed outright (SIGKILL) are removed by the next run into the folder
(:func:`mobisense.core.output.remove_stale_temporaries`).
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np

from .errors import OutputError

__all__ = ["atomic_path", "write_json", "write_netcdf", "write_figure", "to_jsonable"]


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it is renamed to ``path``, on error removed."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        os.close(fd)
    except OSError as exc:
        raise OutputError(f"{path}: cannot be written ({exc.strerror or exc})") from None
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        if tmp_path.exists():  # mkstemp creates 0600; give the file the usual permissions
            os.chmod(tmp_path, 0o666 & ~_umask())
        os.replace(tmp_path, path)
    except OSError as exc:
        if isinstance(exc, OutputError):
            raise
        reason = os.strerror(exc.errno) if exc.errno else " ".join(str(exc).split())[:120]
        raise OutputError(f"{path}: cannot be written ({reason}); the previous version, if any, is unchanged") from None
    finally:
        try:
            tmp_path.unlink()
        except OSError:
            pass


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_PLAIN = (str, int, bool, type(None))


def to_jsonable(value: Any) -> Any:
    """Convert numpy scalars/arrays and enums (recursively) to plain Python for ``json``; NaN/inf become None."""
    kind = type(value)  # the leaves' exact types first (summaries are large trees of them)
    if kind in _PLAIN:
        return value
    if kind is float:
        return value if math.isfinite(value) else None
    if isinstance(value, Enum):
        return to_jsonable(value.value)
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, (np.floating, float)):
        f = float(value)
        return f if np.isfinite(f) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def write_json(path: str | Path, data: dict[str, Any]) -> None:
    """Write ``data`` as indented JSON, atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(to_jsonable(data), indent=2, allow_nan=False) + "\n", encoding="utf-8")


def write_netcdf(path: str | Path, dataset: Any) -> None:
    """Write an ``xarray.Dataset`` or a :class:`~mobisense.core.netcdf_writer.DatasetContent` as CF-1.10 netCDF-4.

    The file is written atomically, through h5netcdf. The global attributes, encoding and string labels are
    those of :func:`mobisense.core.netcdf.prepare`; :func:`mobisense.core.netcdf.open_dataset` reads the file
    back as the dataset it was. A ``DatasetContent`` is written without importing xarray
    (:func:`mobisense.core.netcdf_writer.write_content`), to the same file as its ``to_xarray()``.
    """
    from .netcdf_writer import DatasetContent, write_content

    if isinstance(dataset, DatasetContent):
        with atomic_path(path) as tmp:
            write_content(tmp, dataset)
        return
    from .netcdf import prepare

    prepared, encoding = prepare(dataset)
    with atomic_path(path) as tmp:
        prepared.to_netcdf(tmp, mode="w", engine="h5netcdf", encoding=encoding)


def write_figure(path: str | Path, draw: Callable[[], Any]) -> None:
    """Call ``draw()`` (returning a matplotlib Figure), save it atomically and close it.

    A figure with constrained layout (``layout="constrained"``) is saved at its own size, drawn once; any
    other is cropped to its contents (``bbox_inches="tight"``, which draws it twice). A character of a label
    that the font lacks (a sensor named in CJK script) is drawn as a box, without matplotlib's warning.
    """
    import warnings

    import matplotlib.pyplot as plt
    from matplotlib.layout_engine import ConstrainedLayoutEngine

    fig = draw()
    try:
        tight = None if isinstance(fig.get_layout_engine(), ConstrainedLayoutEngine) else "tight"
        with atomic_path(path) as tmp, warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="Glyph .* missing from font", category=UserWarning)
            fig.savefig(tmp, format=Path(path).suffix.lstrip(".") or "png", dpi=130, bbox_inches=tight)
    finally:
        plt.close(fig)
