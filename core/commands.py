"""The commands about files of every kind: ``mobisense validate``, ``mobisense schema``, ``mobisense examples``.

They read the registry of file kinds (:mod:`mobisense.core.kinds`) and the shipped examples
(:mod:`mobisense.core.examples`); like every command module, heavy imports happen inside ``run``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from .output import output_path

__all__ = ["ValidateCommand", "SchemaCommand", "ExamplesCommand"]


class ValidateCommand:
    """Validate input files of any kind without running them: one line per file saying what it is."""

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        """Add the ``validate`` arguments."""
        parser.add_argument(
            "files", type=Path, nargs="+", help="YAML files of any kind (problem, sweep, formation, scenarios)"
        )

    @staticmethod
    def run(args: argparse.Namespace) -> int:
        """Validate every file (and the files it names); exit 2 if any is invalid."""
        from .config import ConfigError
        from .errors import one_line
        from .examples import resolve_input
        from .kinds import FILE_KINDS, check_file

        invalid = 0
        for given in args.files:
            path = resolve_input(given)
            try:
                kind, line = check_file(path)
            except ConfigError as err:
                print(f"mobisense: error: {one_line(str(err), 600)}", file=sys.stderr)
                invalid += 1
                continue
            print(f"{path}: valid {kind} file ({FILE_KINDS[kind].command}) — {line}")
        return 2 if invalid else 0


class SchemaCommand:
    """Write the JSON Schema of an input file kind, for editors that complete and check YAML."""

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        """Add the ``schema`` arguments."""
        from .kinds import FILE_KINDS

        parser.add_argument("kind", choices=sorted(FILE_KINDS), help="which kind of file")
        parser.add_argument(
            "--out", type=output_path, default=None, help="write the schema to this file (default: stdout)"
        )

    @staticmethod
    def run(args: argparse.Namespace) -> int:
        """Print (or write) the schema."""
        from .config import ConfigError
        from .files import atomic_path
        from .output import OutputFolder
        from .schema import file_schema

        text = json.dumps(file_schema(args.kind), indent=2, ensure_ascii=False) + "\n"
        if args.out is None:
            sys.stdout.write(text)
            return 0
        if args.out.is_dir():
            raise ConfigError(f"--out {args.out}: is a folder; expected a file name")
        OutputFolder.check(args.out.parent, f"--out {args.out}: its folder")
        with atomic_path(args.out) as tmp:
            tmp.write_text(text, encoding="utf-8")
        print(f"JSON Schema of {args.kind} files written to {args.out}")
        return 0


class ExamplesCommand:
    """List the example files shipped with mobisense (one line each); --copy DIR writes them out."""

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        """Add the ``examples`` arguments."""
        parser.add_argument(
            "--copy", type=output_path, default=None, metavar="DIR", help="write every example into DIR"
        )
        parser.add_argument("--force", action="store_true", help="with --copy: overwrite files that differ")

    @staticmethod
    def run(args: argparse.Namespace) -> int:
        """List, or copy, the shipped examples."""
        from .config import ConfigError
        from .examples import EXAMPLES, copy_examples
        from .output import OutputFolder

        if args.copy is not None:
            OutputFolder.check(args.copy, "--copy")  # a file, under a file, not writable: exit 2, nothing written
            try:
                written = copy_examples(args.copy, overwrite=args.force)
            except FileExistsError as err:
                raise ConfigError(f"{err}; use --force to overwrite") from None
            kept = len(EXAMPLES) - len(written)
            same = f" ({kept} already there, unchanged)" if kept else ""
            files = "file" if len(written) == 1 else "files"
            print(f"{len(written)} example {files} written to {args.copy}/{same}; run one with, e.g.,")
            print(f"  mobisense solve {args.copy / 'hussein2008.yaml'}")
            return 0
        width = max(len(e.name) for e in EXAMPLES)
        for example in EXAMPLES:
            print(f"{example.name:<{width}}  {example.summary}  [mobisense {example.command}]")
        print("\nRun one by name (mobisense solve hussein2008) or copy them all: mobisense examples --copy DIR")
        return 0
