"""A CF-1.10 netCDF-4 writer that needs neither xarray nor pandas: :class:`DatasetContent` and :func:`write_content`.

Importing xarray costs about a second of a command's life (pandas, and through xarray's duck-array checks
dask and distributed); writing the file needs only h5py. :class:`DatasetContent` holds what an
``xarray.Dataset`` would — data variables, coordinates, global attributes, as ``(dims, numpy array,
attrs)`` — and :func:`write_content` writes it (through :mod:`mobisense.core.netcdf4_layout`, or h5netcdf's
own API for what that does not cover) exactly as
``mobisense.core.files.write_netcdf(path, content.to_xarray())`` does: the rules of
:func:`mobisense.core.netcdf.prepare` (global attributes, string labels as ``<dim>_label`` character
variables, no ``_FillValue`` on coordinates), and xarray's encoding (``_FillValue = NaN`` on floating-point
data variables, the ``coordinates`` attribute naming the auxiliary coordinates of each variable,
characters with ``_Encoding = "utf-8"`` on a ``string<n>`` dimension). ``xarray.open_dataset`` reads either
file as the same Dataset (tests/core/test_netcdf_writer.py compares them).

Supported: numeric (integer, floating-point) data variables and coordinates, text (unicode) data variables,
and string-valued index coordinates; anything else is a ``TypeError`` (write it with
``write_netcdf(path, content.to_xarray())``).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .netcdf import global_attributes, label_coordinate
from .netcdf4_layout import supports, write_netcdf4

__all__ = ["DatasetContent", "write_content"]

#: one variable: its dimension names, its values, its attributes
Entry = tuple[tuple[str, ...], np.ndarray, dict[str, Any]]


@dataclass
class DatasetContent:
    """The content of a netCDF file as numpy arrays: the xarray-free twin of an ``xarray.Dataset``.

    Attributes
    ----------
    data_vars : dict
        name -> ``(dims, values, attrs)`` of each data variable (values any array-like of that shape).
    coords : dict
        name -> ``(dims, values, attrs)`` of each coordinate; an index coordinate has ``dims == (name,)``.
    attrs : dict
        Global attributes (strings and numbers).
    """

    data_vars: dict[str, Entry] = field(default_factory=dict)
    coords: dict[str, Entry] = field(default_factory=dict)
    attrs: dict[str, Any] = field(default_factory=dict)

    def add_variable(self, name: str, dims: tuple[str, ...], values: Any, attrs: dict[str, Any]) -> None:
        """Add (or replace) the data variable ``name``."""
        self.data_vars[name] = (tuple(dims), np.asarray(values), dict(attrs))

    def add_coord(self, name: str, dims: tuple[str, ...], values: Any, attrs: dict[str, Any]) -> None:
        """Add (or replace) the coordinate ``name``."""
        self.coords[name] = (tuple(dims), np.asarray(values), dict(attrs))

    def to_xarray(self) -> Any:
        """The ``xarray.Dataset`` of this content (imports xarray)."""
        import xarray as xr

        def entries(table: dict[str, Entry]) -> dict[str, Any]:
            return {name: (dims, values, dict(attrs)) for name, (dims, values, attrs) in table.items()}

        return xr.Dataset(entries(self.data_vars), coords=entries(self.coords), attrs=dict(self.attrs))


def write_content(path: str | Path, content: DatasetContent) -> None:
    """Write ``content`` as a CF-1.10 netCDF-4 file at ``path`` (not atomic: see ``core.files.write_netcdf``).

    Parameters
    ----------
    path : str or Path
        The file to create (overwritten if it exists).
    content : DatasetContent
        Data variables, coordinates and global attributes (see the module notes for what is supported).
    """
    data_vars, coords = _checked(content.data_vars, "data variable"), _checked(content.coords, "coordinate")
    coords = _with_labels(coords)
    variables = {**data_vars, **coords}
    encoded = {name: _encoded(name, entry, name in coords) for name, entry in variables.items()}
    auxiliary = sorted(name for name, (dims, _, _) in coords.items() if dims != (name,))
    dimensions: dict[str, int] = {}
    for dims, values, _, _ in encoded.values():
        for dim, size in zip(dims, values.shape, strict=True):
            if dimensions.setdefault(dim, size) != size:
                raise ValueError(f"dimension {dim!r}: sizes {dimensions[dim]} and {size} conflict")
    listed = {  # xarray's rule for the "coordinates" attribute of each variable
        name: [c for c in auxiliary if name not in coords and name not in dims and set(coords[c][0]) <= set(dims)]
        for name, (dims, _, _) in variables.items()
    }
    unlisted = [c for c in auxiliary if not any(c in names for names in listed.values())]
    attrs = global_attributes(content.attrs)
    if unlisted and "coordinates" not in attrs:  # as xarray: coordinates of no variable, named globally
        attrs["coordinates"] = " ".join(unlisted)
    stored = [
        (name, dims, values, list(_with_coordinates(variable_attrs, listed[name])), fillvalue)
        for name, (dims, values, variable_attrs, fillvalue) in encoded.items()
    ]
    if supports(dimensions, stored, attrs):
        write_netcdf4(path, attrs, dimensions, stored)
        return
    import h5netcdf

    with h5netcdf.File(path, mode="w", format="NETCDF4") as f:
        for key, value in attrs.items():
            f.attrs[key] = value
        f.dimensions = dimensions
        for name, dims, values, variable_attrs, fillvalue in stored:
            variable = f.create_variable(name, dims, dtype=values.dtype, fillvalue=fillvalue)
            variable[...] = values
            for key, value in variable_attrs:
                variable.attrs[key] = value


def _checked(table: dict[str, Entry], what: str) -> dict[str, Entry]:
    out = {}
    for name, (dims, values, attrs) in table.items():
        array = np.asarray(values)
        if array.ndim != len(dims):
            raise ValueError(f"{what} {name!r}: {array.ndim}-dimensional values for dimensions {tuple(dims)}")
        string_index = array.dtype.kind in "OUS" and tuple(dims) == (name,) and what == "coordinate"
        text = array.dtype.kind == "U" and what == "data variable"  # characters on a string<n> dimension
        if array.dtype.kind not in "iuf" and not (string_index or text):
            raise TypeError(f"{what} {name!r}: values of type {array.dtype} (expected integers, floats or text)")
        out[str(name)] = (tuple(dims), array, dict(attrs))
    return out


def _with_labels(coords: dict[str, Entry]) -> dict[str, Entry]:
    """String index coordinates replaced by their ``<dim>_label`` auxiliary coordinates, placed last."""
    kept = {name: entry for name, entry in coords.items() if entry[1].dtype.kind not in "OUS"}
    for name, (_, values, attrs) in coords.items():
        if values.dtype.kind in "OUS":
            label, entry = label_coordinate(name, values, attrs)
            kept[label] = entry
    return kept


def _encoded(name: str, entry: Entry, coordinate: bool) -> tuple[tuple[str, ...], np.ndarray, dict[str, Any], Any]:
    """The encoding xarray gives one variable: ``(dims, values as stored, attrs, fill value)``."""
    dims, values, attrs = entry
    if values.dtype.kind == "U":  # characters of the UTF-8 bytes on a string<n> dimension
        encoded = np.char.encode(values, "utf-8")
        chars = encoded.reshape(encoded.shape + (1,)).view("S1")
        return (*dims, f"string{chars.shape[-1]}"), chars, {**attrs, "_Encoding": "utf-8"}, None
    fillvalue = None if coordinate or values.dtype.kind != "f" else values.dtype.type(np.nan)
    return dims, values, attrs, fillvalue


def _with_coordinates(attrs: dict[str, Any], listed: list[str]) -> Iterator[tuple[str, Any]]:
    yield from attrs.items()
    if listed and "coordinates" not in attrs:
        yield "coordinates", " ".join(listed)
