"""Valid small inputs of every command, and the keys a hostile file attacks in each (for the hostile suite)."""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from reference_problems import PROBLEMS, hussein2008

#: placeholder number replaced by a raw YAML literal (``1e400``, ``.nan``, a 400-digit integer …) in the text
SENTINEL = 12345.678


def small_problem() -> dict[str, Any]:
    """The paper's problem on 20 intervals (solves in ~1 s)."""
    return hussein2008(collocation={"intervals": 20})


def shipped(name: str) -> dict[str, Any]:
    """A shipped problem file as data."""
    return yaml.safe_load((PROBLEMS / name).read_text(encoding="utf-8"))


def _set(path: tuple[Any, ...]) -> Callable[[dict[str, Any], Any], None]:
    def setter(data: dict[str, Any], value: Any) -> None:
        target = data
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value

    return setter


def _rename(path: tuple[Any, ...], new: str) -> Callable[[dict[str, Any]], None]:
    def rename(data: dict[str, Any]) -> None:
        target = data
        for key in path[:-1]:
            target = target[key]
        target[new] = target.pop(path[-1])

    return rename


@dataclass
class Kind:
    """One command and its input file: how to write it, and which keys the generic attacks hit.

    ``misspell`` renames a required key (``message``: what the error must say); ``number`` sets a number key
    (``number_path``: its key path in messages); ``top`` is a top-level key (for the duplicate-key attack).
    """

    name: str
    args: list[str]
    data: Callable[[], dict[str, Any]]
    misspell: Callable[[dict[str, Any]], None]
    message: str
    number: Callable[[dict[str, Any], Any], None]
    number_path: str
    top: str
    writes: bool = True
    extra: dict[str, Callable[[], dict[str, Any]]] = field(default_factory=dict)

    def write(self, folder: Path, content: bytes | str | dict[str, Any] | None = None) -> Path:
        """Write the input (``content``, default the valid data) and its companion files into ``folder``."""
        for name, make in self.extra.items():
            (folder / name).write_text(yaml.safe_dump(make()), encoding="utf-8")
        path = folder / "input.yaml"
        if content is None:
            content = self.data()
        if isinstance(content, dict):
            content = yaml.safe_dump(content, sort_keys=False)
        if isinstance(content, str):
            content = content.encode("utf-8")
        path.write_bytes(content)
        return path

    def command(self, path: Path, out: Path | None) -> list[str]:
        """The command line reading ``path`` (and writing into ``out``)."""
        return [*self.args, str(path)] + (["--out", str(out)] if self.writes and out is not None else [])

    def text_with(self, literal: str) -> str:
        """The valid file as YAML text with the number key set to the raw ``literal``."""
        data = copy.deepcopy(self.data())
        self.number(data, SENTINEL)
        return yaml.safe_dump(data, sort_keys=False).replace(str(SENTINEL), literal)

    def misspelled(self) -> dict[str, Any]:
        """The valid data with a required key misspelled."""
        data = copy.deepcopy(self.data())
        self.misspell(data)
        return data


def _sweep() -> dict[str, Any]:
    return {"base": "base.yaml", "mode": "grid", "vary": {"cost.alpha": [0.002, 0.004]}}


def _field_replay() -> dict[str, Any]:
    data = shipped("replay_two_charges.yaml")
    data["duration"], data["time_step"] = 2.0, 0.1
    return data


def _leader_follower() -> dict[str, Any]:
    data = shipped("leader_follower_control1.yaml")
    data["duration"], data["step"] = 1.0, 0.01
    return data


def _distributed() -> dict[str, Any]:
    data = shipped("distributed_advection_diffusion.yaml")
    data["time"] = {"step": 1.0, "duration": 10.0}
    return data


def _replan() -> dict[str, Any]:
    return {"kind": "replan", "problem": "problem.yaml", "replan": {"every": 2.5, "horizon": "shrinking"},
            "disturbance": {"drift": [0.3, -0.2], "force_noise_std": 0.05, "seed": 1},
            "monte_carlo": {"runs": 1, "time_step": 0.05}}  # fmt: skip


KINDS: dict[str, Kind] = {
    "solve": Kind("solve", ["solve", "--no-plot", "--quiet"], small_problem, _rename(("cost", "alpha"), "alhpa"),
                  "cost.alhpa: unknown key; did you mean 'alpha'", _set(("cost", "alpha")), "cost.alpha", "cost"),
    "validate": Kind("validate", ["validate"], small_problem, _rename(("cost", "alpha"), "alhpa"),
                     "cost.alhpa: unknown key; did you mean 'alpha'", _set(("cost", "alpha")), "cost.alpha", "cost",
                     writes=False),
    "sweep": Kind("sweep", ["sweep", "--quiet", "--workers", "1"], _sweep, _rename(("base",), "bsae"),
                  "bsae: unknown key; did you mean 'base'", lambda d, v: d["vary"].update({"cost.alpha": [v]}),
                  "cost.alpha", "base", extra={"base.yaml": small_problem}),
    "steady-state": Kind("steady-state", ["steady-state", "--no-plot"], lambda: shipped("formation_cross.yaml"),
                         _rename(("noise", "sigma_process"), "sigma_proces"),
                         "noise.sigma_proces: unknown key; did you mean 'sigma_process'",
                         _set(("noise", "sigma_measurement")), "noise.sigma_measurement", "noise"),
    "replay": Kind("replay", ["replay", "--no-plot", "--quiet"], _field_replay, _rename(("duration",), "duraton"),
                   "duraton: unknown key; did you mean 'duration'", _set(("time_step",)), "time_step", "duration"),
    "simulate leader-follower": Kind("simulate leader-follower", ["simulate", "leader-follower", "--no-plot"],
                                     _leader_follower, _rename(("duration",), "duraton"),
                                     "duraton: unknown key; did you mean 'duration'", _set(("step",)), "step",
                                     "duration"),
    "simulate distributed": Kind("simulate distributed", ["simulate", "distributed", "--no-plot"], _distributed,
                                 _rename(("network",), "netwrok"), "netwrok: unknown key; did you mean 'network'",
                                 _set(("time", "step")), "time.step", "time"),
    "replan": Kind("replan", ["replay", "--no-plot", "--quiet"], _replan, _rename(("replan", "every"), "evrey"),
                   "replan.evrey: unknown key; did you mean 'every'", _set(("monte_carlo", "time_step")),
                   "monte_carlo.time_step", "replan", extra={"problem.yaml": small_problem}),
}  # fmt: skip
