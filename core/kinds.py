"""The kinds of input file, each with its schema, its command and its shape: one registry for all of them.

A file says what it is with a top-level ``kind:`` key (optional for problem files), or is recognised by
its shape (:func:`detect_kind`: a problem has ``process``/``sensors``, a sweep ``vary``, …). The
``validate`` and ``schema`` commands and the file reference of the documentation read :data:`FILE_KINDS`;
each entry names its pydantic model and the function that validates a file completely (files it refers
to included) and says in one line what it is, as ``"module:name"`` strings, imported when used (so
this registry, like the command registry, imports nothing from the packages above ``core``).
"""

from __future__ import annotations

import difflib
import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = [
    "FileKind",
    "FILE_KINDS",
    "detect_kind",
    "apparent_kind",
    "check_command_kind",
    "load_as",
    "kind_model",
    "check_file",
    "load_target",
]


@dataclass(frozen=True)
class FileKind:
    """One kind of input file.

    Attributes
    ----------
    name : str
        The value of its ``kind:`` key.
    title : str
        What it is, in words.
    command : str
        The command that runs it.
    model : str
        ``"module:Class"`` of its pydantic model (the JSON Schema is generated from it).
    check : str
        ``"module:function"`` ``(data, path, kind) -> str``: validates the whole file (files it names too)
        and returns one line describing it; raises :class:`~mobisense.core.config.ConfigError`.
    shape : callable
        ``data -> bool``: whether a file without ``kind:`` has this kind's shape.
    variants : dict
        Polymorphic parts of the schema: JSON path (``"$defs/NoiseModel"``, ``"properties/motion"``) ->
        ``(discriminating key, "module:REGISTRY")``, a mapping of names to the models a value may be.
    """

    name: str
    title: str
    command: str
    model: str
    check: str
    shape: Callable[[dict[str, Any]], bool]
    variants: dict[str, tuple[str, str]] = field(default_factory=dict)


FILE_KINDS: dict[str, FileKind] = {
    kind.name: kind
    for kind in (
        FileKind("problem", "optimal-control problem", "mobisense solve", "mobisense.ocp.problem:Problem",
                 "mobisense.ocp.commands:check_problem", lambda d: "process" in d or "sensors" in d,
                 {"$defs/NoiseModel": ("model", "mobisense.ocp.registries:NOISE_MODELS")}),
        FileKind("sweep", "parameter sweep", "mobisense sweep", "mobisense.ocp.batch.sweep:SweepSpec",
                 "mobisense.ocp.commands:check_sweep", lambda d: "vary" in d),
        FileKind("formation", "steady-state formation design", "mobisense steady-state",
                 "mobisense.estimation.cooperative.design_study:FormationFile",
                 "mobisense.estimation.commands:check_formation",
                 lambda d: "bounds" in d or "positions" in d or isinstance(d.get("formation"), str)),
        FileKind("field_replay", "field replay (formation on a field)", "mobisense replay",
                 "mobisense.formation.replay.scenario:FieldReplayScenario",
                 "mobisense.formation.commands:check_scenario",
                 lambda d: "motion" in d or ("field" in d and "platforms" in d),
                 {"properties/formation": ("kind", "mobisense.formation.replay.scenario:FORMATIONS"),
                  "properties/motion": ("kind", "mobisense.formation.replay.scenario:MOTIONS")}),
        FileKind("plan_replay", "plan replay (optimised plan flown, Monte Carlo check)", "mobisense replay",
                 "mobisense.formation.replay.plan:OcpReplayScenario", "mobisense.formation.commands:check_scenario",
                 lambda d: "solution" in d),
        FileKind("leader_follower", "leader–follower simulation", "mobisense simulate leader-follower",
                 "mobisense.formation.leader_follower.scenario:LeaderFollowerScenario",
                 "mobisense.formation.commands:check_scenario", lambda d: "leader" in d or "followers" in d),
        FileKind("distributed", "distributed-filter simulation", "mobisense simulate distributed",
                 "mobisense.formation.distributed.simulation:DistributedScenario",
                 "mobisense.formation.commands:check_scenario",
                 lambda d: "network" in d or ("field" in d and "platforms" not in d and "motion" not in d)),
        FileKind("replan", "plan, fly, re-plan under a current (Monte Carlo vs open loop)", "mobisense replay",
                 "mobisense.formation.replay.replan:ReplanScenario", "mobisense.formation.commands:check_scenario",
                 lambda d: "replan" in d),
    )
}  # fmt: skip


