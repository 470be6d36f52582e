"""Chains of neighbouring tasks: the order in which one worker solves its share of a warm-started sweep.

A warm start is only as good as the neighbour it comes from, and handing each finished point back through the
client costs a dask round trip per task. So the client orders the tasks along the sweep's grid (tasks of one
problem structure together; within one, a boustrophedon — snake — over the sorted varied values, so that
consecutive tasks differ in one value by one step), cuts that path into one contiguous chain per worker, and
submits each chain as dependent tasks pinned to its worker: every task receives its predecessor's result on the
worker itself and starts from its primal–dual point, while the client only collects the results.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["snake_order", "cut_chains", "solve_in_chain"]


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
    """Sort ``members`` by column ``dim``, each group of equal values by the next columns, alternating direction."""
    if dim == matrix.shape[1] or len(members) <= 1:
        return members[::-1] if reverse else members
    values = matrix[members, dim]
    levels = np.unique(values)
    if reverse:
        levels = levels[::-1]
    out: list[int] = []
    for k, level in enumerate(levels):
        group = [m for m, v in zip(members, values, strict=True) if v == level]
        out += _snake(matrix, group, dim + 1, bool(k % 2) != reverse)
    return out


def cut_chains(order: list[int], chains: int) -> list[list[int]]:
    """Cut ``order`` into ``chains`` contiguous pieces of nearly equal length (no empty piece)."""
    chains = max(1, min(chains, len(order)))
    bounds = np.linspace(0, len(order), chains + 1).round().astype(int)
    return [order[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True) if b > a]


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
    result["carry"] = result.get("nlp") if result.get("nlp") is not None else seed
    return result
