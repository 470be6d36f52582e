"""Ctrl-C and SIGTERM that are never lost: recorded when they arrive, held in critical sections, acted on after.

A ``KeyboardInterrupt`` raised by a signal handler while CasADi's Python bindings are running (the handler
runs inside the ``DM_from_array`` typemap while an argument is converted, for example) is swallowed by the
binding, which tries the next overload and carries on, or resurfaces later as a stray error at interpreter
exit; the same happens inside CasADi callbacks during Ipopt (casadi/casadi#2006). So the command's handler
(:func:`interrupt_handler`) records the signal, raises at once only when no CasADi frame is on the stack, and
the places where work is handed to CasADi (every Ipopt call, every Newton step of the indirect method, the end
of a command) call :func:`raise_if_interrupted`: an interrupt that arrived inside CasADi is acted on there.

A Python signal handler runs only between two bytecodes, so one CasADi call that computes for minutes (a
gradient of a field shooting NLP with 200 sensors takes two) held Ctrl-C and SIGTERM for as long.
:func:`stop_hard_inside_casadi` watches for them from a thread (the C-level handler writes each signal to a
wakeup pipe at once, and CasADi releases the GIL while it computes): when the main thread is still inside a
CasADi call :data:`HARD_STOP_SECONDS` after a signal, and holds no signal on purpose
(:func:`deferred_interrupts`), the process ends with exit status 130. Files are written atomically, so none is
left half-written; a temporary one is removed by the next run into its folder.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Any

__all__ = [
    "HARD_STOP_SECONDS",
    "stop_hard_inside_casadi",
    "add_hard_stop_cleanup",
    "remove_hard_stop_cleanup",
    "Deferred",
    "deferred_interrupts",
    "forget_interrupts",
    "interrupt_handler",
    "interrupt_received",
    "raise_if_interrupted",
]

_received: list[int] = []  # signals recorded by interrupt_handler/_hold, until forget_interrupts
_holding: list[int] = []  # one entry per deferred_interrupts block running: its signals are held on purpose
_cleanups: list[Callable[[], None]] = []  # what a hard stop undoes first (an output folder's lock), newest last

#: seconds the main thread may stay inside one CasADi call after Ctrl-C or SIGTERM before the process ends
HARD_STOP_SECONDS = 3.0


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
    _holding.append(1)
    try:
        yield deferred
    finally:
        _holding.pop()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if raise_at_exit:
        deferred.check()


def add_hard_stop_cleanup(cleanup: Callable[[], None]) -> None:
    """Have :func:`stop_hard_inside_casadi` call ``cleanup()`` before it ends the process (until removed)."""
    _cleanups.append(cleanup)


def remove_hard_stop_cleanup(cleanup: Callable[[], None]) -> None:
    """Undo :func:`add_hard_stop_cleanup` (nothing if it was not added)."""
    if cleanup in _cleanups:
        _cleanups.remove(cleanup)


@contextlib.contextmanager
def stop_hard_inside_casadi(say: Callable[[], None], grace: float = HARD_STOP_SECONDS) -> Iterator[None]:
    """End the process (exit status 130) when a signal is not acted on because one CasADi call goes on.

    After SIGINT or SIGTERM, if the main thread is still inside CasADi ``grace`` seconds later and no
    :func:`deferred_interrupts` block holds the signal, ``say()`` is called (it must write with ``os.write``:
    nothing is flushed) and the process exits at once. Only in the main thread; a no-op elsewhere.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    read_end, write_end = os.pipe()
    os.set_blocking(write_end, False)
    try:
        previous = signal.set_wakeup_fd(write_end, warn_on_full_buffer=False)
    except ValueError:  # not the main thread of the main interpreter
        os.close(read_end)
        os.close(write_end)
        yield
        return
    done = threading.Event()
    main = threading.main_thread().ident

    def watch() -> None:
        while True:
            try:
                data = os.read(read_end, 64)  # one byte per signal: its number
            except OSError:
                return
            if not data:  # the block ended: the write end is closed
                return
            if not {signal.SIGINT, signal.SIGTERM} & set(data):
                continue
            if done.wait(grace):
                return
            frame = sys._current_frames().get(main)  # noqa: SLF001  (the standard way to see another thread's stack)
            if frame is not None and not _holding and _inside_casadi(frame):
                for cleanup in reversed(list(_cleanups)):
                    try:
                        cleanup()
                    except Exception:  # noqa: BLE001, S110  (the process ends next: each cleanup is best effort)
                        pass
                say()
                os._exit(130)

    thread = threading.Thread(target=watch, name="mobisense-hard-stop", daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        signal.set_wakeup_fd(previous)
        os.close(write_end)
        thread.join(timeout=1.0)
        os.close(read_end)
