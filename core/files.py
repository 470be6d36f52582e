"""Atomic output files: nothing is ever half-written.

Each writer produces a temporary file in the destination folder and renames it into place
(``os.replace`` is atomic on POSIX), so an interrupted run leaves either the previous file or the new one.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["atomic_path", "write_json", "write_netcdf", "write_netcdf_variables", "write_figure", "to_jsonable"]


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it is renamed to ``path``, on error removed."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        if tmp_path.exists():  # mkstemp creates 0600; give the file the usual permissions
            os.chmod(tmp_path, 0o666 & ~_umask())
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def to_jsonable(value: Any) -> Any:
    """Convert numpy scalars/arrays and enums (recursively) to plain Python for ``json``; NaN/inf become None."""
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
    """Write an ``xarray.Dataset`` with the h5netcdf engine, atomically."""
    with atomic_path(path) as tmp:
        dataset.to_netcdf(tmp, mode="w", engine="h5netcdf")


def write_netcdf_variables(
    path: str | Path, data: dict[str, tuple], coords: dict[str, Any], attrs: dict[str, Any] | None = None
) -> None:
    """Write what ``xarray.Dataset(data, coords=coords, attrs=attrs)`` would hold, with h5netcdf alone, atomically.

    ``xarray.Dataset.to_netcdf`` imports pandas and, through its duck-array checks, dask and distributed
    (1–3 s in a fresh process); this writes the same netCDF4 file (``xarray.open_dataset(path,
    engine="h5netcdf")`` reads back an identical dataset) without them.

    Parameters
    ----------
    path : str or Path
    data : dict
        name -> ``(dims, array)`` or ``(dims, array, attrs)``, as for ``xarray.Dataset``.
    coords : dict
        dimension name -> 1-D values (numbers or strings).
    attrs : dict, optional
        Global attributes (str, int, float).
    """
    import h5netcdf
    import h5py

    def as_array(values: Any) -> np.ndarray:
        arr = np.asarray(values)
        if arr.dtype.kind in "US" or arr.dtype == object:
            return np.asarray([str(v) for v in np.ravel(arr)], dtype=object).reshape(arr.shape)
        return arr

    sizes: dict[str, int] = {name: len(v) for name, v in coords.items()}
    for dims, values, *_ in data.values():
        for dim, n in zip(dims, np.shape(values), strict=True):
            sizes.setdefault(dim, n)
    with atomic_path(path) as tmp, h5netcdf.File(str(tmp), "w") as f:
        for dim, n in sizes.items():
            f.dimensions[dim] = n
        for name, values in coords.items():
            arr = as_array(values)
            if arr.dtype == object:
                f.create_variable(name, (name,), dtype=h5py.string_dtype())[...] = arr
            else:
                f.create_variable(name, (name,), data=arr)
        for name, (dims, values, *rest) in data.items():
            variable = f.create_variable(name, tuple(dims), data=as_array(values))
            for key, value in (rest[0] if rest else {}).items():
                variable.attrs[key] = value
        for key, value in (attrs or {}).items():
            f.attrs[key] = value


def write_figure(path: str | Path, draw: Callable[[], Any]) -> None:
    """Call ``draw()`` (returning a matplotlib Figure), save it atomically and close it."""
    import matplotlib.pyplot as plt

    fig = draw()
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format=Path(path).suffix.lstrip(".") or "png", dpi=130, bbox_inches="tight")
    finally:
        plt.close(fig)
