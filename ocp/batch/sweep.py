"""Parameter sweeps: the sweep file, and the list of tasks it expands to (plain problem data).

Sweep file (paths relative to it)::

    base: hussein2008.yaml          # the problem every task starts from
    mode: grid                      # grid (cartesian product) | zip (element-wise)
    vary:
      cost.alpha: [0.001, 0.004, 0.016]
      sensors[0].p0: [[10, 10], [10, -10]]

Every task's problem is validated before anything runs; an invalid key path or value is reported as one
line naming the sweep file and the key (exit 2 in the CLI).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field, field_validator

from ...core.config import ConfigError, StrictModel, load_config
from ...core.keypath import get_path, parse_key_path, set_path
from ..model import Structure
from ..problem import Problem, load_problem

__all__ = ["SweepSpec", "SweepTask", "load_sweep", "expand_sweep"]


class SweepSpec(StrictModel):
    """A sweep: base problem file, expansion mode and the values of each varied key path."""

    kind: Literal["sweep"] | None = Field(None, description="file kind (optional: a 'vary' key makes it a sweep)")
    base: str = Field(description="the base problem file, relative to the sweep file")
    mode: Literal["grid", "zip"] = "grid"
    vary: dict[str, list[Any]] = Field(min_length=1)

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
        return vary


@dataclass(frozen=True)
class SweepTask:
    """One point of the sweep: its id (problem hash), position, varied values and full problem data.

    ``structure`` identifies the NLP layout (problem structure and collocation grid): tasks warm-start
    each other only within one structure.
    """

    task: str
    index: int
    values: dict[str, Any]
    problem: dict[str, Any]
    structure: tuple[Any, str]

    def coordinates(self) -> np.ndarray:
        """The varied values flattened to numbers (for nearest-neighbour warm starts)."""
        flat: list[float] = []
        for value in self.values.values():
            flat.extend(float(v) for v in np.ravel(np.asarray(value, dtype=float)))
        return np.asarray(flat)


def load_sweep(path: str | Path) -> tuple[SweepSpec, Problem]:
    """Read a sweep file and its base problem (relative to the sweep file)."""
    spec = load_config(path, SweepSpec)
    base_path = (Path(path).parent / spec.base).resolve()
    if not base_path.exists():
        raise ConfigError(f"{path}: base: file not found: {base_path}")
    return spec, load_problem(base_path)


def expand_sweep(spec: SweepSpec, base: Problem, source: str = "<sweep>") -> list[SweepTask]:
    """All tasks of the sweep, each validated; raises :class:`ConfigError` naming the offending key."""
    data = base.normalised()
    for key in spec.vary:
        try:
            get_path(data, key)
        except KeyError as exc:
            raise ConfigError(f"{source}: vary.{key}: not a key of the problem: {exc.args[0]}") from None
    keys = list(spec.vary)
    columns = [spec.vary[k] for k in keys]
    if spec.mode == "zip":
        lengths = {k: len(v) for k, v in spec.vary.items()}
        if len(set(lengths.values())) > 1:
            raise ConfigError(f"{source}: vary: mode 'zip' needs lists of equal length, got {lengths}")
        combos = list(zip(*columns, strict=True))
    else:
        combos = list(itertools.product(*columns))
    tasks = []
    for index, combo in enumerate(combos):
        problem_data = data
        for key, value in zip(keys, combo, strict=True):
            problem_data = set_path(problem_data, key, value)
        problem_data["name"] = f"{base.name}_{index:04d}"
        try:
            problem = Problem.from_dict(problem_data, source=source)
        except ConfigError as exc:
            detail = str(exc).split(": ", 1)[1]
            raise ConfigError(
                f"{source}: vary (task {index}: {dict(zip(keys, combo, strict=True))}): {detail}"
            ) from None
        structure = (Structure.of(problem), problem.solver.collocation.model_dump_json())
        values = dict(zip(keys, combo, strict=True))
        tasks.append(SweepTask(problem.digest(), index, values, problem.normalised(), structure))
    return tasks
