"""Gridded fields read from netCDF, interpolated by smoothing-free tensor splines with exact derivatives.

``GriddedField("snapshot.nc", variable="temperature")`` reads a 2-D variable on a rectilinear grid
(coordinates ``x`` and ``y`` by default, in L) and interpolates it with
:class:`scipy.interpolate.RectBivariateSpline` of degree 3 (C² — continuous Hessian) or 5 (C⁴); value,
gradient and Hessian are derivatives of the same spline, so they are mutually consistent. Extra
dimensions (time, depth) are selected with ``select={"time": 0}``.

A file is hostile input: its declared sizes are checked before any array is read (at most
:data:`MAX_GRID_POINTS` grid points, and the memory of the fit within
:func:`mobisense.core.budget.default_memory_limit`), and a file that is not netCDF-4, a missing variable, a
wrong dimension or a non-numeric value is a one-line ``ValueError`` starting with the parameter at fault
(``path: …``, ``variable: …``), which :class:`~mobisense.estimation.fields.library.FieldSpec` reports as
``field.path: …``.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ...core.errors import brief, one_line
from .base import Field, register_field

__all__ = ["GriddedField", "MAX_GRID_POINTS", "BYTES_PER_POINT"]

#: most points of the 2-D grid a gridded field interpolates (5000 × 5000; the fit takes seconds and ~1 GiB),
#: and of any dimension of the file (xarray reads the coordinates of every dimension when it opens a file)
MAX_GRID_POINTS = 25_000_000
#: peak memory of reading and fitting one grid point (bytes): the values as stored and as float64, the spline
#: coefficients and FITPACK's workspace (~16 bytes per point measured), with margin
BYTES_PER_POINT = 48

_KINDS = {bool: "a boolean", str: "a string", int: "an integer", float: "a number", list: "a list", dict: "a mapping"}


def _got(value: Any) -> str:
    """``'3' (a string)``: a value and its YAML type, for messages."""
    kind = "null" if value is None else _KINDS.get(type(value), type(value).__name__)
    return f"{brief(value)} ({kind})"


def _shown(path: Path) -> str:
    text = str(path)
    return text if len(text) <= 120 else "…" + text[-119:]


def _name(text: Any) -> str:
    """A name from the file or the parameters, unquoted, at most 40 characters."""
    return one_line(str(text), 40)


def _dims(dims: Any) -> str:
    return one_line(", ".join(map(str, dims)), 120)


def _reason(exc: BaseException) -> str:
    return one_line(str(exc) or type(exc).__name__, 160)


def _check_parameters(path: Any, variable: Any, x: Any, y: Any, degree: Any, select: Any) -> dict[str, int]:
    """Types and values of the parameters, before the file is touched; the ``select`` mapping."""
    if not (isinstance(path, os.PathLike) or (isinstance(path, str) and path.strip())):
        raise ValueError(f"path: expected the name of a netCDF file (a string), got {_got(path)}")
    for name, value in (("variable", variable), ("x", x), ("y", y)):
        if not isinstance(value, str) or not value:
            raise ValueError(f"{name}: expected a name in the netCDF file (a non-empty string), got {_got(value)}")
    if x == y:
        raise ValueError(f"y: expected a coordinate other than x ({x!r})")
    if type(degree) is not int or degree not in (3, 5):
        raise ValueError(f"degree: expected 3 or 5, got {_got(degree)}")
    if select is None:
        return {}
    if not isinstance(select, dict):
        raise ValueError(
            f"select: expected a mapping of dimension names to integer indices, e.g. {{time: 0}}, got {_got(select)}"
        )
    for key, index in select.items():
        if not isinstance(key, str):
            raise ValueError(f"select: expected dimension names (strings) as keys, got {_got(key)}")
        if type(index) is not int:
            raise ValueError(f"select.{_name(key)}: expected an integer index, got {_got(index)}")
    return dict(select)


def _check_file(path: Path) -> None:
    """The file exists, is a regular file and looks like netCDF-4 (HDF5); its dimensions are bounded."""
    try:
        if not path.exists():
            raise ValueError(f"path: file not found: {_shown(path)}")
        if not path.is_file():
            what = "a directory" if path.is_dir() else "a special file"
            raise ValueError(f"path: expected a netCDF file, got {what}: {_shown(path)}")
        with open(path, "rb") as stream:
            head = stream.read(8)
    except OSError as exc:  # a name too long, a permission denied, an I/O error
        raise ValueError(f"path: cannot read {_shown(path)}: {_reason(exc)}") from None
    if head[:3] == b"CDF":
        raise ValueError(
            f"path: {_shown(path)} is a netCDF-3 (classic) file; expected netCDF-4 (convert it with "
            "'nccopy -k nc4 IN OUT')"
        )
    import h5netcdf

    try:
        with h5netcdf.File(path, "r") as handle:  # metadata only: nothing of the variables' size is read
            sizes = {str(name): int(dim.size) for name, dim in handle.dimensions.items()}
    except Exception as exc:  # noqa: BLE001  (h5py and h5netcdf raise OSError, ValueError, KeyError… on damaged files)
        raise ValueError(f"path: expected a netCDF-4 (HDF5) file, cannot open {_shown(path)}: {_reason(exc)}") from None
    for name, size in sizes.items():
        if size > MAX_GRID_POINTS:
            raise ValueError(
                f"path: dimension {_name(name)!r} of {_shown(path)} declares {size:,} values, more than the "
                f"{MAX_GRID_POINTS:,} a gridded field reads"
            )


def _check_size(shape: tuple[int, ...], path: Path, variable: str) -> None:
    """The selected 2-D grid fits :data:`MAX_GRID_POINTS` and the memory budget (before it is read)."""
    from ...core.budget import PROCESS_BYTES, default_memory_limit, format_bytes

    points = int(np.prod(shape, dtype=float)) if shape else 1
    grid, what = " × ".join(f"{n:,}" for n in shape), f"variable {brief(variable, 60)} of {_shown(path)}"
    if points > MAX_GRID_POINTS:
        raise ValueError(
            f"path: {what} declares a grid of {grid} = {points:,} points, more than the {MAX_GRID_POINTS:,} a "
            "gridded field interpolates (subsample it, e.g. with xarray's isel or coarsen)"
        )
    needed, limit = PROCESS_BYTES + BYTES_PER_POINT * points, default_memory_limit()
    if needed > limit:
        raise ValueError(
            f"path: {what} ({grid} points) needs about {format_bytes(needed)} of memory to interpolate, more than "
            f"the {format_bytes(limit)} available (half of the RAM)"
        )


def _read(
    path: Path, variable: str, x: str, y: str, degree: int, select: dict[str, int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Coordinates ``xs``, ``ys`` and values ``(len(xs), len(ys))`` of the selected variable, sizes checked first."""
    _check_file(path)
    with warnings.catch_warnings():  # decoding warnings of an unusual file would add lines to standard error
        warnings.simplefilter("ignore")
        return _load(path, variable, x, y, degree, select)


