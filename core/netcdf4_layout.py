"""netCDF-4 files written through h5py alone, in the HDF5 layout h5netcdf gives them, four times faster.

h5netcdf (1.8) spends ≈ 4 ms creating each variable and ≈ 1.5 ms writing it, looking HDF5 objects up by path
dozens of times per variable. The default problem's solution file (22 variables) took 119 ms to write, ≈ 10 %
of a ``solve`` command, and a sweep's part file 170 ms, paid by the client at every flush and once more after
the last task. :func:`write_netcdf4` makes the same HDF5 objects with h5py's own calls, keeping the dimension
scales at hand instead of looking them up (27 ms and 32 ms): the same datasets, dtypes, fill values,
dimension scales and their ``_Netcdf4Dimid`` numbering, ``_Netcdf4Coordinates``,
``DIMENSION_LIST``/``REFERENCE_LIST`` attachments and attribute conversions, in h5netcdf's order of creation.
Only ``_NCProperties`` (the writing library's provenance, ``version=2,mobisense=…,hdf5=…,h5py=…``) differs.
tests/core/test_netcdf_writer.py holds every dataset's shape, dtype, fill value, chunking and attributes to
h5netcdf's, and reads both files back with netCDF-C (netCDF4) as the same variables and attributes.

It covers what solution and task files hold (:func:`supports`): dimensions of positive size, each variable
either the coordinate variable of its own one dimension or named unlike every dimension, numeric or byte
data, and attributes of numbers and text. Anything else is written by h5netcdf
(:func:`mobisense.core.netcdf_writer.write_content` decides).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Variable", "supports", "write_netcdf4"]

#: one variable as written: name, dimension names, values as stored, attributes (in order), fill value or None
Variable = tuple[str, tuple[str, ...], np.ndarray, list[tuple[str, Any]], Any]

#: attribute names that netCDF-4 keeps for itself (h5netcdf refuses them as user attributes)
RESERVED = frozenset(
    {"REFERENCE_LIST", "CLASS", "DIMENSION_LIST", "NAME", "_Netcdf4Dimid", "_Netcdf4Coordinates", "_nc3_strict",
     "_NCProperties"}
)  # fmt: skip
#: the scale name netCDF-4 gives a dimension that has no coordinate variable (then its size, 10 characters)
NOT_A_VARIABLE = b"This is a netCDF dimension but not a netCDF variable."


def supports(dimensions: dict[str, int], variables: Iterable[Variable], attrs: dict[str, Any]) -> bool:
    """Whether :func:`write_netcdf4` writes this content exactly as h5netcdf would.

    Parameters
    ----------
    dimensions : dict
        Dimension name -> size, in order of creation.
    variables : iterable of Variable
        The variables in order of creation.
    attrs : dict
        Global attributes.
    """
    if any(size <= 0 for size in dimensions.values()):  # h5netcdf makes a size-0 dimension unlimited (chunked)
        return False
    attribute_sets = [attrs.items()]
    for name, dims, values, variable_attrs, _ in variables:
        if name in dimensions and tuple(dims) != (name,):  # h5netcdf's "_nc4_non_coord_" renaming
            return False
        if values.dtype.kind not in "iufS":
            return False
        attribute_sets.append(variable_attrs)
    return all(key not in RESERVED and _plain(value) for items in attribute_sets for key, value in items)


def _plain(value: Any) -> bool:
    """An attribute value of numbers or text (h5netcdf's conversion is then the one below)."""
    return np.asarray(value).dtype.kind in "iufSU"


def write_netcdf4(
    path: str | Path, attrs: dict[str, Any], dimensions: dict[str, int], variables: list[Variable]
) -> None:
    """Write a netCDF-4 file through h5py, in h5netcdf's layout (check :func:`supports` first).

    Parameters
    ----------
    path : str or Path
        The file to create (overwritten).
    attrs : dict
        Global attributes.
    dimensions : dict
        Dimension name -> size (> 0), in order of creation: ``_Netcdf4Dimid`` 0, 1, ….
    variables : list of Variable
        ``(name, dims, values, attrs, fill value)`` in order of creation; a variable named as a dimension is
        that dimension's coordinate variable (``dims == (name,)``). ``attrs`` are written in the order given,
        after ``_FillValue`` when the fill value is not None.
    """
    import h5py

    from .version import __version__

    with h5py.File(path, "w", track_order=True) as f:
        for key, value in attrs.items():
            _set_attribute(f.attrs, key, value)
        scales = _Scales()
        for dimid, (name, size) in enumerate(dimensions.items()):  # every dimension a placeholder scale first
            scale = f.create_dataset(name, shape=(size,), dtype=">f4", track_order=True)
            scale.attrs["_Netcdf4Dimid"] = np.array(dimid, dtype=np.int32)
            scale.make_scale(NOT_A_VARIABLE + bytes(f"{size:10}", "ascii"))
            scales.add(name, dimid, scale)
        for name, dims, values, variable_attrs, fillvalue in variables:
            dataset = scales.create_variable(f, name, dims, values, fillvalue)
            if fillvalue is not None:
                _set_attribute(dataset.attrs, "_FillValue", dataset.dtype.type(fillvalue))
            dataset[...] = values
            for key, value in variable_attrs:
                _set_attribute(dataset.attrs, key, value)
        text = f"version=2,mobisense={__version__},hdf5={h5py.version.hdf5_version},h5py={h5py.__version__}"
        f.attrs["_NCProperties"] = np.array(text, dtype=h5py.string_dtype(encoding="ascii", length=len(text)))


class _Scales:
    """The dimension scales of the file being written: each one's id, dataset and the axes attached to it.

    Kept here rather than looked up in the file: an h5py lookup by name costs ≈ 0.1 ms, and h5netcdf's many
    lookups are what made it slow.
    """

    def __init__(self) -> None:
        self.ids: dict[str, int] = {}
        self.datasets: dict[str, Any] = {}
        self.attached: dict[str, list[tuple[Any, int]]] = {}

    def add(self, name: str, dimid: int, dataset: Any) -> None:
        self.ids[name], self.datasets[name], self.attached[name] = dimid, dataset, []

    def create_variable(self, f: Any, name: str, dims: tuple[str, ...], values: np.ndarray, fillvalue: Any) -> Any:
        """Create one variable's dataset and its dimension attachments, as h5netcdf's ``create_variable`` does."""
        if name in self.ids:  # the coordinate variable replaces its dimension's placeholder scale
            placeholder, attached = self.datasets[name], self.attached[name]
            for variable, axis in attached:
                variable.dims[axis].detach_scale(placeholder)
            del f[name]
            dataset = f.create_dataset(name, values.shape, dtype=values.dtype, fillvalue=fillvalue, track_order=True)
            dataset.attrs["_Netcdf4Dimid"] = np.array(self.ids[name], dtype=np.int32)
            dataset.make_scale(name)
            for variable, axis in attached:
                variable.dims[axis].attach_scale(dataset)
            self.datasets[name] = dataset
            dataset.attrs["_Netcdf4Coordinates"] = np.array([self.ids[name]], dtype=np.int32)
            return dataset
        dataset = f.create_dataset(name, values.shape, dtype=values.dtype, fillvalue=fillvalue, track_order=True)
        for axis, dim in enumerate(dims):
            dataset.dims[axis].attach_scale(self.datasets[dim])
            self.attached[dim].append((dataset, axis))
        if dims:
            dataset.attrs["_Netcdf4Coordinates"] = np.array([self.ids[d] for d in dims], dtype=np.int32)
            # netCDF-C gives a variable its first dimension's id when it is first written; h5netcdf copies that
            dataset.attrs["_Netcdf4Dimid"] = np.array(self.ids[dims[0]], dtype=np.int32)
        return dataset


def _set_attribute(target: Any, key: str, value: Any) -> None:
    """h5netcdf's conversion: a number becomes a one-element array (as netCDF-C writes it), text stays."""
    dtype = value.dtype if hasattr(value, "dtype") else np.asarray(value).dtype
    if np.isscalar(value) and dtype.kind not in "SU":
        value = np.atleast_1d(value)
    target[key] = value
