"""Run a closed-loop simulation scenario: ``mobisense simulate KIND SCENARIO.yaml --out DIR``."""

from __future__ import annotations

import argparse
import importlib
from pathlib import Path

#: simulation kind -> module exposing ``run_scenario(scenario: Path, out: Path, args) -> int``
SIMULATIONS: dict[str, str] = {
    "leader-follower": "formation.leader_follower_command",
    "distributed": "estimation.distributed_command",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``simulate`` arguments."""
    parser.add_argument("kind", choices=sorted(SIMULATIONS), help="which simulation")
    parser.add_argument("scenario", type=Path, help="scenario YAML file")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default out/<scenario name>)")
    parser.add_argument("--no-plot", action="store_true", help="skip the figures")
    parser.add_argument("--seed", type=int, default=None, help="override the scenario's random seed")


def run(args: argparse.Namespace) -> int:
    """Dispatch to the simulation kind's module."""
    module = importlib.import_module(SIMULATIONS[args.kind])
    out = args.out if args.out is not None else Path("out") / args.scenario.stem
    return int(module.run_scenario(args.scenario, out, args) or 0)
