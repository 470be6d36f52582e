"""Reading a ``solution.nc`` safely: a missing, oversized or non-netCDF file is a one-line ``ConfigError``.

Sizes are bounded before anything is allocated: the file on disk, then the arrays its variables declare (read from
the HDF5 metadata, before xarray reads a value: a file of a few kB can declare arrays of any size) against the
memory budget (:func:`mobisense.core.budget.default_memory_limit`). The shapes, times and values a solution must
have for its stored problem are checked by :func:`mobisense.ocp.solution_dataset.check_layout` and
:func:`~mobisense.ocp.solution_dataset.check_values`.
"""

from __future__ import annotations

import operator
from collections.abc import Iterator
from contextlib import contextmanager
from functools import cache
from pathlib import Path
from typing import Any

from ..core.errors import ConfigError, brief, one_line
from ..core.input_text import missing_file
from .problem import Problem

__all__ = ["brief_error", "open_solution_file", "read_solution_problem"]


def brief_error(exc: BaseException) -> str:
    """``Type: message`` of an exception on one line, at most 120 characters."""
    return one_line(f"{type(exc).__name__}: {exc}", 120)


@contextmanager
def open_solution_file(path: str | Path, task: int | None = None) -> Iterator[tuple[Any, Path]]:
    """Open a solution netCDF lazily: refuse a missing file, a file larger than the memory budget, non-netCDF data.

    The arrays the file declares (all its variables, whatever was written of them) must fit the memory budget
    too; nothing is read before that is known. A sweep's file of several tasks (``tasks/part-NNNNNN.nc``,
    :mod:`mobisense.ocp.task_files`) needs ``task``, the sweep index of the one to read; its dataset is then that
    task's ``solution.nc``.
    """
    import xarray as xr

    from ..core.budget import default_memory_limit, format_bytes
    from ..core.netcdf import check_signature

    path = Path(path)
    if path.is_dir():
        if not (path / "solution.nc").is_file():
            raise ConfigError(f"{path}: is a folder without a solution.nc (write one with mobisense solve)")
        path = path / "solution.nc"
    if not path.is_file():
        raise ConfigError(f"{path}: {missing_file(path)}")
    size, limit = path.stat().st_size, default_memory_limit()
    if size > limit:
        raise ConfigError(f"{path}: {format_bytes(size)} is more than the memory budget allows to load")
    try:
        magic = check_signature(path)
        declared = _declared_arrays(path) if magic.startswith(b"\x89HDF") else None
    except (OSError, ValueError, TypeError, KeyError, RuntimeError) as exc:
        raise ConfigError(f"{path}: not a netCDF solution written by mobisense solve ({brief_error(exc)})") from None
    if declared is not None and declared[0] > limit:
        total, name, shape = declared
        raise ConfigError(
            f"{path}: {name}: expected arrays that fit the memory budget ({format_bytes(limit)}), got shape "
            f"{shape} ({format_bytes(total)} declared by the file's variables in all)"
        )
    try:
        ds = xr.open_dataset(path, engine="h5netcdf", decode_timedelta=False, phony_dims="access", **_lazy_indexes())
    except (OSError, ValueError, TypeError, KeyError, RuntimeError) as exc:
        raise ConfigError(f"{path}: not a netCDF solution written by mobisense solve ({brief_error(exc)})") from None
    with ds:
        yield _one_task(ds, path, task), path


@cache
def _lazy_indexes() -> dict[str, Any]:
    """``create_default_indexes=False`` where xarray has it: opening then reads no coordinate's values."""
    import inspect

    import xarray as xr

    if "create_default_indexes" in inspect.signature(xr.open_dataset).parameters:
        return {"create_default_indexes": False}
    return {}


def _declared_arrays(path: Path) -> tuple[int, str, tuple[int, ...]]:
    """Bytes of all the arrays an HDF5 file declares (its datasets' shapes × item sizes), the largest one and its shape.

    Read from the file's metadata only (h5py reads no data): a chunked dataset declares its shape whatever was
    written of it, and xarray would allocate all of it.
    """
    import h5py

    total, largest = 0, (-1, "", ())

    def visit(name: str, obj: Any) -> None:
        nonlocal total, largest
        if isinstance(obj, h5py.Dataset):
            shape = tuple(int(n) for n in (obj.shape or ()))
            count = 1
            for n in shape:
                count *= n
            nbytes = count * int(obj.dtype.itemsize)
            total += nbytes
            if nbytes > largest[0]:
                largest = (nbytes, name, shape)

    with h5py.File(path, "r") as f:
        f.visititems(visit)
    return total, largest[1], largest[2]


def _one_task(ds: Any, path: Path, task: int | None) -> Any:
    from .task_files import is_stacked, task_dataset

    if not is_stacked(ds):
        if task is not None:
            raise ConfigError(f"{path}: task: {task} given, but the file holds one solution, not a sweep's tasks")
        return ds
    if task is None:
        held = ", ".join(str(int(i)) for i in ds["task"].values[:8])
        raise ConfigError(f"{path}: holds several tasks of a sweep ({held}, …); name one (task: INDEX)")
    try:
        if isinstance(task, bool):
            raise TypeError
        index = operator.index(task)
    except TypeError:
        raise ConfigError(
            f"{path}: task: expected the task's sweep index, an integer (the index column of results.parquet; its "
            f"task column is the problem hash), got {brief(task)}"
        ) from None
    try:
        return task_dataset(ds, index)  # reads that task's part of every variable only
    except KeyError as exc:
        if str(exc.args[0]).startswith(f"task {index} "):
            raise ConfigError(f"{path}: task: {exc.args[0]}") from None
        raise ConfigError(f"{path}: not a sweep's task file written by mobisense sweep ({brief_error(exc)})") from None
    except (ValueError, TypeError, IndexError, AttributeError, OSError, RuntimeError) as exc:
        raise ConfigError(f"{path}: not a sweep's task file written by mobisense sweep ({brief_error(exc)})") from None


def read_solution_problem(path: str | Path, task: int | None = None) -> Problem:
    """The problem stored in a ``solution.nc`` (its ``problem_yaml`` attribute), without loading the arrays.

    The file's variables must have the dimensions a solution of that problem has
    (:func:`~mobisense.ocp.solution_dataset.check_layout`, read from the metadata); ``task`` picks one task of a
    sweep's ``tasks/part-NNNNNN.nc``.
    """
    from .solution_dataset import check_layout, stored_problem

    with open_solution_file(path, task) as (ds, where):
        try:
            problem = stored_problem(ds, str(where))
            check_layout(ds, problem, str(where))
        except ConfigError:
            raise
        except (KeyError, ValueError, TypeError, IndexError, AttributeError, OSError, RuntimeError) as exc:
            raise ConfigError(f"{where}: not a solution written by mobisense solve ({brief_error(exc)})") from None
    return problem
