"""Both chains of a pair start from their own share of the head's starts, before the head is decided.

run_tasks is driven here through an in-process stand-in for dask's client whose futures finish in the order a
test chooses, so that both outcomes of the speculation happen for certain: the head's optimum agrees with
the partner's start (its rows, held back until then, are kept) or it does not (they are dropped and the chain
is solved again from the head; the disagreement is made by showing the client a seed of twice its cost). The
solves are real (K = 20); on a real cluster, tests/ocp/test_batch.py.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest
from reference_problems import hussein2008

import mobisense.ocp.batch.engine as engine
from mobisense.ocp.batch.engine import run_tasks
from mobisense.ocp.direct.solver import solve_direct
from mobisense.ocp.problem import Problem


class _Future:
    """A task that runs when it is first asked for its result (its inputs first)."""

    def __init__(self, client: _Client, fn: Any, args: tuple, key: str) -> None:
        self.client, self.fn, self.args, self.key = client, fn, args, key
        self.value: Any = None
        self.ran = False

    def compute(self) -> Any:
        if not self.ran:
            args = [a.compute() if isinstance(a, _Future) else a for a in self.args]
            args = [[x.compute() if isinstance(x, _Future) else x for x in a] if isinstance(a, list) else a
                    for a in args]  # fmt: skip
            self.value, self.ran = self.fn(*args), True
            self.client.ran.append(self.key)
        return self.value

    def result(self) -> Any:
        return copy.deepcopy(self.compute())  # the client's own copy, as dask's serialisation gives it

    def done(self) -> bool:
        return self.ran

    @property
    def status(self) -> str:
        return "finished" if self.ran else "pending"


class _Client:
    workers = {"tcp://a": {}, "tcp://b": {}}

    def __init__(self) -> None:
        self.submitted: list[_Future] = []
        self.ran: list[str] = []
        self.cancelled: list[str] = []

    def scheduler_info(self) -> dict[str, Any]:
        return {"workers": self.workers}

    def submit(self, fn: Any, *args: Any, key: str = "", **_: Any) -> _Future:
        future = _Future(self, fn, args, key)
        self.submitted.append(future)
        return future

    def cancel(self, futures: list[_Future]) -> None:
        self.cancelled += [f.key for f in futures]


def _payloads() -> list[dict[str, Any]]:
    payloads = []
    for alpha in (0.002, 0.0025, 0.003, 0.0035, 0.004, 0.0045):
        data = hussein2008(collocation={"intervals": 20})
        data["cost"]["alpha"] = alpha
        payloads.append({"problem": Problem.from_dict(data)})
    return payloads


def _seeds_seen_twice_as_costly(monkeypatch: pytest.MonkeyPatch) -> None:
    """The client's view of every share's start: another optimum, twice as costly (the speculation is lost)."""
    real = engine.best_seed

    def far_seed(records: list[dict[str, Any]]) -> dict[str, Any] | None:
        seed = real(records)
        return None if seed is None else {**seed, "cost": 2 * seed["cost"]}

    monkeypatch.setattr(engine, "best_seed", far_seed)


def _run(
    payloads: list[dict[str, Any]],
    monkeypatch: pytest.MonkeyPatch,
    partner_links_first: int,
    together: bool = False,
    own_links_first: int = 0,
) -> tuple[_Client, list[tuple[int, dict]]]:
    """run_tasks on 2 stand-in workers; ``partner_links_first`` links of the partner chain finish before the head.

    With 6 tasks on a line, the head chain is tasks 2, 1, 0 (its head is task 2) and the partner chain 3, 4, 5;
    ``own_links_first`` links of the head's own chain after the head finish before it too.
    ``together``: the head and the partner's next link are reported finished by the same wait, the head first.
    """
    client, rows, finished_partner, finished_own = _Client(), [], [], []

    def rank(future: _Future) -> tuple[int, str]:
        task = int(future.key.split("-")[1])
        if task >= 3 and len(finished_partner) < partner_links_first:
            return 0, future.key
        if task < 2 and len(finished_own) < own_links_first:
            return 0, future.key
        return (1 if task == 2 else 2 if task < 3 else 3), future.key

    def wait_some(futures: list[_Future], deferred: Any) -> list[_Future]:
        first = min(futures, key=rank)
        first.compute()
        if int(first.key.split("-")[1]) >= 3:
            finished_partner.append(first.key)
        elif int(first.key.split("-")[1]) < 2:
            finished_own.append(first.key)
        partner = [f for f in futures if int(f.key.split("-")[1]) >= 3]
        if together and first.key.startswith("task-2-") and partner:
            partner[0].compute()
            return [first, partner[0]]
        return [first]

    monkeypatch.setattr(engine, "_wait_some", wait_some)
    coordinates = [np.array([float(i)]) for i in range(len(payloads))]
    run_tasks(client, payloads, lambda i, r: rows.append((i, r["row"])), coordinates=coordinates)
    return client, rows


@pytest.mark.slow
def test_a_partner_chain_that_agrees_with_the_head_keeps_its_rows(monkeypatch):
    payloads = _payloads()
    client, rows = _run(payloads, monkeypatch, partner_links_first=2)  # the whole partner chain before the head
    assert sorted(i for i, _ in rows) == list(range(6))  # every task once
    assert client.cancelled == [] and sum(k.startswith("task-3-") for k in client.ran) == 1  # nothing solved again
    # the partner's rows were held back until the head was decided: the head's row comes first
    assert rows[0][0] == 2 and rows[0][1]["start"] != "warm start from init"
    assert [i for i, _ in rows[1:4]] == [3, 4, 5]
    for i, row in rows:  # each the optimum of its own problem
        assert row["status"] == "solved" and (row["start"] == "warm start from init") == (i != 2)
        assert row["cost"] == pytest.approx(solve_direct(payloads[i]["problem"]).cost, rel=1e-8)


@pytest.mark.slow
def test_a_partner_chain_that_disagrees_with_the_head_is_solved_again_from_it(monkeypatch):
    payloads = _payloads()
    _seeds_seen_twice_as_costly(monkeypatch)
    client, rows = _run(payloads, monkeypatch, partner_links_first=1)
    assert sorted(i for i, _ in rows) == list(range(6))  # every task once: the speculative rows were dropped
    assert [k for k in client.cancelled if k.startswith("task-4-")]  # the speculative link still waiting
    assert sum(k.startswith("task-3-") for k in client.ran) == 2  # solved speculatively, then again from the head
    assert rows[0][0] == 2 and [i for i, _ in rows].index(3) > 0
    for i, row in rows:
        assert row["status"] == "solved"
        assert row["cost"] == pytest.approx(solve_direct(payloads[i]["problem"]).cost, rel=1e-8)


@pytest.mark.slow
def test_a_partner_link_finished_with_the_head_that_drops_it_is_ignored(monkeypatch):
    payloads = _payloads()
    _seeds_seen_twice_as_costly(monkeypatch)
    _, rows = _run(payloads, monkeypatch, partner_links_first=1, together=True)
    assert sorted(i for i, _ in rows) == list(range(6))  # every task once, none from the dropped speculation
    assert all(row["status"] == "solved" for _, row in rows)


@pytest.mark.slow
def test_a_speculation_without_a_start_waits_for_the_head(monkeypatch):
    # the partner's share reached no usable start (all its starts failed): its links solve nothing, and the
    # chain is solved from the head once that is decided — no task is solved cold by the partner
    import mobisense.ocp.batch.chains as chains

    payloads = _payloads()
    monkeypatch.setattr(chains, "best_seed", lambda records: None)  # what the partner's worker sees
    client, rows = _run(payloads, monkeypatch, partner_links_first=2)
    assert sorted(i for i, _ in rows) == list(range(6))
    assert all(row["status"] == "solved" for _, row in rows)
    partner = [row for i, row in rows if i >= 3]
    assert all(row["start"] == "warm start from init" for row in partner)  # from the head, not cold


@pytest.mark.slow
def test_the_head_chain_goes_on_before_its_head_is_decided_and_keeps_its_rows(monkeypatch):
    # the head's own chain (tasks 1, 0 after the head 2) starts from its own share's best start too: both its
    # links finish before the head (the other share is slower), their rows are held, then kept
    payloads = _payloads()
    client, rows = _run(payloads, monkeypatch, partner_links_first=2, own_links_first=2)
    assert sorted(i for i, _ in rows) == list(range(6))
    firsts = [k.split("-")[1] for k in client.ran if k.startswith("task-")]  # each link by its first task
    assert client.cancelled == [] and len(firsts) == len(set(firsts)) == 4  # [2], [1, 0], [3], [4, 5]: once each
    assert rows[0][0] == 2  # the head's row first: every other row waited for its decision
    for i, row in rows:
        assert row["status"] == "solved" and (row["start"] == "warm start from init") == (i != 2)
        assert row["cost"] == pytest.approx(solve_direct(payloads[i]["problem"]).cost, rel=1e-8)


@pytest.mark.slow
def test_a_head_chain_that_disagrees_with_its_head_is_solved_again_after_it(monkeypatch):
    payloads = _payloads()
    _seeds_seen_twice_as_costly(monkeypatch)
    client, rows = _run(payloads, monkeypatch, partner_links_first=1, own_links_first=1)
    assert sorted(i for i, _ in rows) == list(range(6))  # every task once; the head is not solved again
    assert sum(k.startswith("task-2-") for k in client.ran) == 1
    assert sum(k.startswith("task-1-") for k in client.ran) == 2  # speculatively, then again from the head
    for i, row in rows:
        assert row["status"] == "solved"
        assert row["cost"] == pytest.approx(solve_direct(payloads[i]["problem"]).cost, rel=1e-8)
