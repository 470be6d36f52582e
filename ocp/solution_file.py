"""Reading a ``solution.nc`` safely: a missing, oversized or non-netCDF file is a one-line ``ConfigError``."""

from __future__ import annotations

import operator
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from ..core.errors import ConfigError, brief, one_line
from ..core.reader import parse_document
from .problem import Problem

__all__ = ["brief_error", "open_solution_file", "read_solution_problem"]


def brief_error(exc: BaseException) -> str:
    """``Type: message`` of an exception on one line, at most 120 characters."""
    return one_line(f"{type(exc).__name__}: {exc}", 120)


@contextmanager
def open_solution_file(path: str | Path, task: int | None = None) -> Iterator[tuple[Any, Path]]:
    """Open a solution netCDF lazily: refuse a missing file, a file larger than the memory budget, non-netCDF data.

    A sweep's file of several tasks (``tasks/part-NNNNNN.nc``, :mod:`mobisense.ocp.task_files`) needs
    ``task``, the sweep index of the one to read; its dataset is then that task's ``solution.nc``.
    """
    import xarray as xr

    from ..core.budget import default_memory_limit, format_bytes

    path = Path(path)
    if path.is_dir():
        path = path / "solution.nc"
    if not path.is_file():
        raise ConfigError(f"{path}: file not found")
    size = path.stat().st_size
    if size > default_memory_limit():
        raise ConfigError(f"{path}: {format_bytes(size)} is more than the memory budget allows to load")
    try:
        with open(path, "rb") as f:
            magic = f.read(8)
        if not magic.startswith((b"\x89HDF\r\n\x1a\n", b"CDF")):
            raise ValueError("neither HDF5 nor netCDF data")
        ds = xr.open_dataset(path, engine="h5netcdf")
    except (OSError, ValueError, TypeError, KeyError, RuntimeError) as exc:
        raise ConfigError(f"{path}: not a netCDF solution written by mobisense solve ({brief_error(exc)})") from None
    with ds:
        yield _one_task(ds, path, task), path


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
        return task_dataset(ds.load(), index)
    except KeyError as exc:
        raise ConfigError(f"{path}: task: {exc.args[0]}") from None


def read_solution_problem(path: str | Path, task: int | None = None) -> Problem:
    """The problem stored in a ``solution.nc`` (its ``problem_yaml`` attribute), without loading the arrays."""
    with open_solution_file(path, task) as (ds, where):
        if "problem_yaml" not in ds.attrs:
            raise ConfigError(f"{where}: not a solution written by mobisense solve (no problem_yaml attribute)")
        text = str(ds.attrs["problem_yaml"])
    return Problem.from_dict(parse_document(text, f"{where}:problem_yaml"), source=f"{where}:problem_yaml")
