"""Gridded fields read from netCDF, interpolated by smoothing-free tensor splines with exact derivatives.

``GriddedField("snapshot.nc", variable="temperature")`` reads a 2-D variable on a rectilinear grid
(coordinates ``x`` and ``y`` by default, in L) and interpolates it with
:class:`scipy.interpolate.RectBivariateSpline` of degree 3 (C² — continuous Hessian) or 5 (C⁴); value,
gradient and Hessian are derivatives of the same spline, so they are mutually consistent. Extra
dimensions (time, depth) are selected with ``select={"time": 0}``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .base import Field, register_field

__all__ = ["GriddedField"]


@register_field
class GriddedField(Field):
    """Spline interpolation of a gridded 2-D field stored in a netCDF file.

    Parameters
    ----------
    path : str or Path
        netCDF file (read with xarray/h5netcdf).
    variable : str
        Name of the data variable.
    x, y : str
        Names of its horizontal coordinates (strictly increasing, L).
    degree : int
        Spline degree in each direction, 3 or 5.
    select : dict, optional
        Integer indices of the other dimensions, e.g. ``{"time": 0, "depth": 2}``.
    """

    kind = "gridded"

    def __init__(
        self,
        path: str | Path,
        variable: str = "z",
        x: str = "x",
        y: str = "y",
        degree: int = 3,
        select: dict[str, int] | None = None,
    ) -> None:
        import xarray as xr
        from scipy.interpolate import RectBivariateSpline

        if degree not in (3, 5):
            raise ValueError(f"degree: expected 3 or 5, got {degree}")
        path = Path(path)
        if not path.is_file():
            raise ValueError(f"path: file not found: {path}")
        with xr.open_dataset(path, engine="h5netcdf") as ds:
            if variable not in ds:
                raise ValueError(
                    f"variable: {variable!r} not in {path} (variables: {', '.join(map(str, ds.data_vars))})"
                )
            data = ds[variable]
            if select:
                data = data.isel(select)
            if set(data.dims) != {x, y}:
                raise ValueError(
                    f"variable {variable!r}: expected dimensions ({y}, {x}) after selecting {select or {}}, "
                    f"got {data.dims}"
                )
            data = data.transpose(x, y)
            xs, ys = np.asarray(data[x], dtype=float), np.asarray(data[y], dtype=float)
            values = np.asarray(data.values, dtype=float)
        for name, coord in ((x, xs), (y, ys)):
            if coord.size <= degree or np.any(np.diff(coord) <= 0):
                raise ValueError(f"coordinate {name!r}: expected more than {degree} strictly increasing values")
        if not np.all(np.isfinite(values)):
            raise ValueError(f"variable {variable!r}: contains NaN or infinite values (land mask?)")
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
