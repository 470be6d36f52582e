"""Scenario files of the closed-loop simulations, behind one shape: load → :meth:`Scenario.run` → result.

- ``field_replay`` (a ``field:`` key): :func:`~mobisense.formation.replay.runs.run_field_replay`;
- ``plan_replay`` (a ``solution:`` key): :func:`~mobisense.formation.replay.runs.run_plan_replay`;
- ``replan`` (``kind: replan``): :func:`~mobisense.formation.replay.replan.run_replan`;
- ``leader_follower`` (``mobisense simulate leader-follower``):
  :func:`~mobisense.formation.leader_follower.runs.run_leader_follower`;
- ``distributed`` (``mobisense simulate distributed``):
  :func:`~mobisense.formation.distributed.simulation.run_distributed`.

Example::

    from .. import load_scenario
    result = load_scenario("problems/replay_two_charges.yaml").run(seed=3)
    result.save("out/two_charges")          # result.nc, figures, summary.json
    ds = result.to_xarray()
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .simulation_result import SimulationResult

__all__ = ["SCENARIO_KINDS", "REPLAY_KINDS", "Scenario", "load_scenario", "scenario_model"]

#: scenario kind -> "module:model class" of its file
SCENARIO_KINDS: dict[str, str] = {
    "field_replay": "mobisense.formation.replay.scenario:FieldReplayScenario",
    "plan_replay": "mobisense.formation.replay.plan:OcpReplayScenario",
    "leader_follower": "mobisense.formation.leader_follower.scenario:LeaderFollowerScenario",
    "distributed": "mobisense.formation.distributed.simulation:DistributedScenario",
    "replan": "mobisense.formation.replay.replan:ReplanScenario",
}
#: the kinds ``mobisense replay`` runs
REPLAY_KINDS = ("field_replay", "plan_replay", "replan")


@dataclass
class Scenario:
    """A validated scenario file: its ``kind``, its model (``config``) and where it was read from."""

    kind: str
    config: Any
    source: Path

    def estimates(self) -> list[Any]:
        """Memory and time of :meth:`run` (:class:`mobisense.core.budget.Estimate` items) from the sizes."""
        from .sizes import scenario_estimates

        return scenario_estimates(self.kind, self.config, self.source)

    def run(self, seed: int | None = None, progress: bool = False, animate: bool = False) -> SimulationResult:
        """Simulate the scenario.

        Parameters
        ----------
        seed : int, optional
            Overrides the file's random seed.
        progress : bool
            Show a progress bar where the simulation has one.
        animate : bool
            Field replays: also write an animation when plotting.
        """
        if self.kind == "field_replay":
            from .replay.runs import run_field_replay

            return run_field_replay(self.config, self.source, seed, progress=progress, animate=animate)
        if self.kind == "plan_replay":
            from .replay.runs import run_plan_replay

            return run_plan_replay(self.config, self.source, seed)
        if self.kind == "replan":
            from .replay.replan import run_replan

            return run_replan(self.config, self.source, seed)
        if self.kind == "leader_follower":
            from .leader_follower.runs import run_leader_follower

            return run_leader_follower(self.config, seed, source=self.source)
        from .distributed.simulation import run_distributed

        return run_distributed(self.config, seed, progress=progress)


def scenario_model(kind: str) -> Any:
    """The pydantic model of a scenario kind (a key of :data:`SCENARIO_KINDS`)."""
    import importlib

    module_name, _, name = SCENARIO_KINDS[kind].partition(":")
    return getattr(importlib.import_module(module_name), name)


def replay_kind(data: Any, source: Path) -> str:
    """``field_replay``, ``plan_replay`` or ``replan`` from the ``kind`` or the keys of a replay file; else an error.

    Raises ``ConfigError``; a file of another kind has been refused by :func:`mobisense.core.kinds.check_command_kind`.
    """
    from ..core.config import ConfigError
    from ..core.errors import brief

    if data is None:
        raise ConfigError(f"{source}: (top level): the file is empty; expected a mapping of keys")
    if not isinstance(data, dict):
        raise ConfigError(
            f"{source}: (top level): expected a mapping of keys (a field replay, a plan replay or a re-planning file)"
        )
    kind = data.get("kind")
    if kind in REPLAY_KINDS:
        return str(kind)
    if "field" in data:
        return "field_replay"
    if "solution" in data:
        return "plan_replay"
    if "replan" in data:  # a re-planning file without its kind: key
        return "replan"
    if "kind" in data:  # neither a replay kind nor the shape of one
        raise ConfigError(f"{source}: kind: expected one of {', '.join(map(repr, REPLAY_KINDS))}, got {brief(kind)}")
    raise ConfigError(
        f"{source}: (top level): expected a field replay (key 'field') or a replay of an optimised "
        "solution (key 'solution')"
    )


def load_scenario(path: str | Path, kind: str | None = None) -> Scenario:
    """Read and validate a scenario file, or a shipped example by name (``load_scenario("replay_two_charges")``).

    Parameters
    ----------
    path : str or Path
        The YAML file, or the name of a shipped example (:func:`mobisense.core.examples.resolve_input`).
    kind : str, optional
        One of :data:`SCENARIO_KINDS`; ``"replay"`` for one of the kinds ``mobisense replay`` runs (a field
        replay, a plan replay, a re-planning file), told apart by their keys; default: any scenario kind,
        told by the file's ``kind:`` key or its shape (:func:`mobisense.core.kinds.apparent_kind`).

    Raises
    ------
    ConfigError
        One line naming the file and the key path; a file of another kind (a problem, a formation design)
        is refused with the command that runs it.
    """
    from ..core.config import ConfigError, parse_config, read_yaml
    from ..core.examples import resolve_input
    from ..core.kinds import apparent_kind, check_command_kind

    path = resolve_input(path)
    data = read_yaml(path)
    if kind is not None and kind != "replay" and kind not in SCENARIO_KINDS:
        raise ConfigError(f"{path}: unknown scenario kind {kind!r}; expected one of {sorted(SCENARIO_KINDS)}")
    expected = REPLAY_KINDS if kind == "replay" else (kind,) if kind else tuple(SCENARIO_KINDS)
    check_command_kind(data, path, expected)
    if kind is None:
        kind = apparent_kind(data)
    if kind is None or kind == "replay":
        kind = replay_kind(data, path)
    return Scenario(kind, parse_config(data, scenario_model(kind), source=str(path)), path)
