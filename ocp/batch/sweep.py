"""Parameter sweeps: the sweep file, and the list of tasks it expands to (plain problem data).

Sweep file (paths relative to it)::

    base: hussein2008.yaml          # the problem every task starts from
    mode: grid                      # grid (cartesian product) | zip (element-wise)
    vary:
      cost.alpha: [0.001, 0.004, 0.016]
      sensors[0].p0: [[10, 10], [10, -10]]

Any value of the problem can be varied — numbers, lists, strings (``solver.collocation.scheme: [radau,
legendre]``), whole mappings (noise models) — and a sweep has at most :data:`MAX_TASKS` tasks (counted before
they are expanded). Every task's problem is validated before anything runs; an invalid key path or value is
reported as one line naming the sweep file and the key (exit 2 in the CLI).
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field, field_validator

from ...core.budget import PROCESS_BYTES, Estimate
from ...core.config import ConfigError, StrictModel
from ...core.errors import brief
from ...core.keypath import get_path, parse_key_path, with_values
from ...core.kinds import load_as
from ..model import Structure
from ..problem import Problem, load_problem, problem_digest
from ..sizes import problem_estimates, solution_bytes

__all__ = [
    "RESULT_COLUMNS",
    "MAX_TASKS",
    "SweepSpec",
    "SweepTask",
    "load_sweep",
    "expand_sweep",
    "iter_tasks",
    "task_count",
    "sweep_estimates",
    "warm_share",
    "WARM_SHARE",
    "sweep_digest",
    "value_coordinates",
]

#: columns of results.parquet after the task id, index and one column per varied key path
RESULT_COLUMNS = [
    "status",
    "cost",
    "terminal_cost",
    "running_cost",
    "iterations",
    "time_s",
    "solve_time_s",
    "worker",
    "error",
    "start",
    "transcription_cached",
    "solution_file",
    "warning",
]


#: most tasks of one sweep (expanding and validating one takes ~4 ms: 10⁵ tasks ≈ 7 minutes)
MAX_TASKS = 100_000


class SweepSpec(StrictModel):
    """A sweep: base problem file, expansion mode and the values of each varied key path."""

    kind: Literal["sweep"] | None = Field(None, description="file kind (optional: a 'vary' key makes it a sweep)")
    base: str = Field(min_length=1, max_length=4096, description="the base problem file, relative to the sweep file")
    mode: Literal["grid", "zip"] = "grid"
    vary: dict[str, list[Any]] = Field(min_length=1, max_length=64)

    @field_validator("vary")
    @classmethod
    def _well_formed(cls, vary: dict[str, list[Any]]) -> dict[str, list[Any]]:
        for key, values in vary.items():
            try:
                parse_key_path(key)
            except ValueError as exc:
                raise ValueError(f"{key}: {exc}") from None
            if len(values) == 0:
                raise ValueError(f"{key}: expected at least one value")
            if key.strip() == "name":  # expand_sweep names each task after the base problem and its index
                raise ValueError(f"{key}: the tasks are named by the sweep (base name and index); vary another key")
            if key.strip() in ("task", "index", *RESULT_COLUMNS):  # a row holds both under one column name
                raise ValueError(
                    f"{key}: also the name of a column of the results; vary the keys inside it ({key}.…) instead "
                    "(mode: zip to change several together)"
                )
        return vary


@dataclass(frozen=True)
class SweepTask:
    """One point of the sweep: its id (problem hash), position, varied values and full problem data.

    ``structure`` identifies the NLP layout (problem structure, method and its grid): tasks warm-start
    each other only within one structure. ``coords`` places the task's varied values in a space where the
    nearest finished task is found (see :func:`value_coordinates`).
    """

    task: str
    index: int
    values: dict[str, Any]
    problem: dict[str, Any]
    structure: tuple[Any, str, str]
    coords: np.ndarray = field(default_factory=lambda: np.zeros(0), compare=False)
    #: the validated problem (what ``problem`` holds), handed to the worker so that it is not validated twice
    model: Problem | None = field(default=None, compare=False, repr=False)

    def coordinates(self) -> np.ndarray:
        """The varied values as numbers (for nearest-neighbour warm starts), shape (D,)."""
        return self.coords

    def payload(self) -> dict[str, Any]:
        """What a worker solves (:func:`mobisense.ocp.batch.worker.solve_task`): the validated problem.

        A validated :class:`~mobisense.ocp.problem.Problem` unpickles in a quarter of the time its validation
        takes (0.06 against 0.23 ms), which a warm-started task (≈ 10 ms) pays on the worker.
        """
        return {"problem": self.model if self.model is not None else self.problem}


def load_sweep(path: str | Path) -> tuple[SweepSpec, Problem]:
    """Read a sweep file and its base problem (relative to the sweep file)."""
    spec = load_as(path, "sweep")
    base_path = Path(path).parent / spec.base
    if base_path.is_dir():
        raise ConfigError(f"{path}: base: {base_path} is a directory, expected the base problem file")
    if not base_path.exists():
        raise ConfigError(f"{path}: base: file not found: {base_path}")
    if base_path.resolve() == Path(path).resolve():
        raise ConfigError(f"{path}: base: expected the base problem file, got this sweep file itself")
    try:
        return spec, load_problem(base_path)
    except ConfigError as err:  # the base's own error, under the key that named it (as a replan file's problem:)
        raise ConfigError(f"{path}: base: {err}") from None


def task_count(spec: SweepSpec, source: str = "<sweep>") -> int:
    """How many tasks ``spec`` expands to, without expanding it; ``ConfigError`` beyond :data:`MAX_TASKS`."""
    lengths = {k: len(v) for k, v in spec.vary.items()}
    if spec.mode == "zip":
        if len(set(lengths.values())) > 1:
            raise ConfigError(f"{source}: vary: mode 'zip' needs lists of equal length, got {lengths}")
        count = next(iter(lengths.values()))
    else:
        count = math.prod(lengths.values())
    if count > MAX_TASKS:
        raise ConfigError(
            f"{source}: vary: {count:.3g} tasks ({' × '.join(map(str, lengths.values()))}) is more than the "
            f"{MAX_TASKS} a sweep may have; split it into several sweeps or use fewer values"
        )
    return count


def sweep_estimates(
    spec: SweepSpec,
    base: Problem,
    local_workers: int,
    source: str = "<sweep>",
    tasks: list[SweepTask] | None = None,
) -> list[Estimate]:
    """Memory and time of a sweep: its tasks and results in this process, the local workers' solves.

    Before the tasks are expanded (``tasks`` None) the workers' part is the base problem's; with the expanded
    ``tasks`` it is that of the largest of their problem structures (a varied value can change the grid, the
    sensors or the method: ``solver.collocation.intervals: [100000]`` needs 51 GiB where the base needs 10 MB),
    and the time the sum over the tasks.
    """
    count = task_count(spec, source)
    per_task = 8 * len(json.dumps(base.normalised())) + 8 * len(json.dumps(spec.vary)) / max(1, count) + 2048
    if tasks:
        by_structure: dict[Any, list[SweepTask]] = {}
        for task in tasks:
            by_structure.setdefault(task.structure, []).append(task)
        problems = {k: group[0].model or Problem.from_dict(group[0].problem) for k, group in by_structure.items()}
        solves = {k: _solve_estimate(problem) for k, problem in problems.items()}
        key = max(solves, key=lambda k: solves[k].bytes)
        worker, result_bytes = solves[key], solution_bytes(problems[key])
        seconds = sum(solves[k].seconds * warm_share(len(group)) for k, group in by_structure.items())
    else:
        worker = _solve_estimate(base)
        seconds = worker.seconds * warm_share(count)
        result_bytes = solution_bytes(base)
    return [
        Estimate(f"the sweep's {count} tasks", count * per_task, "use fewer values or split the sweep"),
        Estimate(
            f"{local_workers} local worker processes, each solving {worker.what}",
            local_workers * (PROCESS_BYTES + worker.bytes + result_bytes),
            worker.hint + "; or fewer --workers",
        ),
        Estimate(
            f"the sweep's {count} solves on " + (f"{local_workers} local worker{'s' * (local_workers > 1)}"
                                                  if local_workers else "the cluster's workers"),
            0.0,
            "use fewer values, split the sweep, or run it on a cluster (--scheduler)",
            seconds / local_workers if local_workers else 0.0,
        ),
    ]


#: a warm-started task's share of a cold solve's time (warm starts pass between tasks of one NLP structure)
WARM_SHARE = 0.2


def warm_share(tasks: int) -> float:
    """Cold solves' worth of ``tasks`` tasks of one structure: the first cold, the others warm (:data:`WARM_SHARE`).

    Counting every task at a fifth let a sweep over ``solver.method: [shooting, direct]`` of a 3 × 3 field pass
    ``--max-time 10s`` and run 4 min 52 s: its direct task, estimated alone at ≥ 50 s, has no neighbour to start from.
    """
    return 1.0 + WARM_SHARE * (tasks - 1) if tasks > 0 else 0.0


def _solve_estimate(problem: Problem) -> Estimate:
    """One solve of ``problem`` by its method: the largest part's memory, every part's time (``both``: two)."""
    parts = problem_estimates(problem)
    largest = max(parts, key=lambda e: e.bytes)
    return Estimate(largest.what, largest.bytes, largest.hint, sum(e.seconds for e in parts))


def expand_sweep(spec: SweepSpec, base: Problem, source: str = "<sweep>") -> list[SweepTask]:
    """All tasks of the sweep, each validated; raises :class:`ConfigError` naming the offending key."""
    tasks = list(iter_tasks(spec, base, source))
    coords = value_coordinates([t.values for t in tasks])
    return [replace(t, coords=c) for t, c in zip(tasks, coords, strict=True)]


def iter_tasks(spec: SweepSpec, base: Problem, source: str = "<sweep>") -> Iterator[SweepTask]:
    """The tasks of the sweep one at a time, each validated (without ``coords``): what :func:`expand_sweep` lists.

    ``mobisense validate`` counts them this way, so that validating a sweep of :data:`MAX_TASKS` tasks holds
    one task in memory at a time, not all of them. Raises :class:`ConfigError` naming the offending key.
    """
    task_count(spec, source)
    data = base.normalised()
    for key in spec.vary:
        try:
            get_path(data, key)
        except KeyError as exc:
            raise ConfigError(f"{source}: vary.{key}: not a key of the problem: {exc.args[0]}") from None
    keys = list(spec.vary)
    columns = [spec.vary[k] for k in keys]
    combos = zip(*columns, strict=True) if spec.mode == "zip" else itertools.product(*columns)
    for index, combo in enumerate(combos):
        values = dict(zip(keys, combo, strict=True))
        # shares all but the varied values with ``data``: only validated, never changed
        problem_data = with_values(data, {**values, "name": f"{base.name[:100]}_{index:04d}"})
        try:
            problem = Problem.from_dict(problem_data, source=source)
        except ConfigError as exc:
            detail = str(exc).split(": ", 1)[1]
            shown = ", ".join(f"{k}: {brief(v, 40)}" for k, v in values.items())
            raise ConfigError(f"{source}: vary (task {index}: {{{shown}}}): {detail}") from None
        solver = problem.solver  # a shooting grid or a collocation one: tasks of another method start no warm solve
        grid = solver.shooting if solver.method == "shooting" else solver.collocation
        structure = (Structure.of(problem), solver.method, grid.model_dump_json())
        normalised = problem.normalised()
        yield SweepTask(problem_digest(normalised), index, values, normalised, structure, model=problem)


def sweep_digest(tasks: list[SweepTask]) -> str:
    """SHA-256 (hex, 16 chars) of a sweep's tasks in order: equal iff the same problems are solved."""
    text = "\n".join(f"{t.index}:{t.task}" for t in tasks)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _leaves(value: Any, prefix: str = "") -> dict[str, Any]:
    """``{path: scalar}`` of a nested value: ``{"beta": 5, "p": [1, 2]}`` -> ``{".beta": 5, ".p[0]": 1, …}``."""
    if isinstance(value, dict):
        return {k: v for key, item in value.items() for k, v in _leaves(item, f"{prefix}.{key}").items()}
    if isinstance(value, list):
        return {k: v for i, item in enumerate(value) for k, v in _leaves(item, f"{prefix}[{i}]").items()}
    return {prefix: value}


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


