"""The ``mobisense`` command line: ``mobisense solve|validate|steady-state|replay|sweep|simulate …``.

Each sub-command lives in its own module (imported only when used, so ``--help`` is fast) exposing
``add_arguments(parser)`` and ``run(args) -> int``; its module docstring's first line is its help text.
Exit status: 0 success, 1 solver failure (results already solved are kept), 2 invalid input
(one message naming the file and the key path, no traceback), 130 interrupted.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys
from collections.abc import Sequence

#: sub-command name -> module implementing it
COMMANDS: dict[str, str] = {
    "solve": "ocp.command_solve",
    "validate": "ocp.command_validate",
    "steady-state": "estimation.command_steady_state",
    "replay": "formation.command_replay",
    "sweep": "ocp.command_sweep",
    "simulate": "formation.command_simulate",
}


def _help_line(module_name: str) -> str:
    spec = importlib.util.find_spec(module_name)
    if spec is None or spec.origin is None:
        return "(not installed)"
    with open(spec.origin, encoding="utf-8") as handle:
        for line in handle:
            line = line.strip().strip('"').strip()
            if line:
                return line
    return ""


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """Build the argument parser; only the sub-command named in ``argv`` is imported."""
    parser = argparse.ArgumentParser(prog="mobisense", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    wanted = next((a for a in (argv or []) if not a.startswith("-")), None)
    for name, module_name in COMMANDS.items():
        if importlib.util.find_spec(module_name) is None:
            continue  # a command whose module is not there yet
        help_line = _help_line(module_name)
        command_parser = sub.add_parser(name, help=help_line, description=help_line)
        if name == wanted:
            module = importlib.import_module(module_name)
            module.add_arguments(command_parser)
            command_parser.set_defaults(run=module.run)
        else:
            command_parser.set_defaults(module_name=module_name)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit status (also used by ``python -m``/console script)."""
    from ocp.config import ConfigError

    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    try:
        return int(args.run(args) or 0)
    except ConfigError as err:
        print(f"mobisense: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("mobisense: interrupted; files already written are complete", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
