"""The ``mobisense`` command line: ``mobisense solve|sweep|steady-state|replay|simulate|validate|schema|examples``.

:data:`COMMANDS` is the one registry of sub-commands. Each names a class in its package's ``commands``
module whose docstring's first line is its help text, with ``add_arguments(parser)`` and
``run(args) -> int``; those modules import their heavy dependencies only inside ``run``, so ``--help``
is fast. Exit status: 0 success, 1 solver or simulation failure, numerical failure or an output file that
could not be written (results already complete are kept), 2 invalid input — a file, a key, an option, an
output folder that cannot be used, a problem too large for the memory budget (one line naming the file and
the key path, no traceback, nothing written), 3 an internal error (a bug: one line; set
``MOBISENSE_TRACEBACK=1`` to see the traceback), 130 interrupted (Ctrl-C or SIGTERM; files already written
are complete), 141 standard output closed by its reader (``mobisense examples | head -1``; quietly, as a
program ended by SIGPIPE).
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import importlib
import os
import signal
import sys
from collections.abc import Iterator, Sequence
from typing import Any, NoReturn

from . import __version__

__all__ = ["COMMANDS", "INTERRUPTED", "build_parser", "main"]

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


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (exit status 2), like every other input error.

    An option the command does not have is answered with the command's closest options and its own help
    (argparse reports it from the top-level parser: ``mobisense: error: unrecognized arguments: --stratgy``).
    """

    argv: Sequence[str] = ()

    def parse_args(self, args: Sequence[str] | None = None, namespace: Any = None) -> Any:  # noqa: D102
        self.argv = list(sys.argv[1:] if args is None else args)
        return super().parse_args(args, namespace)

    def error(self, message: str) -> NoReturn:  # noqa: D102
        from .core.errors import one_line

        prog = self.prog
        if message.startswith("unrecognized arguments:"):
            command = self._command_parser()
            if command is not None:
                prog, message = command.prog, message + _closest_options(command, self.argv)
        self.exit(2, f"{prog}: error: {one_line(message, 400)} (see {prog} --help)\n")

    def _command_parser(self) -> argparse.ArgumentParser | None:
        """The parser of the sub-command named on the command line, if any."""
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                word = next((a for a in self.argv if not a.startswith("-")), None)
                return action.choices.get(word) if word is not None else None
        return None


def _closest_options(parser: argparse.ArgumentParser, argv: Sequence[str]) -> str:
    """``; did you mean --strategy?`` for each unknown ``--option`` of ``argv`` close to one of ``parser``'s."""
    import difflib

    known = [s for action in parser._actions for s in action.option_strings if s.startswith("--")]
    hints = []
    for word in argv:
        name = word.split("=", 1)[0]
        if name.startswith("--") and name not in known:
            close = difflib.get_close_matches(name, known, n=2, cutoff=0.75)
            if close:
                hints.append(f"{name}: did you mean {' or '.join(close)}?")
    return "; " + "; ".join(hints) if hints else ""


def build_parser(commands: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The argument parser with every sub-command.

    Parameters
    ----------
    commands : sequence of str, optional
        The sub-commands whose arguments are added (default: all). The others get only their help line: the
        command line adds the arguments of the one command it runs (its options import what they list).
    """
    parser = _Parser(prog="mobisense", description=__doc__.splitlines()[0].replace("``", ""))
    parser.add_argument("--version", action="version", version=f"mobisense {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True, parser_class=_Parser)
    for name in COMMANDS:
        command = _command(name)
        help_line = (command.__doc__ or "").strip().splitlines()[0].replace("``", "")
        command_parser = sub.add_parser(name, help=help_line, description=help_line)
        if commands is None or name in commands:
            command.add_arguments(command_parser)
        command_parser.set_defaults(run=command.run)
    return parser


#: what an interrupted command says (Ctrl-C or SIGTERM), however it was stopped
INTERRUPTED = "interrupted; files already written are complete"


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit status (also used by ``python -m``/console script)."""
    said: list[str] = []
    if sys.stdout is None:  # started with its standard output closed (>&-): what it prints is discarded
        sys.stdout = open(os.devnull, "w")  # noqa: SIM115  (for the life of the process)
    if sys.stderr is None:  # the same for messages and progress (2>&-)
        sys.stderr = open(os.devnull, "w")  # noqa: SIM115
    stderr = sys.stderr
    sys.stderr = _Discarding(stderr)  # type: ignore[assignment]
    try:
        status = _main(argv, said)
        try:
            sys.stdout.flush()  # a closed pipe is met here, not at interpreter exit
        except BrokenPipeError:
            raise
        except OSError as err:  # standard output on a full disk (>/dev/full): its text is lost, the files are not
            _discard_stdout()
            _say(f"error: cannot write to standard output ({err.strerror}); files already written are complete")
            return 1
        return status
    except KeyboardInterrupt:  # also during the imports, or while an error is being reported
        if not said:
            _say(INTERRUPTED)
        return 130
    except BrokenPipeError:  # stdout closed by the reader (``mobisense examples | head -1``): end quietly
        _discard_stdout()
        return 128 + signal.SIGPIPE
    finally:
        sys.stderr = stderr


class _Discarding:
    """Standard error that cannot fail a command: after its first failed write or flush it discards.

    Messages and progress go to standard error; on a full disk (``2>/dev/full``), a reader that went away or an
    I/O error they are lost, the command's files are not (as with a closed standard error, ``2>&-``).
    """

    def __init__(self, stream: Any) -> None:
        self.stream = stream

    def write(self, text: str) -> int:
        try:
            return int(self.stream.write(text))
        except (OSError, ValueError):
            self.discard()
            return len(text)

    def flush(self) -> None:
        try:
            self.stream.flush()
        except (OSError, ValueError):
            self.discard()

    def discard(self) -> None:
        """Write to /dev/null from now on, and so does the stream's file descriptor (its buffer flushes at exit)."""
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self.stream.fileno())
            os.close(devnull)
        except (OSError, ValueError, AttributeError):  # no file descriptor (tests capture it)
            pass
        self.stream = open(os.devnull, "w")  # noqa: SIM115  (for the rest of the command)

    def __getattr__(self, name: str) -> Any:  # isatty, fileno, encoding, … of the stream written to
        return getattr(self.stream, name)


