"""Distributed solving on dask.distributed: sweeps and multi-start, resumable and fault-tolerant.

Tasks carry plain data (problem dicts, numpy arrays), never CasADi objects; each worker process builds and caches the
transcription of a problem structure (:func:`mobisense.ocp.direct.solver.transcription_for`) and re-solves it with new
parameters. Warm-started tasks run in chains of neighbours, one per worker (:mod:`mobisense.ocp.batch.chains`): each
task is started on its worker from its predecessor's primal–dual point (re-scaled by
:meth:`DirectCollocation.transfer`), without a round trip through the client, and one dask task solves a link of
up to :data:`~mobisense.ocp.batch.chains.LINK_TASKS` consecutive tasks. A task that raises, or whose worker
dies more often than dask retries, becomes a row with ``status = "error"``; nothing stops the sweep.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from ...core.errors import ConfigError
from ...core.interrupts import deferred_interrupts
from .chains import chain_links, pair_chains, snake_order, solve_chain_link
from .cluster import CONNECT_TIMEOUT
from .worker import solve_start_share, solve_task

__all__ = ["open_client", "run_tasks", "CHAIN_AHEAD"]

#: links of one chain submitted ahead of their results (a link is up to LINK_TASKS tasks)
CHAIN_AHEAD = 4


@contextlib.contextmanager
def open_client(scheduler: str | None, workers: int | None, security: Any = None) -> Iterator[Any]:
    """A dask Client: on ``scheduler`` (``tls://…``, ``tcp://…``) or on a LocalCluster of ``workers`` processes.

    A scheduler that does not answer within :data:`CONNECT_TIMEOUT` seconds raises ``ConfigError``. Local
    workers ignore SIGINT (:func:`mobisense.ocp.batch.worker.dask_setup`), so Ctrl-C stops the client, which
    closes them, without a traceback from every worker.
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
        with client:
            deferred.check()
            yield client
        return
    n = workers or os.cpu_count() or 1
    # the scheduler's HTTP server (no dashboard here) falls back to a free port when 8787 is taken: not news
    warnings.filterwarnings("ignore", message="Port .* is already in use", category=UserWarning)
    # dask sets MALLOC_TRIM_THRESHOLD_ in its workers, which also freezes glibc's mmap threshold: MUMPS' large
    # per-factorisation workspaces then go through mmap/munmap and page faults. Unset it for our workers.
    with (
        dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}),
        deferred_interrupts(raise_at_exit=False) as deferred,
    ):
        cluster = LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=50,
            preload=["mobisense.ocp.batch.worker"],  # its dask_setup: workers ignore Ctrl-C (the client stops them)
        )
        try:
            client = Client(cluster)
        except BaseException:
            cluster.close()
            raise
    with cluster, client:
        deferred.check()  # Ctrl-C or SIGTERM during the start: stop now, closing the cluster cleanly
        yield client


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
    task started on its worker from its predecessor's converged point; without, every task starts cold, at most
    ``in_flight`` (default 2 × workers) at a time. Ctrl-C and SIGTERM are held while dask is waited on and raised
    (``KeyboardInterrupt``) between two results, never inside dask's own code.
    """
    n = len(payloads)
    if n == 0:
        return
    keys = structure_keys or [None] * n
    coords = coordinates or [np.zeros(1)] * n
    workers = sorted(client.scheduler_info().get("workers", {})) or [None]
    seeded_by: list[int | None] = [None]
    if warm_start:  # each queue: one chain's links (lists of consecutive tasks), solved by one dask task each
        plan = pair_chains(snake_order(coords, keys), len(workers))
        queues = [iter(chain_links(chain)) for chain, _ in plan]
        seeded_by = [seed for _, seed in plan]
    else:
        queues = [iter([i] for i in range(n))]
    # a chain's next links wait on its worker (their payloads are small), so that the worker never waits for the
    # client (busy writing a batch of results); cold tasks are queued two per worker
    limit = CHAIN_AHEAD if warm_start else in_flight or 2 * len(workers)
    futures: dict[Any, tuple[list[int], int]] = {}  # future -> (its tasks, queue)
    last: dict[int, Any] = {}  # queue -> its latest future (a chain's next link depends on it)
    heads: dict[int, Any] = {}  # queue -> its first future (the head the other chain of a pair starts from)
    pending = [0] * len(queues)
    # chain -> the chain seeded by its head, on another worker (which would wait for the head: it helps solve it)
    partner = {seed: q for q, seed in enumerate(seeded_by) if seed is not None and workers[0] is not None}

    def pin(q: int) -> dict[str, Any]:
        return {"workers": [workers[q % len(workers)]], "allow_other_workers": True} if workers[0] else {}

    def submit_next(q: int) -> bool:
        tasks = next(queues[q], None)
        if tasks is None:
            return False
        key = f"task-{tasks[0]}-{time.time_ns()}"
        if warm_start:
            link = [payloads[i] for i in tasks]
            before = last.get(q, heads.get(seeded_by[q]) if seeded_by[q] is not None else None)
            shares = None
            if q not in heads and q in partner:  # a shared cold head: its certain starts on both workers at once
                shares = [
                    client.submit(solve_start_share, link[0], k, 2, pure=False, key=f"starts-{k}-{key}", **pin(chain))
                    for k, chain in enumerate((q, partner[q]))
                ]
            future = client.submit(solve_chain_link, link, before, shares, pure=False, key=key, **pin(q))
            heads.setdefault(q, future)
        else:
            future = client.submit(solve_task, payloads[tasks[0]], pure=False, key=key)
        futures[future] = (tasks, q)
        last[q] = future
        pending[q] += 1
        return True

    for q in range(len(queues)):
        for _ in range(limit):
            submit_next(q)
    with deferred_interrupts(raise_at_exit=False) as deferred:
        while futures:
            done = _wait_some(list(futures), deferred)
            for future in done:
                tasks, q = futures.pop(future)
                pending[q] -= 1
                try:
                    results = future.result() if warm_start else [future.result()]
                except Exception as exc:  # noqa: BLE001  (a task's failure is data, not a crash of the sweep)
                    results = [{"row": {"status": "error", "error": f"{type(exc).__name__}: {exc}"}} for _ in tasks]
                for i, result in zip(tasks, results, strict=True):  # a link's rows are all kept, then Ctrl-C
                    result.pop("carry", None)
                    on_result(i, result)
                deferred.check()
                while pending[q] < limit and submit_next(q):
                    pass
            deferred.check()


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
