"""The ``mobisense`` command line: ``mobisense solve|sweep|steady-state|replay|simulate|validate|schema|examples``.

:data:`COMMANDS` is the one registry of sub-commands. Each names a class in its package's ``commands``
module whose docstring's first line is its help text, with ``add_arguments(parser)`` and
``run(args) -> int``; those modules import their heavy dependencies only inside ``run``, so ``--help``
is fast. Exit status: 0 success, 1 solver or simulation failure (results already computed are kept),
2 invalid input (one message naming the file and the key path, no traceback), 130 interrupted.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence
from typing import Any

from . import __version__

__all__ = ["COMMANDS", "build_parser", "main"]

#: sub-command name -> "module:class" implementing it
COMMANDS: dict[str, str] = {
    "solve": "mobisense.ocp.commands:SolveCommand",
    "sweep": "mobisense.ocp.commands:SweepCommand",
    "steady-state": "mobisense.estimation.commands:SteadyStateCommand",
    "replay": "mobisense.formation.commands:ReplayCommand",
    "simulate": "mobisense.formation.commands:SimulateCommand",
    "validate": "mobisense.core.commands:ValidateCommand",
    "schema": "mobisense.core.commands:SchemaCommand",
    "examples": "mobisense.core.commands:ExamplesCommand",
}


def _command(name: str) -> Any:
    module_name, _, class_name = COMMANDS[name].partition(":")
    return getattr(importlib.import_module(module_name), class_name)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every sub-command."""
    parser = argparse.ArgumentParser(prog="mobisense", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"mobisense {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        command = _command(name)
        help_line = (command.__doc__ or "").strip().splitlines()[0]
        command_parser = sub.add_parser(name, help=help_line, description=help_line)
        command.add_arguments(command_parser)
        command_parser.set_defaults(run=command.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit status (also used by ``python -m``/console script)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:  # --help, --version, usage errors: argparse has printed what to say
        return exit_.code if isinstance(exit_.code, int) else 2
    from .core.config import ConfigError  # after parsing: ``--help`` needs neither pydantic nor numpy
    from .core.netcdf import recorded_command

    try:
        with recorded_command(argv):  # the "history" of every netCDF file written
            return int(args.run(args) or 0)
    except ConfigError as err:
        print(f"mobisense: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("mobisense: interrupted; files already written are complete", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