def _main(argv: Sequence[str] | None, said: list[str]) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser([a for a in argv if not a.startswith("-")][:1])  # the command: the first word
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:  # --help, --version, usage errors: argparse has printed what to say
        return exit_.code if isinstance(exit_.code, int) else 2
    from .core.interrupts import (
        forget_interrupts,
        interrupt_handler,
        interrupt_received,
        raise_if_interrupted,
        stop_hard_inside_casadi,
    )

    forget_interrupts()
    # Ctrl-C and SIGTERM (``kill``, a batch scheduler ending the job) both stop a command; the handler records
    # the signal too, so one swallowed by CasADi's bindings is acted on at the next check instead of lost
    watched = (signal.SIGINT, signal.SIGTERM)
    previous = {sig: signal.signal(sig, interrupt_handler) for sig in watched} if _main_thread() else {}
    import numpy as np

    # overflow/invalid-value warnings of intermediate steps are not messages: results are checked for NaN/inf
    errors = np.seterr(all="ignore")
    from .core.netcdf import recorded_command  # needs neither pydantic nor numpy

    try:
        # a signal held for seconds by one long CasADi call ends the process (core/interrupts.py)
        with recorded_command(argv), _notes(), stop_hard_inside_casadi(_hard_stop):
            status = int(args.run(args) or 0)
            raise_if_interrupted()  # a signal that arrived in CasADi code and was not acted on before the end
            return status
    except KeyboardInterrupt:
        return _interrupted(said)
    except BrokenPipeError:
        raise
    except Exception as err:  # noqa: BLE001  (sorted out in _report: input, computation, output or a bug)
        # an error raised while a signal was being handled is its doing: Python turns an exception raised in
        # ``__set_name__`` (class creation) into a RuntimeError, CasADi's callbacks into a solver failure
        return _interrupted(said) if interrupt_received() else _report(err)
    finally:
        np.seterr(**errors)
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _hard_stop() -> None:
    """The one line of a command stopped inside a long CasADi call (written unbuffered: the process ends next)."""
    try:
        os.write(sys.__stderr__.fileno() if sys.__stderr__ else 2, f"mobisense: {INTERRUPTED}\n".encode())
    except (OSError, ValueError):
        pass


@contextlib.contextmanager
def _notes() -> Iterator[None]:
    """Print what the library says to the ``mobisense`` logger, for the command's duration.

    INFO as ``mobisense: note: …`` (a missing ``x.yaml`` read as the shipped example ``x``), WARNING and above as
    ``mobisense: warning: …`` (a scheduler reached unencrypted).
    """
    import logging

    class Notes(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            _say(f"{'warning' if record.levelno >= logging.WARNING else 'note'}: {record.getMessage()}")

    logger, handler = logging.getLogger("mobisense"), Notes(logging.INFO)
    level = logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)


def _interrupted(said: list[str]) -> int:
    from .core.interrupts import forget_interrupts

    forget_interrupts()
    said.append("interrupted")
    _say(INTERRUPTED)
    return 130


def _report(err: Exception) -> int:
    """Say the one-line message of an error and return its exit status (2 input, 1 computation/output, 3 bug)."""
    from .core.errors import ComputationError, ConfigError, OutputError, one_line  # after parsing: ``--help``

    if isinstance(err, ConfigError):
        _say(f"error: {one_line(str(err), 600)}")
        return 2
    if isinstance(err, (ComputationError, OutputError)):
        _say(f"error: {one_line(str(err), 600)}")
        return 1
    if isinstance(err, OSError) and err.errno == errno.ENAMETOOLONG:  # a path given in a file or an option
        _say(f"error: {one_line(str(err.filename or 'a path'), 100)}: file name too long for this system")
        return 2
    if isinstance(err, OSError) and err.errno in _NO_SPACE:  # a file, or standard output (>/dev/full)
        where = f" {err.filename}" if err.filename else " to standard output or a file"
        _say(f"error: cannot write{where} ({err.strerror}); files already written are complete")
        return 1
    if isinstance(err, MemoryError):
        _say("error: out of memory; lower the problem size (or --max-memory, the budget checked before starting)")
        return 1
    if os.environ.get("MOBISENSE_TRACEBACK"):
        raise err
    _say(f"internal error: {one_line(f'{type(err).__name__}: {err}', 300)} (a bug: please report it with "
         "the input; MOBISENSE_TRACEBACK=1 shows the traceback)")  # fmt: skip
    return 3


#: errors of a write that no input could fix: no space, over quota, a read-only file system, an I/O error
_NO_SPACE = (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EIO)


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


def _discard_stdout() -> None:
    """Point stdout at /dev/null so the interpreter's final flush does not raise again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):  # stdout has no file descriptor (tests capture it)
        pass


def _say(text: str) -> None:
    try:
        print(f"mobisense: {text}", file=sys.stderr, flush=True)
    except (OSError, ValueError):  # stderr closed
        pass


if __name__ == "__main__":
    sys.exit(main())
