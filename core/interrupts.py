"""Ctrl-C and SIGTERM that are never lost: recorded when they arrive, held in critical sections, acted on after.

A ``KeyboardInterrupt`` raised by a signal handler while CasADi's Python bindings are running (the handler
runs inside the ``DM_from_array`` typemap while an argument is converted, for example) is swallowed by the
binding, which tries the next overload and carries on, or resurfaces later as a stray error at interpreter
exit; the same happens inside CasADi callbacks during Ipopt (casadi/casadi#2006). So the command's handler
(:func:`interrupt_handler`) records the signal, raises at once only when no CasADi frame is on the stack, and
the places where work is handed to CasADi (every Ipopt call, every Newton step of the indirect method, the end
of a command) call :func:`raise_if_interrupted`: an interrupt that arrived inside CasADi is acted on there.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from typing import Any

__all__ = [
    "Deferred",
    "deferred_interrupts",
    "forget_interrupts",
    "interrupt_handler",
    "interrupt_received",
    "raise_if_interrupted",
]

_received: list[int] = []  # signals recorded by interrupt_handler/_hold, until forget_interrupts


def interrupt_handler(signum: int, frame: Any) -> None:
    """The signal handler of SIGINT and SIGTERM for a command: record the signal, raise ``KeyboardInterrupt``.

    Inside CasADi's bindings the exception would be swallowed: there it is only recorded, and raised by the
    next :func:`raise_if_interrupted`.
    """
    _received.append(signum)
    if not _inside_casadi(frame):
        raise KeyboardInterrupt


def _inside_casadi(frame: Any) -> bool:
    while frame is not None:
        if str(frame.f_globals.get("__name__", "")).startswith("casadi"):
            return True
        frame = frame.f_back
    return False


def raise_if_interrupted() -> None:
    """Raise ``KeyboardInterrupt`` if SIGINT or SIGTERM arrived (recorded inside CasADi, or swallowed there).

    The record stays until :func:`forget_interrupts`: an error that the interrupt causes further on is still
    recognised as its doing.
    """
    if _received:
        raise KeyboardInterrupt


def interrupt_received() -> bool:
    """Whether SIGINT or SIGTERM arrived since the record was last cleared."""
    return bool(_received)


def forget_interrupts() -> None:
    """Clear the record: the ``KeyboardInterrupt`` raised for it has been handled.

    Also clears CPython's own record of an unhandled ``KeyboardInterrupt``. A ``KeyboardInterrupt`` that passes
    through code run by ``exec`` of a string (``dataclasses`` builds every ``__init__`` that way) sets it even
    when the exception is caught later, and the interpreter then ends by killing itself with SIGINT instead of
    returning the command's exit status 130. Every ``exec`` of a string resets it first; this one succeeds.
    """
    _received.clear()
    exec("None")  # noqa: S102  (a constant string: resets CPython's unhandled-KeyboardInterrupt flag)


class Deferred:
    """The handle of a :func:`deferred_interrupts` block: :meth:`check` acts on a signal held in it."""

    def check(self) -> None:
        """Raise ``KeyboardInterrupt`` if SIGINT or SIGTERM arrived (held here, or recorded and swallowed)."""
        raise_if_interrupted()


def _hold(signum: int, frame: Any) -> None:
    """The handler inside :func:`deferred_interrupts`: record the signal, do not raise.

    :meth:`Deferred.check` raises it after the block; an error raised in the block before then is reported as
    the interrupt.
    """
    _received.append(signum)


@contextlib.contextmanager
def deferred_interrupts(raise_at_exit: bool = True) -> Iterator[Deferred]:
    """Hold SIGINT and SIGTERM inside the block; with ``raise_at_exit`` raise ``KeyboardInterrupt`` after it.

    Use it where an interruption would separate two things that belong together (a task's solution file and
    its row of results), or inside library code that cannot be interrupted cleanly (dask's cluster start).
    Outside the main thread the block runs unprotected (signals are only delivered to the main thread).
    """
    deferred = Deferred()
    if threading.current_thread() is not threading.main_thread():
        yield deferred
        return

    previous = {sig: signal.signal(sig, _hold) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield deferred
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if raise_at_exit:
        deferred.check()
