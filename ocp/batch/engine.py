"""Distributed solving on dask.distributed: sweeps and multi-start, resumable and fault-tolerant.

Tasks carry plain data (problem dicts, numpy arrays), never CasADi objects; each worker process builds and caches the
transcription of a problem structure (:func:`mobisense.ocp.direct.solver.transcription_for`) and re-solves it with new
parameters. Warm-started tasks run in chains of neighbours, one per worker (:mod:`mobisense.ocp.batch.chains`): each
task is started on its worker from its predecessor's primal–dual point (re-scaled by
:meth:`DirectCollocation.transfer`), without a round trip through the client, and one dask task solves a link of
up to :data:`~mobisense.ocp.batch.chains.LINK_TASKS` consecutive tasks (fewer when they are slow). A task that
raises, or whose worker dies more often than dask retries, becomes a row with ``status = "error"``; nothing stops
the sweep.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from ...core.errors import ConfigError
from ...core.interrupts import deferred_interrupts
from .chains import ChainLinks, best_seed, pair_chains, ring_order, solve_chain_link
from .cluster import CONNECT_TIMEOUT, insecure_warning
from .worker import shareable_starts, solve_start_share, solve_task, task_problem

__all__ = ["open_client", "run_tasks", "refuse_in_a_worker_import", "CHAIN_AHEAD"]

#: links of one chain submitted ahead of their results (a link is up to LINK_TASKS tasks, see ChainLinks): one
#: solving and one waiting on its worker. Chains that share an arc cannot take back a link in flight, so more links
#: ahead end them further apart (4 ahead: 50 ms apart in a run of the 40-task sweep; the 200-task sweep 1.52x serial
#: with 4, 1.58x with 2 and the head's own chain speculating, medians of 5 rounds)
CHAIN_AHEAD = 2
#: dask settings of the local cluster: every task is pinned to its chain's worker, so there is nothing to steal
#: or rebalance; the workers' statistical profiler (a thread sampling the solving thread every 10 ms) and the
#: twice-a-second system monitors cost CPU that the two cores of a small machine share with the solves
LOCAL_CONFIG: dict[str, Any] = {
    "distributed.scheduler.work-stealing": False,
    "distributed.scheduler.active-memory-manager.start": False,
    "distributed.worker.profile.enabled": False,
    "distributed.admin.system-monitor.interval": "5s",
}


@contextlib.contextmanager
def open_client(scheduler: str | None, workers: int | None, security: Any = None) -> Iterator[Any]:
    """A dask Client: on ``scheduler`` (``tls://…``, ``tcp://…``) or on a LocalCluster of ``workers`` processes.

    A scheduler that does not answer within :data:`CONNECT_TIMEOUT` seconds raises ``ConfigError``. Local
    workers start with SIGINT blocked and then ignore it (:func:`mobisense.ocp.batch.worker.dask_setup`), so
    Ctrl-C stops the client, which closes them, without a traceback from every worker.
    """
    import os
    import warnings

    import dask
    from dask.distributed import Client, LocalCluster

    if scheduler:
        try:
            _probe(scheduler)
            with deferred_interrupts(raise_at_exit=False) as deferred:
                client = Client(scheduler, timeout=CONNECT_TIMEOUT, security=security)
        except (OSError, TimeoutError, ValueError, TypeError, MemoryError) as exc:
            reason = " ".join(str(exc).split())[:160] or type(exc).__name__
            raise ConfigError(
                f"--scheduler {scheduler[:80]}: cannot connect within {CONNECT_TIMEOUT:g} s ({reason}); check the "
                "address, or leave out --scheduler to use local workers"
            ) from None
        warning = insecure_warning(scheduler, security)
        if warning:
            import logging

            logging.getLogger("mobisense").warning(warning)
        with client:
            deferred.check()
            yield client
        return
    refuse_in_a_worker_import()
    n = workers or os.cpu_count() or 1
    # the scheduler's HTTP server (no dashboard here) falls back to a free port when 8787 is taken: not news
    warnings.filterwarnings("ignore", message="Port .* is already in use", category=UserWarning)
    # dask sets MALLOC_TRIM_THRESHOLD_ in its workers, which also freezes glibc's mmap threshold: MUMPS' large
    # per-factorisation workspaces then go through mmap/munmap and page faults. Unset it for our workers.
    with (
        dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None, **LOCAL_CONFIG}),
        deferred_interrupts(raise_at_exit=False) as deferred,
        _sigint_blocked_in_new_processes(),
    ):
        try:
            cluster = LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=50,
                preload=["mobisense.ocp.batch.worker"],  # its dask_setup: workers ignore Ctrl-C (the client stops them)
            )
        except RuntimeError as exc:  # "Nanny failed to start": say what usually causes it
            raise RuntimeError(f"{exc}: the local dask workers did not start (a script that calls ms.sweep or "
                               "ms.multistart needs the call under `if __name__ == \"__main__\":`; the workers' own "
                               "messages are above)") from exc  # fmt: skip
        try:
            client = Client(cluster)
        except BaseException:
            cluster.close()
            raise
    import logging

    loggers = [logging.getLogger(name) for name in ("distributed", "distributed.batched", "distributed.core")]
    levels = [logger.level for logger in loggers]
    try:
        with cluster, client:
            deferred.check()  # Ctrl-C or SIGTERM during the start: stop now, closing the cluster cleanly
            try:
                yield client
            except BaseException:
                for logger in loggers:  # the killed workers' closed connections are logged with tracebacks
                    logger.setLevel(logging.CRITICAL)
                _kill_local_workers(cluster)  # interrupted or failed: nothing more to collect from them
                raise
    finally:
        for logger, level in zip(loggers, levels, strict=True):
            logger.setLevel(level)


def _kill_local_workers(cluster: Any) -> None:
    """SIGKILL the worker processes of a local cluster, so that closing it does not wait on their solves.

    A worker inside a long Ipopt call does not answer its nanny's request to close; the cluster then waited for
    its timeout and Ctrl-C during ``--multistart`` took 3.3–4 s to exit (first-hour audit). Their results are not
    needed any more (a sweep's finished tasks are written by the client).
    """
    for nanny in list(getattr(cluster, "workers", {}).values()):
        process = getattr(getattr(nanny, "process", None), "process", None)  # Nanny → WorkerProcess → AsyncProcess
        try:
            if process is not None and process.is_alive():
                process.kill()
        except (OSError, ValueError, AttributeError):  # already gone, or another kind of worker
            pass


def refuse_in_a_worker_import() -> None:
    """Raise ``RuntimeError`` when a local worker process, importing the user's script, reaches this call again.

    Local workers are new Python processes that import the script that started them (multiprocessing's spawn): a
    script calling ``ms.sweep`` at its top level, without ``if __name__ == "__main__":``, would start a cluster
    in every worker, and the user saw "--out …: is in use by another mobisense run" and "Nanny failed to start"
    (first-hour audit). A script run from stdin (``python - <<EOF``) cannot be imported by the workers at all.
    """
    import inspect

    frame = inspect.currentframe()
    while frame is not None and frame.f_globals.get("__name__") != "__mp_main__":  # the script, run by a worker
        frame = frame.f_back
    if frame is not None:
        raise RuntimeError(
            "mobisense: a local dask worker imported the script that calls ms.sweep/ms.multistart and reached that "
            "call again: put the call under `if __name__ == \"__main__\":` (local workers import the script; a "
            "script read from stdin cannot be imported, save it to a file)"
        )


@contextlib.contextmanager
def _sigint_blocked_in_new_processes() -> Iterator[None]:
    """Block SIGINT in this thread, and so in the threads and processes started from here, inside the block.

    A worker process imports dask for about a second before its :func:`~mobisense.ocp.batch.worker.dask_setup`
    ignores SIGINT; a Ctrl-C in that second (sent to the whole process group) printed each worker's
    ``KeyboardInterrupt`` traceback. A signal mask is inherited through ``fork`` and ``exec``: the workers, and
    the event-loop threads that spawn them, start with SIGINT blocked and never see it. Here a SIGINT arriving
    in the block stays pending and is delivered when the mask is restored (not lost). SIGTERM stays open: the
    nannies stop their workers with it. The standard library's resource tracker, whose start unblocks SIGINT in
    the thread that starts it (the nannies' event loop, spawning the workers just after), is started first.
    """
    import signal
    from multiprocessing import resource_tracker

    if not hasattr(signal, "pthread_sigmask"):  # not POSIX
        yield
        return
    resource_tracker.ensure_running()
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _probe(address: str) -> None:
    """Connect to a scheduler's port within :data:`CONNECT_TIMEOUT` (``OSError``/``TimeoutError`` if not).

    Over plain ``tcp://`` also read the first 8 bytes of the handshake (a frame length a real scheduler sends
    at once), so that a port that accepts and never answers, or answers another protocol, is refused instead
    of hanging the client.
    """
    import socket
    import struct

    scheme, _, rest = address.partition("://")
    if scheme not in ("tcp", "tls"):
        return
    host, _, port = rest.rpartition(":")
    host = host.strip("[]")
    if not host or not port.isdigit():
        raise ValueError(f"expected host:port, got {rest[:60]!r}")
    deadline = time.monotonic() + CONNECT_TIMEOUT
    with socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT) as sock:
        if scheme != "tcp":
            return
        header = b""
        while len(header) < 8:
            sock.settimeout(max(0.01, deadline - time.monotonic()))
            try:
                chunk = sock.recv(8 - len(header))
            except TimeoutError:
                raise TimeoutError("the port accepts connections but sends no dask handshake") from None
            if not chunk:
                raise OSError("the connection was closed before a dask handshake")
            header += chunk
    if not 0 < struct.unpack("<Q", header)[0] < 2**20:
        raise OSError("the port answers, but not with the dask protocol")


def run_tasks(
    client: Any,
    payloads: list[dict[str, Any]],
    on_result: Callable[[int, dict[str, Any]], None],
    structure_keys: list[Any] | None = None,
    coordinates: list[np.ndarray] | None = None,
    warm_start: bool = True,
    in_flight: int | None = None,
) -> None:
    """Run ``payloads`` on ``client``, calling ``on_result(i, result)`` as each finishes (in completion order).

    ``result`` is the worker's dict, or ``{"row": {"status": "error", "error": …}}`` if the task failed.
    With ``warm_start`` the tasks run in chains (:mod:`mobisense.ocp.batch.chains`): ordered along the
    ``coordinates`` (grouped by ``structure_keys``), cut into one chain per worker, two chains running
    outwards from each cold head (:func:`mobisense.ocp.batch.chains.pair_chains`; the head's certain starts
    are solved on both chains' workers at once, :func:`mobisense.ocp.batch.worker.solve_start_share`), each
    task started on its worker from its predecessor's converged point. Neither chain of a pair waits for the
    head's strategy to decide: each starts *speculatively* from the best start its own worker solved, and its
    rows are held back until the head is decided — kept if the head's optimum agrees with that start's
    (``solver.agreement``, the strategy's own test of two optima being one), else discarded and the chain solved
    again from the head. Without ``warm_start`` every task starts cold, at most ``in_flight`` (default 2 ×
    workers) at a time. Ctrl-C and SIGTERM are held while dask is waited on and raised (``KeyboardInterrupt``)
    between two results, never inside dask's own code.
    """
    if not payloads:
        return
    run = _TaskRun(client, payloads, on_result, structure_keys, coordinates, warm_start, in_flight)
    with deferred_interrupts(raise_at_exit=False) as deferred, _collector_paused_on_old_objects():
        while run.futures:
            for future in _wait_some(list(run.futures), deferred):
                run.finished(future)
                deferred.check()
            deferred.check()


@contextlib.contextmanager
def _collector_paused_on_old_objects() -> Iterator[None]:
    """Keep the objects that exist now out of Python's cyclic garbage collector until the block ends.

    The client process holds dask's scheduler, whose event loop shares the interpreter: a full collection of
    its ≈ 130 000 objects took 90–130 ms (measured), during which no worker is told that a task's inputs are
    ready — about one such pause per 200-task sweep. :func:`gc.freeze` exempts the objects alive before the run
    (imports, the expanded tasks) from collections; they are unfrozen afterwards, so the process is left as it
    was (unless it had frozen objects itself, which are left alone).
    """
    import gc

    if gc.get_freeze_count():
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


class _TaskRun:
    """The futures of one :func:`run_tasks` call: what each queue (a chain, or the cold tasks) submits next."""

    def __init__(
        self,
        client: Any,
        payloads: list[dict[str, Any]],
        on_result: Callable[[int, dict[str, Any]], None],
        structure_keys: list[Any] | None,
        coordinates: list[np.ndarray] | None,
        warm_start: bool,
        in_flight: int | None,
    ) -> None:
        n = len(payloads)
        self.client, self.payloads, self.on_result, self.warm_start = client, payloads, on_result, warm_start
        self.workers = sorted(client.scheduler_info().get("workers", {})) or [None]
        if warm_start:  # each queue: one chain's links (lists of consecutive tasks), solved by one dask task each
            keys = structure_keys or [None] * n
            order, ring = ring_order(coordinates or [np.zeros(1)] * n, keys)
            plan = pair_chains(order, len(self.workers), ring)
            self.queues = [links for links, _ in plan]
            self.seeded_by = [seed for _, seed in plan]
        else:
            self.queues, self.seeded_by = [ChainLinks(list(range(n)), longest=1)], [None]
        # each queue hands out its next tasks: a chain's links (sized by the pace of its finished tasks, and
        # shared with the chain running towards it), or one cold task at a time
        self.pace: dict[int, float] = {}  # queue -> worker-seconds per task of its latest finished link
        # a chain's next links wait on its worker (their payloads are small), so that the worker never waits for
        # the client (busy writing a batch of results); cold tasks are queued two per worker
        self.limit = CHAIN_AHEAD if warm_start else in_flight or 2 * len(self.workers)
        self.futures: dict[Any, tuple[list[int], int, int]] = {}  # future -> (its tasks, queue, generation)
        self.last: dict[int, Any] = {}  # queue -> its latest future (a chain's next link depends on it)
        self.heads: dict[int, Any] = {}  # queue -> its first future (the head the other chain of a pair starts from)
        self.pending = [0] * len(self.queues)
        self.generation = [0] * len(self.queues)  # a chain solved again (speculation lost) ignores older futures
        # chain -> the chain seeded by its head, on another worker (which helps solve the head's starts)
        self.partner = {s: q for q, s in enumerate(self.seeded_by) if s is not None and self.workers[0] is not None}
        self.speculating: dict[int, Any] = {}  # chain -> the share future it went on from, until the head decides
        self.held: dict[int, list[tuple[list[int], list[dict[str, Any]]]]] = {}  # its finished links meanwhile
        self.handed_on: set[int] = set()  # tasks whose rows went to on_result (a chain solved again skips them)
        for q in range(len(self.queues)):
            self.fill(q)

    def pin(self, q: int) -> dict[str, Any]:
        """Where queue ``q``'s tasks run: on its chain's worker."""
        if self.workers[0] is None:
            return {}
        return {"workers": [self.workers[q % len(self.workers)]], "allow_other_workers": True}

    def fill(self, q: int) -> None:
        """Submit queue ``q``'s next links until :attr:`limit` of them are waiting."""
        while self.pending[q] < self.limit and self.submit_next(q):
            pass

    def submit_next(self, q: int) -> bool:
        """Submit queue ``q``'s next link (or cold task); False when it has none left."""
        tasks = self.queues[q].take(self.pace.get(q))
        if not tasks:  # used up, or its links in flight already hold its share of an arc
            return False
        key = f"task-{tasks[0]}-{time.time_ns()}"
        if not self.warm_start:
            future = self.client.submit(solve_task, self.payloads[tasks[0]], pure=False, key=key)
        else:
            link = [self.payloads[i] for i in tasks]
            seed = self.seeded_by[q]
            before = self.last.get(q, self.heads.get(seed) if seed is not None else None)
            shares, seeds = None, None
            if q not in self.heads and q in self.partner:  # a shared cold head: its certain starts on both workers
                shares = [
                    self.client.submit(
                        solve_start_share, link[0], k, 2, pure=False, key=f"starts-{k}-{key}", **self.pin(chain)
                    )  # fmt: skip
                    for k, chain in enumerate((q, self.partner[q]))
                ]
                if shareable_starts(link[0]):  # both chains go on from their own share's best start
                    self.speculating[q], self.speculating[self.partner[q]] = shares
            elif q not in self.last and q in self.speculating:
                before, seeds = None, self.speculating[q]
            deciding = shares is not None  # the head itself is never speculative: it decides
            future = self.client.submit(solve_chain_link, link, before, shares, seeds,
                                        q in self.speculating and not deciding, pure=False, key=key,
                                        **self.pin(q))  # fmt: skip
            self.heads.setdefault(q, future)
            if deciding and q in self.speculating:  # the chain's next link does not wait for the head
                self.futures[future] = (tasks, q, self.generation[q])
                self.pending[q] += 1
                return True
        self.futures[future] = (tasks, q, self.generation[q])
        self.last[q] = future
        self.pending[q] += 1
        return True

    def finished(self, future: Any) -> None:
        """Take a finished future's rows: hand them on (or hold them, or drop a discarded chain's), submit more."""
        entry = self.futures.pop(future, None)
        if entry is None:  # finished in the same wait as the head whose decision dropped it
            return
        tasks, q, generation = entry
        if generation != self.generation[q]:
            return  # a link of a speculation that was lost: solved again from the head
        self.pending[q] -= 1
        self.queues[q].done(len(tasks))
        try:
            results = future.result() if self.warm_start else [future.result()]
        except Exception as exc:  # noqa: BLE001  (a task's failure is data, not a crash of the sweep)
            results = [{"row": {"status": "error", "error": f"{type(exc).__name__}: {exc}"}} for _ in tasks]
        seconds = [r["row"]["time_s"] for r in results if isinstance(r["row"].get("time_s"), float)]
        if seconds and future is not self.heads.get(q):  # a cold head is no measure of the warm tasks after it
            self.pace[q] = sum(seconds) / len(seconds)
        head = q in self.partner and future is self.heads.get(q)  # a shared cold head, decided
        if q in self.speculating and not head:
            self.held.setdefault(q, []).append((tasks, results))
        elif not results:  # a speculative link with no start, finished after its head agreed with its share
            self.solve_again(q)
            return
        else:
            self.hand_on(tasks, results)
        if head:
            for chain in (self.partner[q], q):
                if chain in self.speculating:
                    self.decide(chain, results[0] if results else None)
        if not (q in self.speculating and not results):  # a speculation without a start waits for the head
            self.fill(q)

    def hand_on(self, tasks: list[int], results: list[dict[str, Any]]) -> None:
        for i, result in zip(tasks, results, strict=True):  # a link's rows are all kept, then Ctrl-C
            result.pop("carry", None)
            self.handed_on.add(i)
            self.on_result(i, result)

    def decide(self, q: int, head: dict[str, Any] | None) -> None:
        """The head chain ``q`` went on from is decided: keep ``q``'s speculative rows, or solve ``q`` again."""
        share = self.speculating.pop(q)
        seed = best_seed(share.result()) if share.done() and share.status == "finished" else None
        row = (head or {}).get("row", {})
        head_task = self.queues[self.owner(q)].first
        agreement = task_problem(self.payloads[head_task]).solver.agreement
        agrees = (
            seed is not None
            and row.get("status") == "solved"
            and abs(seed["cost"] - row["cost"]) <= agreement * abs(row["cost"])
        )
        held = self.held.pop(q, [])
        if agrees and all(results for _, results in held):
            for tasks, results in held:
                self.hand_on(tasks, results)
            return
        self.solve_again(q)

    def owner(self, q: int) -> int:
        """The chain whose first task is the head chain ``q`` went on from (``q`` itself, or its pair's)."""
        return q if self.seeded_by[q] is None else self.seeded_by[q]

    def solve_again(self, q: int) -> None:
        """A speculation of chain ``q`` is lost: forget its futures and solve it again from its head."""
        stale = [f for f, (_, chain, _) in self.futures.items() if chain == q]
        self.client.cancel(stale)
        for f in stale:
            del self.futures[f]
        self.generation[q] += 1
        self.pending[q] = 0
        self.queues[q].restart(self.handed_on)
        if self.owner(q) == q:  # the head's own chain: its head stays solved, the rest is solved again from it
            self.last[q] = self.heads[q]
        else:
            self.last.pop(q, None)
            self.heads.pop(q, None)
        self.fill(q)


def _wait_some(futures: list[Any], deferred: Any) -> list[Any]:
    """The finished ones of ``futures``, waiting in short slices so that a held Ctrl-C is acted on promptly."""
    from dask.distributed import wait

    while True:
        deferred.check()
        try:
            finished, _ = wait(futures, timeout=0.2, return_when="FIRST_COMPLETED")
        except TimeoutError:
            continue
        if finished:
            return [f for f in futures if f in finished]
