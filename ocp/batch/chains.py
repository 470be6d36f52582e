"""Chains of neighbouring tasks: the order in which one worker solves its share of a warm-started sweep.

A warm start is only as good as the neighbour it comes from, and handing each finished point back through the
client costs a dask round trip per task. So the client orders the tasks along the sweep's grid (tasks of one
problem structure together; within one, a boustrophedon — snake — over the sorted varied values, so that
consecutive tasks differ in one value by one step), cuts that path into one contiguous piece per worker, pairs
the pieces so that two chains run outwards from one cold head (:func:`pair_chains`), and submits each chain as
dependent dask tasks pinned to its worker: every task receives its predecessor's result on the worker itself
(the second chain of a pair receives the head's, once) and starts from its primal–dual point, while the client
only collects the results. One dask
task solves a *link* of consecutive tasks (:class:`ChainLinks`: 1, 2, 4, … up to :data:`LINK_TASKS` at a time, and
about :data:`LINK_SECONDS` of work once the chain's pace is known), so that dask's round trip (≈ 20 ms on two
cores) is paid once per link, not once per warm solve (≈ 10 ms).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = [
    "LINK_TASKS",
    "LINK_SECONDS",
    "ChainLinks",
    "snake_order",
    "cut_chains",
    "pair_chains",
    "chain_links",
    "solve_in_chain",
    "solve_chain_link",
    "best_seed",
]

#: the most tasks one dask task of a chain solves (the first links are shorter: results come early) …
LINK_TASKS = 32
#: … and the work (s) it holds once the chain's pace is known (:class:`ChainLinks`)
LINK_SECONDS = 0.5


def snake_order(coordinates: list[np.ndarray], keys: list[Any] | None = None) -> list[int]:
    """Task positions in chain order: grouped by structure ``keys``, a snake over the ``coordinates``.

    Parameters
    ----------
    coordinates : list of ndarray, shape (D,)
        Each task's varied values as numbers (:func:`mobisense.ocp.batch.sweep.value_coordinates`).
    keys : list, optional
        Each task's structure key (tasks of one structure are kept together, in first-seen order).

    Returns
    -------
    list of int
        A permutation of ``range(len(coordinates))``.
    """
    n = len(coordinates)
    if n == 0:
        return []
    keys = keys if keys is not None else [None] * n
    groups: dict[Any, list[int]] = {}
    for i, key in enumerate(keys):
        groups.setdefault(repr(key), []).append(i)
    matrix = np.stack([np.atleast_1d(np.asarray(c, float)) for c in coordinates])
    order: list[int] = []
    for members in groups.values():
        order += _snake(matrix, members, 0, False)
    return order


def _snake(matrix: np.ndarray, members: list[int], dim: int, reverse: bool) -> list[int]:
    """Sort ``members`` by column ``dim``, each group of equal values by the next columns, alternating direction.

    The boustrophedon of the grid: the ``k``-th value of column ``dim`` (ascending) is crossed forwards in the
    next columns when ``k`` is even, backwards when odd; a ``reverse`` walk is the forward one backwards (so
    consecutive tasks still differ in one column by one step, whatever the number of values in each column).
    """
    if dim == matrix.shape[1] or len(members) <= 1:
        return members[::-1] if reverse else members
    values = matrix[members, dim]
    out: list[int] = []
    for k, level in enumerate(np.unique(values)):
        group = [m for m, v in zip(members, values, strict=True) if v == level]
        out += _snake(matrix, group, dim + 1, bool(k % 2))
    return out[::-1] if reverse else out


def cut_chains(order: list[int], chains: int) -> list[list[int]]:
    """Cut ``order`` into ``chains`` contiguous pieces of nearly equal length (no empty piece)."""
    chains = max(1, min(chains, len(order)))
    bounds = np.linspace(0, len(order), chains + 1).round().astype(int)
    return [order[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True) if b > a]


def pair_chains(order: list[int], workers: int) -> list[tuple[list[int], int | None]]:
    """Chains for ``workers`` workers that share cold heads: two chains run outwards from each head.

    ``order`` is cut into one piece per worker (:func:`cut_chains`); the pieces are paired, and the pair
    ``(P, Q)`` becomes the chain ``P`` backwards — its first task ``P[-1]`` solved cold, the *head* — and the
    chain ``Q``, whose first task neighbours the head in ``order`` and starts from the head's solution. A
    cold head costs 20–35 warm tasks on bench_sweep_overhead.py's sweep (0.37–0.6 s against 18 ms), so
    paying it once per pair instead of once per chain shortens the parallel run; ``Q``'s worker waits for it
    (≈ one head), then both run. An odd worker out keeps a piece with its own cold head.

    Returns
    -------
    list of (chain, seeded_by)
        Each chain's task positions in solving order, and the index (in this list) of the chain whose head
        its first task starts from, or None for a chain that starts cold.
    """
    pieces = cut_chains(order, workers)
    plan: list[tuple[list[int], int | None]] = []
    for k in range(0, len(pieces), 2):
        if k + 1 == len(pieces):
            plan.append((pieces[k], None))
            break
        plan.append((pieces[k][::-1], None))
        plan.append((pieces[k + 1], len(plan) - 1))
    return plan


class ChainLinks:
    """A chain's links, sized as they are taken: 1, 2, 4, … tasks, at most ``longest`` and about ``seconds`` each.

    The first link is the chain's cold head alone (its result, and the sweep's first rows, come back as soon as
    it is solved); the links then double, so that a long chain of fast tasks costs few dask round trips, until a
    link would take longer than ``seconds`` at the pace measured so far (:meth:`take`'s ``seconds_per_task``), so
    that a chain of slow tasks still reports progress and an interrupted sweep loses little.

    Parameters
    ----------
    chain : list of int
        Task positions in solving order.
    longest : int
        The most tasks in one link.
    seconds : float
        The work one link should hold (s), once the pace of the chain's tasks is known.
    """

    def __init__(self, chain: list[int], longest: int = LINK_TASKS, seconds: float = LINK_SECONDS) -> None:
        self.chain, self.longest, self.seconds = chain, max(1, longest), seconds
        self.start, self.size = 0, 1

    def take(self, seconds_per_task: float | None = None) -> list[int] | None:
        """The next link (None when the chain is used up), given the measured seconds per task if known."""
        if self.start >= len(self.chain):
            return None
        size = self.size
        if seconds_per_task is not None and seconds_per_task > 0:
            size = max(1, min(size, int(self.seconds / seconds_per_task)))
        link = self.chain[self.start : self.start + size]
        self.start += size
        self.size = min(2 * size, self.longest)
        return link


def chain_links(chain: list[int], longest: int = LINK_TASKS) -> list[list[int]]:
    """The links of ``chain`` when no pace is known (:class:`ChainLinks`): 1, 2, 4, … tasks, at most ``longest``."""
    links, queue = [], ChainLinks(chain, longest)
    while (link := queue.take()) is not None:
        links.append(link)
    return links


def solve_chain_link(
    payloads: list[dict[str, Any]],
    previous: list[dict[str, Any]] | None = None,
    shares: list[list[dict[str, Any]]] | None = None,
    seeds: list[dict[str, Any]] | None = None,
    speculative: bool = False,
) -> list[dict]:
    """Worker side: solve a link of consecutive chain tasks, each warm-started from the one before.

    ``previous`` is the preceding link's result (its last task's ``carry`` starts this link). ``shares`` are
    the first task's starts solved on several workers (:func:`mobisense.ocp.batch.worker.solve_start_share`),
    adopted by its strategy. ``seeds`` are such start records of a neighbouring task: the link starts from the
    lowest-cost one that reached ε = 1 (:func:`best_seed`). A ``speculative`` link (one started before the
    neighbour's strategy has decided, see :func:`mobisense.ocp.batch.engine.run_tasks`) with nothing to start
    from solves nothing and returns ``[]`` rather than solving its first task cold. Otherwise one
    :func:`solve_in_chain` result per payload; only the last keeps ``carry`` (the next link's start).
    """
    before = best_seed(seeds) if seeds is not None else (previous[-1] if previous else None)
    if speculative and (before is None or before.get("carry") is None):
        return []
    if shares:
        payloads = [{**payloads[0], "solved_elsewhere": [r for share in shares for r in share]}, *payloads[1:]]
    results = []
    for payload in payloads:
        before = solve_in_chain(payload, before)
        results.append(before)
    for result in results[:-1]:
        result.pop("carry", None)
    return results


def best_seed(records: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The lowest-cost start record that reached ε = 1, as a chain predecessor; None if none did.

    ``records`` come from :func:`mobisense.ocp.direct.solver.solve_starts`; the predecessor is
    ``{"carry": its primal–dual point, "cost": its J}``.
    """
    solved = [r for r in records if r.get("carry") is not None and r.get("cost") is not None]
    if not solved:
        return None
    best = min(solved, key=lambda r: r["cost"])
    return {"carry": best["carry"], "cost": best["cost"]}


def solve_in_chain(payload: dict[str, Any], previous: dict[str, Any] | None = None) -> dict[str, Any]:
    """Worker side: solve one task warm-started from its chain predecessor's result (``previous``).

    The predecessor's converged NLP point — or, if it did not converge, the point it was itself started from —
    is the warm start. A task that raises becomes an ``error`` row (its successors still run, from the point
    before it). The result is :func:`mobisense.ocp.batch.worker.solve_task`'s, plus ``carry``: the point the
    next task of the chain starts from.
    """
    from .worker import solve_task

    seed = None if previous is None else previous.get("carry")
    try:
        result = solve_task({**payload, "seed": seed})
    except Exception as exc:  # noqa: BLE001  (a task's failure is data, not the end of its chain)
        result = {"row": {"status": "error", "error": f"{type(exc).__name__}: {exc}"}}
    nlp = result.pop("nlp", None)  # the client has no use for it: only the chain's next task does
    result["carry"] = nlp if nlp is not None else seed
    return result