def load_target(target: str) -> Any:
    """The object named by ``"module:name"`` (imported now)."""
    module_name, _, name = target.partition(":")
    return getattr(importlib.import_module(module_name), name)


def kind_model(kind: str) -> Any:
    """The pydantic model class of a file kind."""
    return load_target(FILE_KINDS[kind].model)


def detect_kind(data: Any, source: str | Path) -> str:
    """The kind of a parsed YAML document: its ``kind:`` key, or the one kind whose shape it has.

    Raises
    ------
    ConfigError
        Not a mapping, an unknown ``kind``, or a shape that fits no kind or several.
    """
    from .config import ConfigError  # here: listing the kinds (``--help``) must not import pydantic
    from .errors import brief

    if data is None:
        raise ConfigError(f"{source}: (top level): the file is empty; expected a mapping of keys")
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: (top level): expected a mapping of keys, got {type(data).__name__}")
    names = sorted(FILE_KINDS)
    if "kind" in data:
        kind = data["kind"]
        if isinstance(kind, str) and kind in FILE_KINDS:
            return kind
        hint = difflib.get_close_matches(kind[:100], names, n=1) if isinstance(kind, str) else []
        suggestion = f"; did you mean '{hint[0]}'?" if hint else ""
        expected = ", ".join(names)
        raise ConfigError(f"{source}: kind: unknown file kind {brief(kind)}{suggestion} (expected one of {expected})")
    fits = [name for name, kind in FILE_KINDS.items() if kind.shape(data)]
    if len(fits) == 1:
        return fits[0]
    which = "fits several kinds (" + ", ".join(fits) + ")" if fits else "fits no kind"
    raise ConfigError(f"{source}: (top level): the file {which}; add 'kind: …' (one of {', '.join(names)})")


def apparent_kind(data: Any) -> str | None:
    """The kind a parsed document says it is (a known ``kind:``) or has the shape of (one kind only); else None."""
    if not isinstance(data, dict):
        return None
    kind = data.get("kind")
    if "kind" in data:
        return kind if isinstance(kind, str) and kind in FILE_KINDS else None
    fits = [name for name, file_kind in FILE_KINDS.items() if file_kind.shape(data)]
    return fits[0] if len(fits) == 1 else None


def check_command_kind(data: Any, source: str | Path, expected: tuple[str, ...]) -> None:
    """Refuse a file that is plainly of another kind than a command runs, naming the command that runs it.

    A file given to the wrong command (``mobisense steady-state hussein2008``) would otherwise be reported by
    the model it does not follow ("noise: required key is missing (and 6 more problems)"). It is plainly
    another kind when its ``kind:`` key says so, or when it has the shape of no ``expected`` kind and of
    exactly one other (:func:`apparent_kind`); anything less clear is left to the model's own report.

    Raises
    ------
    ConfigError
        ``FILE: kind: …`` or ``FILE: (top level): …``, saying what the file looks like and which command runs it.
    """
    from .config import ConfigError

    found = apparent_kind(data)
    if found is None or found in expected:
        return
    title = FILE_KINDS[found].title
    what = f"{'an' if title[0] in 'aeiou' else 'a'} {title} file"
    names = ", ".join(expected[:-1]) + (" or " if len(expected) > 1 else "") + expected[-1]
    advice = f"run it with '{FILE_KINDS[found].command} {source}' (this reads {names} files)"
    if "kind" in data:
        raise ConfigError(f"{source}: kind: {what}; {advice}")
    if any(FILE_KINDS[e].shape(data) for e in expected):
        return
    raise ConfigError(f"{source}: (top level): this looks like {what}; {advice}")


def load_as(path: str | Path, kind: str) -> Any:
    """Read and validate a file of kind ``kind`` (its model instance), refusing a file of another kind.

    Raises
    ------
    ConfigError
        One line naming the file, the key path and what was expected (:func:`check_command_kind`, then the
        model's own validation).
    """
    from .config import parse_config, read_yaml

    data = read_yaml(path)
    check_command_kind(data, path, (kind,))
    return parse_config(data, kind_model(kind), source=str(path))


def check_file(path: str | Path) -> tuple[str, str]:
    """Validate a file of any kind completely; return ``(kind, one line describing it)``.

    Raises
    ------
    ConfigError
        One line naming the file, the key path and what was expected.
    """
    from .config import read_yaml

    data = read_yaml(path)
    kind = detect_kind(data, path)
    return kind, load_target(FILE_KINDS[kind].check)(data, Path(path), kind)
