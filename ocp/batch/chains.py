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

import math
from collections.abc import Collection
from typing import Any

import numpy as np

__all__ = [
    "LINK_TASKS",
    "LINK_SECONDS",
    "SHARE_PARTS",
    "ChainLinks",
    "snake_order",
    "cut_chains",
    "ring_order",
    "Arc",
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
#: a link taken from an arc shared with another chain holds at most this fraction (1/SHARE_PARTS) of the tasks the
#: chain still has to take for both to end together (in a model of the 200-task benchmark sweep with 2 links in
#: flight per chain, the two chains end 0.9 ms apart with 25 links in all; taking up to half: 28 ms apart, 18 links)
SHARE_PARTS = 3


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


def ring_order(coordinates: list[np.ndarray], keys: list[Any] | None = None) -> tuple[list[int], bool]:
    """The chain order, closed into a ring where the sweep's grid has one (else :func:`snake_order`'s path).

    A grid whose first varied column (with more than one value) has ``m`` values, each with the same snake
    of ``L`` combinations of the other columns, is an ``m × L`` grid of unit steps; it has a Hamiltonian cycle
    when ``m`` or ``L`` is even (both at least 2): rows 1 … L−1 of each column in turn, back and forth, and home
    along row 0. On a ring the chains that run towards each other from two cold heads meet wherever the work
    balances (:class:`Arc`), instead of each ending at a fixed end of the path. One problem structure only
    (a ring across structures would join tasks that cannot warm-start each other).

    Parameters
    ----------
    coordinates : list of ndarray, shape (D,)
        Each task's varied values as numbers.
    keys : list, optional
        Each task's structure key.

    Returns
    -------
    order : list of int
        A permutation of ``range(len(coordinates))``, consecutive tasks differing in one value by one step.
    ring : bool
        Whether the last task also neighbours the first.
    """
    path = snake_order(coordinates, keys)
    n = len(coordinates)
    if n < 4 or (keys is not None and len({repr(k) for k in keys}) > 1):
        return path, False
    matrix = np.stack([np.atleast_1d(np.asarray(c, float)) for c in coordinates])
    matrix = matrix[:, [j for j in range(matrix.shape[1]) if len(np.unique(matrix[:, j])) > 1]]
    if matrix.shape[1] < 2:
        return path, False
    levels = np.unique(matrix[:, 0])
    rows = [_snake(matrix, [i for i in range(n) if matrix[i, 0] == level], 1, False) for level in levels]
    m, length = len(rows), len(rows[0])
    if length < 2 or any(not np.array_equal(matrix[r, 1:], matrix[rows[0], 1:]) for r in rows):
        return path, False  # not a full product of the first column and one snake of the others
    if m % 2 == 0:  # along each column's rows 1 … L−1, back and forth, then home along row 0
        cycle = [(c, r) for c in range(m) for r in (range(1, length) if c % 2 == 0 else range(length - 1, 0, -1))]
        cycle += [(c, 0) for c in range(m - 1, -1, -1)]
    elif length % 2 == 0:  # the same with the roles of columns and rows exchanged
        cycle = [(c, r) for r in range(length) for c in (range(1, m) if r % 2 == 0 else range(m - 1, 0, -1))]
        cycle += [(0, r) for r in range(length - 1, -1, -1)]
    else:
        return path, False  # an odd number of tasks on a grid: no cycle of unit steps exists
    return [rows[c][r] for c, r in cycle], True


class Arc:
    """Consecutive tasks of the chain order between two chains' starts, taken from both ends.

    The chain running forwards from the head on the arc's left takes its first tasks, the chain running
    backwards from the head on its right its last ones (:class:`ChainLinks`); where they meet depends on how
    fast each runs, so that both end together.
    """

    def __init__(self, tasks: list[int]) -> None:
        self.tasks, self.first, self.stop = list(tasks), 0, len(tasks)
        self.ends: list[ChainLinks] = []  # the chains taking from it (one or two)

    @property
    def remaining(self) -> int:
        """Tasks not taken yet."""
        return self.stop - self.first

    def pop(self, backwards: bool, size: int) -> list[int]:
        """Take ``size`` tasks (fewer when fewer are left): the first ones, or with ``backwards`` the last ones."""
        size = max(0, min(size, self.remaining))
        if backwards:
            self.stop -= size
            return self.tasks[self.stop : self.stop + size][::-1]
        self.first += size
        return self.tasks[self.first - size : self.first]


def pair_chains(order: list[int], workers: int, ring: bool = False) -> list[tuple[ChainLinks, int | None]]:
    """Chains for ``workers`` workers that share cold heads: two chains run outwards from each head.

    ``order`` is cut into one piece per worker (:func:`cut_chains`); the pieces are paired, and the pair
    ``(P, Q)`` becomes the chain ``P`` backwards — its first task ``P[-1]`` solved cold, the *head* — and the
    chain ``Q``, whose first task neighbours the head in ``order`` and starts from the head's solution. A
    cold head costs 20–35 warm tasks on bench_sweep_overhead.py's sweep (0.37–0.6 s against 18 ms), so
    paying it once per pair instead of once per chain shortens the parallel run; ``Q``'s worker waits for it
    (≈ one head), then both run. An odd worker out keeps a piece with its own cold head, run forwards.

    The tasks between two heads are one :class:`Arc`, taken from both ends by the chains that run towards
    each other (``Q`` of one pair, ``P`` of the next; on a ``ring`` also the last chain and the first), so that
    the pieces' lengths adapt to how fast each worker gets through its cold-head work and its tasks.

    Returns
    -------
    list of (links, seeded_by)
        Each chain's :class:`ChainLinks`, and the index (in this list) of the chain whose head its first task
        starts from, or None for a chain that starts cold.
    """
    pieces = cut_chains(order, workers)
    # per chain: (its own first tasks, the tasks it takes from the arc before / after its start)
    chains: list[tuple[list[int], int | None, bool]] = []  # (own, seeded_by, runs backwards)
    spans: list[list[int]] = []  # the tasks each chain runs through after its own, in its direction of travel
    for k in range(0, len(pieces), 2):
        if k + 1 == len(pieces):
            chains.append((pieces[k][:1], None, False))
            spans.append(pieces[k][1:])
            break
        chains.append((pieces[k][-1:], None, True))
        spans.append(pieces[k][-2::-1])
        chains.append(([], len(chains) - 1, False))
        spans.append(pieces[k + 1])
    # join each forward span with the backward span that follows it on the order (around the ring on a ring)
    arcs: list[Arc | None] = [None] * len(chains)
    for c, (_, _, backwards) in enumerate(chains):
        if backwards:
            continue
        nxt = c + 1 if c + 1 < len(chains) else (0 if ring and len(chains) > 1 else None)
        if nxt is not None and chains[nxt][2] and arcs[nxt] is None:
            arcs[c] = arcs[nxt] = Arc(spans[c] + spans[nxt][::-1])
    plan = []
    for c, (own, seeded_by, backwards) in enumerate(chains):
        arc = arcs[c] or Arc(spans[c][::-1] if backwards else spans[c])
        plan.append((ChainLinks(own, arc=arc, backwards=backwards), seeded_by))
    return plan


class ChainLinks:
    """A chain's links, sized as they are taken: 1, 2, 4, … tasks, at most ``longest`` and about ``seconds`` each.

    The first link is the chain's cold head alone (its result, and the sweep's first rows, come back as soon as
    it is solved); the links then double, so that a long chain of fast tasks costs few dask round trips, until a
    link would take longer than ``seconds`` at the pace measured so far (:meth:`take`'s ``seconds_per_task``), so
    that a chain of slow tasks still reports progress and an interrupted sweep loses little.

    After its own tasks ``chain`` the chain goes on through ``arc`` (from its start, or with ``backwards`` from
    its end). When another chain takes from the other end of the same arc, a link holds at most a
    :data:`SHARE_PARTS`-th of what this chain still has to take for both to end together — the arc's tasks
    left and both chains' tasks in flight (:meth:`done`), shared in proportion to their paces — and nothing
    while its tasks in flight already cover that share.

    Parameters
    ----------
    chain : list of int
        Task positions in solving order.
    longest : int
        The most tasks in one link.
    seconds : float
        The work one link should hold (s), once the pace of the chain's tasks is known.
    arc : Arc, optional
        Where the chain goes on after ``chain``.
    backwards : bool
        Take ``arc``'s tasks from its end.
    """

    def __init__(
        self,
        chain: list[int],
        longest: int = LINK_TASKS,
        seconds: float = LINK_SECONDS,
        arc: Arc | None = None,
        backwards: bool = False,
    ) -> None:
        self.chain, self.longest, self.seconds = list(chain), max(1, longest), seconds
        self.arc, self.backwards = arc, backwards
        if arc is not None:
            arc.ends.append(self)
        self.start, self.size = 0, 1
        self.taken: list[int] = []  # every task handed out, in order (:meth:`restart` solves them again)
        self.in_flight = 0  # tasks handed out and not yet reported :meth:`done`
        self.pace: float | None = None  # seconds per task, as last given to :meth:`take`

    @property
    def first(self) -> int | None:
        """The chain's first task (its head, or the first of its arc), or None if it has none."""
        if self.chain:
            return self.chain[0]
        if self.arc is None or not self.arc.tasks:
            return None
        return self.arc.tasks[-1] if self.backwards else self.arc.tasks[0]

    def take(self, seconds_per_task: float | None = None) -> list[int] | None:
        """The next link: None when the chain is used up, ``[]`` when it should wait for a link in flight.

        ``seconds_per_task`` is the chain's measured pace, if known.
        """
        if seconds_per_task is not None and seconds_per_task > 0:
            self.pace = seconds_per_task
        size = self.size
        if self.pace is not None:
            size = max(1, min(size, int(self.seconds / self.pace)))
        if self.start < len(self.chain):
            link = self.chain[self.start : self.start + size]
            self.start += len(link)
        elif self.arc is not None and self.arc.remaining:
            size = min(size, self._fair_share())
            link = self.arc.pop(self.backwards, size)
        else:
            return None
        self.size = min(2 * max(1, len(link)), self.longest)
        self.taken += link
        self.in_flight += len(link)
        return link

    def _fair_share(self) -> int:
        """The most tasks this link may take from a shared arc (0: wait for the tasks in flight)."""
        arc = self.arc
        others = [] if arc is None else [c for c in arc.ends if c is not self]
        if arc is None or not others:
            return self.longest
        paces = [c.pace for c in (self, *others) if c.pace]
        default = sum(paces) / len(paces) if paces else 1.0
        rates = [1.0 / (c.pace or default) for c in (self, *others)]
        work = arc.remaining + sum(c.in_flight for c in (self, *others))
        share = work * rates[0] / sum(rates) - self.in_flight  # tasks still to take to end with the others
        if share <= 0:
            return 0 if self.in_flight else 1
        return max(1, math.ceil(share / SHARE_PARTS))

    def done(self, count: int) -> None:
        """``count`` tasks handed out have finished (or will not be solved)."""
        self.in_flight = max(0, self.in_flight - count)

    def restart(self, solved: Collection[int] = ()) -> None:
        """Hand out again every task taken so far but those ``solved`` (a chain solved again from another start)."""
        again = [i for i in self.taken if i not in solved]
        self.chain, self.taken = again + self.chain[self.start :], [i for i in self.taken if i in solved]
        self.start, self.size, self.in_flight = 0, 1, 0


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
