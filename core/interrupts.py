"""Critical sections that Ctrl-C and SIGTERM cannot split: the signal is held and acted on right after."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from typing import Any

__all__ = ["Deferred", "deferred_interrupts"]


class Deferred:
    """The interrupt received inside :func:`deferred_interrupts`, if any."""

    def __init__(self) -> None:
        self.received: int | None = None

    def check(self) -> None:
        """Raise ``KeyboardInterrupt`` if SIGINT or SIGTERM arrived."""
        if self.received is not None:
            self.received = None
            raise KeyboardInterrupt


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

    def hold(signum: int, frame: Any) -> None:
        deferred.received = signum

    previous = {sig: signal.signal(sig, hold) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield deferred
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if raise_at_exit:
        deferred.check()
