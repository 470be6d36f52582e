"""The solutions of a sweep's tasks, many to a file: ``tasks/part-NNNNNN.nc`` with a ``task`` dimension.

One HDF5 file per task costs more than a warm-started solve (creating a file and its ~20 datasets: 0.1–0.4 s
against ≈ 10 ms of Ipopt), so the tasks finished between two flushes of the results are written as one file,
each of their ``solution.nc`` datasets stacked along a leading ``task`` dimension (one file per set of
equally shaped datasets). In that file

* ``task`` (coordinate) is the task's index in the sweep (the ``index`` column of ``results.parquet``) and
  ``task_id`` its problem hash (the ``task`` column); ``results.parquet`` names each task's file in its
  ``solution_file`` column (relative to the sweep folder);
* every variable of ``solution.nc`` keeps its name, attributes and dimensions, with ``task`` in front; an index
  coordinate whose values differ between the tasks (``time`` when the horizon is varied) is the variable
  ``<name>_of_task`` (task, <name>); coordinates equal in all tasks (sensor names, ``xy``) stay shared;
* the global attributes of each task's dataset (its problem YAML, costs, status, solver statistics) are the JSON
  string ``task_attrs`` (task,).

:func:`task_dataset` cuts one task's dataset back out — identical to what ``solution.nc`` held — and
:func:`mobisense.ocp.solution.Solution.load` with ``task=INDEX`` reads it as a Solution (``mobisense replay``:
``solution: OUT/tasks/part-000001.nc`` with ``task: INDEX``).
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from ..core.netcdf_writer import DatasetContent

__all__ = ["TASK_DIM", "TASKS", "stack_tasks", "task_dataset", "shape_key", "is_stacked", "write_task_files",
           "remove_unlisted", "lost_solutions"]

#: the folder of the task files inside a sweep folder
TASKS = "tasks"
_PART = re.compile(r"^part-(\d{6})\.nc$")

#: the leading dimension of a file of several tasks
TASK_DIM = "task"
_OF_TASK = "_of_task"
_META = "mobisense_stacked_json"


def shape_key(dataset: Any) -> tuple[Any, ...]:
    """Datasets with equal keys stack into one file: names, dimensions, shapes and attributes of the variables.

    ``dataset`` is an ``xarray.Dataset`` or a :class:`~mobisense.core.netcdf_writer.DatasetContent`.
    """
    return _key(_parts(dataset)[0])


def _key(variables: dict[str, Any]) -> tuple[Any, ...]:
    return tuple(
        (name, dims, values.shape, values.dtype.kind, _attrs_key(attrs))
        for name, (dims, values, attrs) in sorted(variables.items())
    )


def _attrs_key(attrs: dict[str, Any]) -> Any:
    """A comparable stand-in for a variable's attributes: its (name, text) pairs, or their JSON if not all text.

    A solution's variables carry text attributes only (``long_name``, ``units``); the pairs compare as the JSON
    text did, at a fraction of its cost (a sweep computes one key per task and variable at every flush).
    """
    if all(type(v) is str for v in attrs.values()):
        return tuple(sorted(attrs.items()))
    return json.dumps(attrs, sort_keys=True, default=str)


def _parts(dataset: Any) -> tuple[dict[str, Any], set[str], dict[str, Any]]:
    """``(variables: name -> (dims, values, attrs), coordinate names, global attributes)`` of either kind."""
    if isinstance(dataset, DatasetContent):
        table = {**dataset.data_vars, **dataset.coords}
        variables = {str(k): (tuple(d), np.asarray(v), a) for k, (d, v, a) in table.items()}
        return variables, set(dataset.coords), dict(dataset.attrs)
    variables = {str(k): (tuple(v.dims), v.values, dict(v.attrs)) for k, v in dataset.variables.items()}
    return variables, {str(c) for c in dataset.coords}, dict(dataset.attrs)


def is_stacked(dataset: Any) -> bool:
    """Whether a dataset read from a file holds several tasks (see the module notes)."""
    return _META in dataset.attrs


def stack_tasks(datasets: list[Any], indices: list[int], task_ids: list[str]) -> DatasetContent:
    """Stack equally shaped ``solution.nc`` datasets (same :func:`shape_key`) along ``task``.

    Parameters
    ----------
    datasets : list of DatasetContent or xarray.Dataset
        One per task, as :meth:`mobisense.ocp.solution.Solution.to_content` (or ``to_dataset``) returns them.
    indices : list of int
        The tasks' indices in the sweep (the ``task`` coordinate).
    task_ids : list of str
        The tasks' problem hashes (``task_id``).

    Returns
    -------
    DatasetContent
        The stacked file's content (``.to_xarray()`` for a Dataset); built without importing xarray.
    """
    parts = [_parts(ds) for ds in datasets]
    key = _key(parts[0][0])
    if any(_key(variables) != key for variables, _, _ in parts[1:]):
        raise ValueError("stack_tasks: the datasets differ in their variables or shapes")
    return _stack(parts, indices, task_ids)


def _stack(parts: list[Any], indices: list[int], task_ids: list[str]) -> DatasetContent:
    """:func:`stack_tasks` of datasets given as their :func:`_parts`, known to have one shape key."""
    first, coord_names, _ = parts[0]
    index_dims = {name for name, (dims, _, _) in first.items() if dims == (name,)}
    out = DatasetContent()
    index_attrs = {"long_name": "index of the task in the sweep", "units": "1"}
    out.add_coord(TASK_DIM, (TASK_DIM,), np.asarray(indices, np.int64), index_attrs)
    coordinates, renamed = [], []
    for name, (dims, _, attrs) in first.items():
        values = [variables[name][1] for variables, _, _ in parts]
        is_coord = name in coord_names
        if is_coord and all(np.array_equal(values[0], v) for v in values[1:]):
            out.add_coord(name, dims, values[0], attrs)  # shared by every task
            continue
        if is_coord:
            coordinates.append(name)
        if name in index_dims:  # an index coordinate cannot have two dimensions: renamed
            renamed.append(name)
            out.add_variable(name + _OF_TASK, (TASK_DIM, *dims), np.stack(values), attrs)
        else:
            out.add_variable(name, (TASK_DIM, *dims), np.stack(values), attrs)
    out.add_variable("task_id", (TASK_DIM,), np.asarray(task_ids, dtype=str), {"long_name": "problem hash of the task"})
    text = [json.dumps({k: _plain(v) for k, v in attrs.items()}) for _, _, attrs in parts]
    described = {"long_name": "global attributes of the task's solution.nc (JSON)"}
    out.add_variable("task_attrs", (TASK_DIM,), np.asarray(text, dtype=str), described)
    meta = {"coordinates": coordinates, "renamed": renamed}
    out.attrs.update({"title": f"mobisense: solutions of {len(parts)} sweep tasks", _META: json.dumps(meta)})
    return out


def task_dataset(stacked: Any, index: int) -> Any:
    """The ``solution.nc`` dataset of the task with sweep index ``index`` in a file of several tasks.

    Raises ``KeyError`` (naming the indices held) when the file does not hold that task.
    """
    import xarray as xr

    held = [int(i) for i in stacked[TASK_DIM].values]
    if index not in held:
        shown = ", ".join(map(str, held[:12])) + (" …" if len(held) > 12 else "")
        raise KeyError(f"task {index} is not in this file (it holds tasks {shown})")
    meta = json.loads(stacked.attrs[_META])
    one = stacked.isel({TASK_DIM: held.index(index)})
    data, coords = {}, {}
    for name, var in one.variables.items():
        name = str(name)
        if name in (TASK_DIM, "task_id", "task_attrs"):
            continue
        base = name[: -len(_OF_TASK)]
        original = base if name.endswith(_OF_TASK) and base in meta["renamed"] else name
        entry = (var.dims, var.values, dict(var.attrs))
        if name in stacked.coords or original in meta["coordinates"]:
            coords[original] = entry
        else:
            data[original] = entry
    own = json.loads(str(one["task_attrs"].values))
    attrs = {k: stacked.attrs[k] for k in ("Conventions", "history", "source") if k in stacked.attrs}
    if "Conventions" in attrs:  # as the task's own file would have it (mobisense.core.netcdf.prepare)
        attrs["title"] = own.get("title") or "mobisense output"
    attrs.update(own)
    return xr.Dataset(data, coords=coords, attrs=attrs)


def write_task_files(folder: Path, rows: list[dict[str, Any]], datasets: list[Any]) -> None:
    """Write the ``datasets`` of finished tasks as new ``tasks/part-NNNNNN.nc`` files; set each row's ``solution_file``.

    ``rows[k]`` (with ``index`` and ``task``) belongs to ``datasets[k]`` (``None``: the task has no solution, an
    error row). Tasks whose datasets have the same :func:`shape_key` share a file.
    """
    from ..core.files import write_netcdf

    groups: dict[tuple[Any, ...], list[int]] = {}
    parts = {k: _parts(ds) for k, ds in enumerate(datasets) if ds is not None}
    for k, (variables, _, _) in parts.items():
        groups.setdefault(_key(variables), []).append(k)
    folder = Path(folder) / TASKS
    number = max((int(m.group(1)) for p in folder.glob("part-*.nc") if (m := _PART.match(p.name))), default=0)
    for members in groups.values():
        number += 1
        name = f"part-{number:06d}.nc"
        stacked = _stack([parts[k] for k in members], [int(rows[k]["index"]) for k in members],
                         [str(rows[k]["task"]) for k in members])  # fmt: skip
        try:  # numbers and string indices: written without xarray
            write_netcdf(folder / name, stacked)
        except TypeError:  # strings stacked along task (task_id, task_attrs, a label that varies): through xarray
            write_netcdf(folder / name, stacked.to_xarray())
        for k in members:
            rows[k]["solution_file"] = f"{TASKS}/{name}"


def remove_unlisted(folder: Path, rows: Iterable[dict[str, Any]]) -> None:
    """Delete the task files no row names (left by a run killed between a file and its rows)."""
    listed = {str(r.get("solution_file")) for r in rows}
    for path in (Path(folder) / TASKS).glob("part-*.nc"):
        if _PART.match(path.name) and f"{TASKS}/{path.name}" not in listed:
            path.unlink(missing_ok=True)


def lost_solutions(folder: Path, rows: Iterable[dict[str, Any]]) -> dict[str, str]:
    """The finished rows whose solution is gone: task id -> why (its file missing, unreadable or without it).

    A row's ``solution_file`` must be a regular file under ``tasks/`` (not a link) that HDF5 opens and whose
    ``task`` coordinate holds the row's index; the files are opened once each, only the coordinate is read.
    Rows without a ``solution_file`` (an error row, or a folder of an earlier version) are not checked.
    """
    import h5py

    by_file: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        if row.get("solution_file"):
            by_file.setdefault(str(row["solution_file"]), []).append(row)
    lost: dict[str, str] = {}
    for name, members in by_file.items():
        path = Path(folder) / name
        indices: set[int] = set()
        if not _PART.match(path.name) or path.parent.name != TASKS or path.is_symlink() or not path.is_file():
            why = f"{name} is missing"
        else:
            try:
                with h5py.File(path, "r") as f:
                    indices = {int(i) for i in np.asarray(f[TASK_DIM][()]).ravel()}
                why = f"{name} does not hold it"
            except Exception as exc:  # noqa: BLE001  (h5py raises many kinds for a damaged file)
                why = f"{name} is unreadable ({type(exc).__name__})"
        for row in members:
            if int(row["index"]) not in indices:
                lost[str(row["task"])] = why
    return lost


def _plain(value: Any) -> Any:
    return value.item() if isinstance(value, np.generic) else value