#: categorical values with up to this many distinct values get one 0/1 dimension each
_ONE_HOT = 16


def value_coordinates(values: list[dict[str, Any]]) -> list[np.ndarray]:
    """Numbers for the varied values of each task, for nearest-neighbour warm starts; any YAML values.

    Each scalar inside a varied value (a number, or an entry of a list or mapping) is one dimension when it
    is a number in every task that has it (plus a 0/1 dimension marking the tasks without it); any other
    scalar — strings, booleans, null, a number in some tasks only — becomes one 0/1 dimension per distinct
    value (or, beyond 16 distinct values, one dimension holding the value's rank). Tasks of different
    structure never warm-start each other anyway (see :class:`SweepTask`).
    """
    flat = [{f"{key}{path}": leaf for key, value in v.items() for path, leaf in _leaves(value).items()} for v in values]
    paths = sorted({path for row in flat for path in row})
    dims: list[np.ndarray] = []
    for path in paths:
        present = [path in row for row in flat]
        items = [row.get(path) for row in flat]
        if all(_is_number(x) for x, here in zip(items, present, strict=True) if here):
            dims.append(np.array([float(x) if here else 0.0 for x, here in zip(items, present, strict=True)]))
            if not all(present):
                dims.append(np.array([float(here) for here in present]))
            continue
        labels = [json.dumps(x, sort_keys=True) if here else "" for x, here in zip(items, present, strict=True)]
        distinct = sorted(set(labels))
        if len(distinct) <= _ONE_HOT:
            dims += [np.array([float(label == other) for other in labels]) for label in distinct]
        else:  # many categories: their rank, so that the coordinates stay (tasks × a few)
            rank = {label: i for i, label in enumerate(distinct)}
            dims.append(np.array([float(rank[label]) for label in labels]))
    if not dims:
        return [np.zeros(1) for _ in values]
    matrix = np.stack(dims, axis=1)
    return list(matrix)