def _load(
    path: Path, variable: str, x: str, y: str, degree: int, select: dict[str, int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    import xarray as xr

    shown = brief(variable, 60)
    try:  # HDF5 datasets without netCDF dimensions get phony dimensions
        ds = xr.open_dataset(path, engine="h5netcdf", phony_dims="sort")
    except Exception as exc:  # noqa: BLE001  (decoding errors of a damaged or unusual file)
        raise ValueError(f"path: cannot read {_shown(path)} as netCDF-4: {_reason(exc)}") from None
    with ds:
        if variable not in ds:
            names = ", ".join(_name(v) for v in list(ds.data_vars)[:20])
            raise ValueError(f"variable: {shown} not in {_shown(path)} (variables: {names or 'none'})")
        data = ds[variable]
        for dim, index in select.items():
            if dim not in data.dims:
                raise ValueError(
                    f"select.{_name(dim)}: not a dimension of variable {shown} (dimensions: {_dims(data.dims)})"
                )
            size = data.sizes[dim]
            if not -size <= index < size:
                raise ValueError(f"select.{_name(dim)}: expected an index in 0 … {size - 1}, got {index}")
        if select:
            data = data.isel(select)
        if set(data.dims) != {x, y} or data.ndim != 2:
            others = [_name(d) for d in data.dims if d not in (x, y)]
            hint = f"; select the other dimensions, e.g. select: {{{others[0]}: 0}}" if others else ""
            if data.ndim == 2 and len(others) == 2:  # two dimensions, named otherwise: name them as x and y
                hint = f"; its two dimensions are named otherwise: set x: {others[1]} and y: {others[0]} (or reversed)"
            raise ValueError(
                f"variable: {shown} has dimensions ({_dims(data.dims)}) after selecting {brief(select)}; expected "
                f"({_name(y)}, {_name(x)}) (the parameters x and y name its coordinates){hint}"
            )
        _check_size(tuple(int(n) for n in data.shape), path, variable)
        data = data.transpose(x, y)
        for which, name, array in (("variable", variable, data), ("x", x, data[x]), ("y", y, data[y])):
            if array.dtype.kind not in "biuf":
                raise ValueError(f"{which}: {brief(name, 60)} holds values of type {array.dtype}; expected numbers")
        try:
            xs, ys = np.asarray(data[x], dtype=float), np.asarray(data[y], dtype=float)
            values = np.asarray(data.values, dtype=float)
        except Exception as exc:  # noqa: BLE001  (a damaged chunk, a failing filter)
            raise ValueError(f"path: reading {shown} from {_shown(path)} failed: {_reason(exc)}") from None
    for which, name, coord in (("x", x, xs), ("y", y, ys)):
        if coord.size <= degree:
            raise ValueError(
                f"{which}: coordinate {brief(name, 60)} has {coord.size} values; a spline of degree {degree} needs more"
            )
        if not np.all(np.isfinite(coord)) or np.any(np.diff(coord) <= 0):
            raise ValueError(f"{which}: coordinate {brief(name, 60)}: expected strictly increasing finite values")
    if not np.all(np.isfinite(values)):
        raise ValueError(f"variable: {brief(variable, 60)} contains NaN or infinite values (land mask?)")
    return xs, ys, values


@register_field
class GriddedField(Field):
    """Spline interpolation of a gridded 2-D field stored in a netCDF file.

    Parameters
    ----------
    path : str or Path
        netCDF-4 file (read with xarray/h5netcdf). In a scenario file a relative path is relative to the
        folder of that scenario file (not to the working directory), so the scenario validates and runs the
        same from anywhere; an absolute path is used as is. (:class:`~mobisense.estimation.fields.library.FieldSpec`
        resolves it; in Python a relative path is relative to the working directory.)
    variable : str
        Name of the data variable.
    x, y : str
        Names of its horizontal coordinates (strictly increasing, L).
    degree : int
        Spline degree in each direction, 3 or 5.
    select : dict, optional
        Integer indices of the other dimensions, e.g. ``{"time": 0, "depth": 2}``.

    Raises
    ------
    ValueError
        One line starting with the parameter at fault (``path: …``): a missing or non-netCDF-4 file, a grid
        of more than :data:`MAX_GRID_POINTS` points or one whose fit would not fit in memory (both checked
        from the declared sizes, before anything is read), an unknown variable or dimension, non-numeric,
        non-finite or non-increasing values.
    """

    kind = "gridded"
    #: parameters naming files, resolved by FieldSpec against the folder of the file naming them
    file_parameters = ("path",)

    def __init__(
        self,
        path: str | Path,
        variable: str = "z",
        x: str = "x",
        y: str = "y",
        degree: int = 3,
        select: dict[str, int] | None = None,
    ) -> None:
        from scipy.interpolate import RectBivariateSpline

        selection = _check_parameters(path, variable, x, y, degree, select)
        path = Path(path)
        xs, ys, values = _read(path, variable, x, y, degree, selection)
        self.path, self.variable = path, variable
        self.bounds = ((xs[0], xs[-1]), (ys[0], ys[-1]))
        self._spline = RectBivariateSpline(xs, ys, values, kx=degree, ky=degree, s=0)

    def _ev(self, r: np.ndarray, dx: int, dy: int) -> np.ndarray:
        r = np.asarray(r, dtype=float)
        return self._spline.ev(r[..., 0], r[..., 1], dx=dx, dy=dy)

    def value(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Interpolated value, shape ``r.shape[:-1]`` (extrapolated outside the grid: avoid)."""
        return self._ev(r, 0, 0)

    def gradient(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Spline gradient, shape ``r.shape``."""
        return np.stack([self._ev(r, 1, 0), self._ev(r, 0, 1)], axis=-1)

    def hessian(self, r: np.ndarray, t: float = 0.0) -> np.ndarray:
        """Spline Hessian, shape ``r.shape + (2,)``."""
        hxx, hxy, hyy = self._ev(r, 2, 0), self._ev(r, 1, 1), self._ev(r, 0, 2)
        return np.stack([np.stack([hxx, hxy], -1), np.stack([hxy, hyy], -1)], -2)
