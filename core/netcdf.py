"""CF-1.10 netCDF files: the global attributes, the encoding and the reading back of every file written.

Every dataset the toolkit writes (``solution.nc``, ``result.nc``, ``trace_grid.nc``, a sweep's task files)
goes through :func:`prepare` (called by :func:`mobisense.core.files.write_netcdf`; a
``DatasetContent`` gets the same rules in :mod:`mobisense.core.netcdf_writer`, without xarray), which adds

* the global attributes ``Conventions = "CF-1.10"``, ``title`` (the producer's, or a generic one),
  ``history`` (UTC time, mobisense version and the command line, or the Python call) and ``source``;
* no ``_FillValue`` on coordinate variables (CF §2.5.1: coordinates have no missing values);
* string-valued index coordinates (sensor names, ``x``/``y`` labels) written as CF *auxiliary* coordinate
  variables ``<dim>_label`` of characters (CF §6.1): a coordinate variable must be numeric and monotonic.

:func:`open_dataset` reads such a file back with the labels as index coordinates again, so
``open_dataset("solution.nc").sel(sensor="s1")`` works as on the dataset before writing. Producers give
each variable ``long_name`` and ``units`` (UDUNITS strings, see :mod:`mobisense.core.units`);
:func:`cf_problems` lists what is missing (the tests run it on every file the commands write).
"""

from __future__ import annotations

import datetime
import sys
from collections.abc import Callable, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from .version import __version__

__all__ = [
    "CONVENTIONS",
    "LABEL_SUFFIX",
    "recorded_command",
    "global_attributes",
    "label_coordinate",
    "prepare",
    "open_dataset",
    "check_signature",
    "SIGNATURES",
    "cf_problems",
]

CONVENTIONS = "CF-1.10"
#: suffix of the auxiliary coordinate that carries the string labels of a dimension in the file
LABEL_SUFFIX = "_label"
#: the first bytes of a netCDF-4 (HDF5) file and of a classic netCDF file
SIGNATURES = (b"\x89HDF\r\n\x1a\n", b"CDF")

_command: list[str] = []


@contextmanager
def recorded_command(argv: Sequence[str]):  # noqa: ANN201  (context manager)
    """Within this context, ``history`` records ``mobisense ARGV…`` (the command line calls this)."""
    _command.append(" ".join(["mobisense", *map(str, argv)]))
    try:
        yield
    finally:
        _command.pop()


def _history() -> str:
    stamp = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    what = _command[-1] if _command else f"Python API ({Path(sys.argv[0]).name or 'python'})"
    return f"{stamp}: {what} (mobisense {__version__})"


def global_attributes(attrs: dict[str, Any]) -> dict[str, Any]:
    """The global attributes as written: ``Conventions``, ``title``, ``history`` (appended to), ``source``, the rest."""
    title = attrs.get("title") or "mobisense output"
    previous = attrs.get("history")
    history = _history() if not previous else f"{previous}\n{_history()}"
    fixed = {"Conventions": CONVENTIONS, "title": title, "history": history, "source": f"mobisense {__version__}"}
    return {**fixed, **{k: v for k, v in attrs.items() if k not in fixed}}


def label_coordinate(dim: str, labels: Any, attrs: dict[str, Any]) -> tuple[str, Any]:
    """The auxiliary coordinate ``(name, (dims, values, attrs))`` that carries the string labels of ``dim``."""
    label_attrs = {"long_name": attrs.get("long_name", f"name of each {dim}")}
    return f"{dim}{LABEL_SUFFIX}", ((dim,), labels.astype(str), label_attrs)


def prepare(dataset: Any) -> tuple[Any, dict[str, dict[str, Any]]]:
    """The dataset as written, and its encoding (see the module notes).

    Parameters
    ----------
    dataset : xarray.Dataset
        The producer's dataset (left unchanged).

    Returns
    -------
    dataset : xarray.Dataset
        A shallow copy with the global attributes and string labels as auxiliary coordinates.
    encoding : dict
        ``to_netcdf`` encoding: no ``_FillValue`` on coordinates, strings as characters.
    """
    ds = dataset.copy()
    for dim in list(ds.dims):
        if dim in ds.coords and ds[dim].dtype.kind in "OUS":
            name, label = label_coordinate(str(dim), ds[dim].values, ds[dim].attrs)
            ds = ds.drop_vars(dim).assign_coords({name: label})
    ds.attrs = global_attributes(ds.attrs)
    encoding: dict[str, dict[str, Any]] = {}
    for name, variable in ds.variables.items():
        entry: dict[str, Any] = {}
        if name in ds.coords:
            entry["_FillValue"] = None
        if variable.dtype.kind in "OUS":
            entry["dtype"] = "S1"
        if entry:
            encoding[str(name)] = entry
    return ds, encoding


def check_signature(path: str | Path) -> bytes:
    """The first 8 bytes of ``path``; ``ValueError`` unless they begin a netCDF-4 (HDF5) or classic netCDF file."""
    with open(path, "rb") as f:
        magic = f.read(8)
    if not magic.startswith(SIGNATURES):
        raise ValueError("neither HDF5 nor netCDF data")
    return magic


def open_dataset(path: str | Path) -> Any:
    """Read a file written by mobisense, restoring string labels as index coordinates (loaded into memory).

    Raises
    ------
    FileNotFoundError
        No file at ``path``.
    ConfigError
        ``path`` is not a netCDF file xarray can read (``FILE: expected a netCDF file written by mobisense …``).
    """
    import xarray as xr

    from .errors import ConfigError, one_line

    try:
        check_signature(path)
        with xr.open_dataset(path, engine="h5netcdf") as ds:
            ds = ds.load()
    except FileNotFoundError:
        raise
    except (OSError, ValueError, TypeError, KeyError, RuntimeError) as exc:
        reason = one_line(f"{type(exc).__name__}: {exc}", 120)
        raise ConfigError(f"{path}: expected a netCDF file written by mobisense (solution.nc, result.nc, …), got "
                          f"one it cannot read ({reason})") from None  # fmt: skip
    for name in [str(n) for n in ds.coords if str(n).endswith(LABEL_SUFFIX)]:
        dim = name[: -len(LABEL_SUFFIX)]
        if ds[name].dims == (dim,):
            ds = ds.assign_coords({dim: ds[name].values.astype(str)}).drop_vars(name)
    return ds


def cf_problems(dataset: Any, parse_unit: Callable[[str], Any] | None = None) -> list[str]:
    """What keeps a dataset *as written* (after :func:`prepare`) from the CF rules this toolkit follows.

    Parameters
    ----------
    dataset : xarray.Dataset
        The dataset as written (or read back with ``xarray.open_dataset``).
    parse_unit : callable, optional
        A UDUNITS parser (``cf_units.Unit``) that raises on an invalid unit string.

    Returns
    -------
    list of str
        One line per problem; empty when every variable and coordinate has ``long_name`` and ``units``
        (parsable, if a parser is given), no coordinate has a ``_FillValue``, every coordinate variable
        is numeric and monotonic, and the global attributes are there.
    """
    import numpy as np

    required = ("Conventions", "title", "history")
    problems = [f"global attribute {k!r} missing" for k in required if k not in dataset.attrs]
    if dataset.attrs.get("Conventions") not in (None, CONVENTIONS):
        problems.append(f"Conventions is {dataset.attrs['Conventions']!r}, expected {CONVENTIONS!r}")
    for name, variable in dataset.variables.items():
        attrs = {**variable.attrs, **variable.encoding}
        if variable.dtype.kind in "OSU" and str(name).endswith(LABEL_SUFFIX):
            continue  # a label (auxiliary coordinate of names), described by its dimension
        for key in ("long_name",) if variable.dtype.kind in "OSU" else ("long_name", "units"):
            if key not in variable.attrs:
                problems.append(f"{name}: no {key}")
        if "units" in variable.attrs and parse_unit is not None:
            try:
                parse_unit(variable.attrs["units"])
            except Exception as err:  # noqa: BLE001  (any parser error is the finding)
                problems.append(f"{name}: units {variable.attrs['units']!r} do not parse: {err}")
        if name in dataset.coords and "_FillValue" in attrs:
            problems.append(f"{name}: coordinate with _FillValue")
        if variable.dims == (name,):
            values = np.asarray(variable.values)
            if values.dtype.kind not in "iuf":
                problems.append(f"{name}: coordinate variable of type {values.dtype}, expected numbers")
            elif values.size > 1 and not (np.all(np.diff(values) > 0) or np.all(np.diff(values) < 0)):
                problems.append(f"{name}: coordinate variable not strictly monotonic")
    return problems
