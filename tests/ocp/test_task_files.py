"""A sweep's stacked task files and chain order (fast: synthetic datasets, no solver)."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from mobisense.core.files import write_netcdf
from mobisense.core.netcdf import open_dataset
from mobisense.ocp.batch.chains import (
    ChainLinks,
    chain_links,
    cut_chains,
    pair_chains,
    ring_order,
    snake_order,
    solve_chain_link,
)
from mobisense.ocp.batch.engine import CHAIN_AHEAD
from mobisense.ocp.task_files import shape_key, stack_tasks, task_dataset


def _solution_like(k: int, horizon: float) -> xr.Dataset:
    t = np.linspace(0.0, horizon, 7)
    rng = np.random.default_rng(k)
    data = {
        "p": (("time", "sensor", "xy"), rng.normal(size=(7, 2, 2)), {"long_name": "sensor position", "units": "m"}),
        "nlp_w": (("nlp_variable",), rng.normal(size=11), {"long_name": "w", "units": "1"}),
    }
    coords = {"time": ("time", t, {"long_name": "time", "units": "s"}), "sensor": ["s1", "s2"], "xy": ["x", "y"]}
    attrs = {"problem_yaml": f"name: task{k}\n", "status": "solved", "eps": 1.0, "terminal_cost": 0.1 * k}
    return xr.Dataset(data, coords=coords, attrs=attrs)


def test_stacked_file_gives_back_each_task_as_written_alone(tmp_path):
    # tasks 3 and 5 share the time grid, task 8 another one: 'time' becomes a per-task variable
    datasets = [_solution_like(3, 10.0), _solution_like(5, 10.0), _solution_like(8, 12.0)]
    assert len({shape_key(ds) for ds in datasets}) == 1
    write_netcdf(tmp_path / "part.nc", stack_tasks(datasets, [3, 5, 8], ["a", "b", "c"]))
    stacked = open_dataset(tmp_path / "part.nc")
    for index, ds in zip([3, 5, 8], datasets, strict=True):
        write_netcdf(tmp_path / f"{index}.nc", ds)
        alone = open_dataset(tmp_path / f"{index}.nc")
        back = task_dataset(stacked, index)
        for d in (alone, back):
            d.attrs.pop("history")  # the write time
        xr.testing.assert_identical(back, alone)  # values bit for bit, attributes, coordinates and labels
    with pytest.raises(KeyError, match="task 4 is not in this file"):
        task_dataset(stacked, 4)


def test_datasets_of_other_shapes_are_not_stacked():
    small = _solution_like(1, 10.0).isel(nlp_variable=slice(0, 5))
    with pytest.raises(ValueError, match="differ"):
        stack_tasks([_solution_like(0, 10.0), small], [0, 1], ["a", "b"])


def test_snake_order_visits_grid_neighbours_and_keeps_structures_together():
    # a 3 × 4 grid (index = 4 i + j): every step of the snake changes one value by one grid step
    coords = [np.array([i, j], float) for i in range(3) for j in range(4)]
    order = snake_order(coords)
    assert sorted(order) == list(range(12))
    steps = [np.abs(coords[a] - coords[b]).sum() for a, b in zip(order, order[1:], strict=False)]
    assert steps == [1.0] * 11
    # three columns, an even number of values in the middle one: the walk still moves one step at a time
    cube = [np.array([i, j, k], float) for i in range(3) for j in range(4) for k in range(2)]
    walk = snake_order(cube)
    assert sorted(walk) == list(range(24))
    assert [np.abs(cube[a] - cube[b]).sum() for a, b in zip(walk, walk[1:], strict=False)] == [1.0] * 23
    keys = ["A" if k % 2 else "B" for k in range(12)]
    grouped = snake_order(coords, keys)
    assert {keys[k] for k in grouped[:6]} == {"B"} and {keys[k] for k in grouped[6:]} == {"A"}
    chains = cut_chains(order, 5)
    assert [len(c) for c in chains] == [2, 3, 2, 3, 2] and sum(chains, []) == order
    assert cut_chains(order[:1], 4) == [order[:1]]


def test_chain_links_double_up_to_the_longest_and_keep_the_order():
    chain = list(range(30, 0, -1))
    links = chain_links(chain, longest=8)
    assert [len(link) for link in links] == [1, 2, 4, 8, 8, 7] and sum(links, []) == chain
    assert chain_links([5], longest=8) == [[5]] and chain_links([]) == []
    assert [len(link) for link in chain_links(list(range(5)), longest=1)] == [1] * 5


def test_chain_links_hold_about_link_seconds_once_the_pace_is_known():
    queue = ChainLinks(list(range(100)), longest=32, seconds=0.5)
    sizes = [len(queue.take()) for _ in range(3)]  # no pace yet: 1, 2, 4
    sizes += [len(queue.take(0.007)) for _ in range(3)]  # fast tasks (7 ms): doubling goes on up to 32
    sizes.append(len(queue.take(0.2)))  # 0.2 s per task: 0.5 s holds 2 tasks
    sizes.append(len(queue.take(3.0)))  # slower than a link's worth: one task at a time
    sizes.append(len(queue.take(0.007)))  # fast again: doubling starts over from the last size
    assert sizes == [1, 2, 4, 8, 16, 32, 2, 1, 2]
    rest = []
    while (link := queue.take(0.001)) is not None:
        rest += link
    assert rest == list(range(sum(sizes), 100))  # every task once, in order


def test_a_chain_link_starts_each_task_from_the_one_before(monkeypatch):
    import mobisense.ocp.batch.worker as worker

    seen = []

    def fake_solve(payload):  # records the seed it was given; converges to its own label (or fails on "bad")
        seen.append(payload["seed"])
        if payload["problem"] == "bad":
            raise RuntimeError("no")
        return {"row": {"status": "solved"}, "nlp": payload["problem"]}

    monkeypatch.setattr(worker, "solve_task", fake_solve)
    results = solve_chain_link([{"problem": p} for p in ("a", "b", "bad", "c")], [{"carry": "start"}])
    assert seen == ["start", "a", "b", "b"]  # after a failure the next task starts from the point before it
    assert [r["row"]["status"] for r in results] == ["solved", "solved", "error", "solved"]
    assert ["carry" in r for r in results] == [False, False, False, True] and results[-1]["carry"] == "c"
    assert not any("nlp" in r for r in results)  # the client receives one NLP point per link, not one per task


def _drain(links: ChainLinks) -> list[int]:
    """Every task of a chain, in order, taking its links until it is used up."""
    out = []
    while (link := links.take()) is not None:
        assert link, "a chain alone on its arc never waits"
        out += link
        links.done(len(link))
    return out


def test_pair_chains_run_outwards_from_shared_heads():
    order = list(range(100, 111))  # 11 tasks along the snake
    plan = pair_chains(order, 2)
    (a_links, seed_a), (b_links, seed_b) = plan
    assert seed_a is None and seed_b == 0  # one cold head: the second chain starts from the first chain's head
    a, b = _drain(a_links), _drain(b_links)
    assert a[0] + 1 == b[0] and a == list(range(a[0], 99, -1)) and b == list(range(b[0], 111))
    assert sorted(a + b) == order and abs(len(a) - len(b)) <= 1
    three = pair_chains(order, 3)  # an odd worker out keeps a chain with its own cold head
    assert [seed for _, seed in three] == [None, 0, None]
    assert sorted(sum((_drain(c) for c, _ in three), [])) == order
    four = pair_chains(order, 4)
    assert [seed for _, seed in four] == [None, 0, None, 2]
    one = pair_chains([7], 2)
    assert [(_drain(c), seed) for c, seed in one] == [([7], None)]


def _cycle_steps(coords, order):
    return [float(np.abs(coords[a] - coords[b]).sum()) for a, b in zip(order, order[1:] + order[:1], strict=True)]


@pytest.mark.parametrize("shape", [(4, 3), (3, 4), (2, 2), (40, 5), (3, 2, 3)])
def test_ring_order_closes_a_grid_with_an_even_side_into_a_cycle_of_unit_steps(shape):
    coords = [np.array(c, float) for c in np.ndindex(*shape)]
    order, ring = ring_order(coords)
    assert ring and sorted(order) == list(range(len(coords)))
    assert _cycle_steps(coords, order) == [1.0] * len(coords)  # the last task neighbours the first too


def test_ring_order_keeps_the_path_where_no_cycle_exists():
    odd = [np.array(c, float) for c in np.ndindex(3, 3)]  # 9 tasks on a grid: bipartite, odd -> no cycle
    line = [np.array([k], float) for k in range(6)]  # a zip sweep: a line
    holes = odd[:-1] + [np.array([5.0, 5.0])]  # not a full product
    for coords in (odd, line, holes):
        order, ring = ring_order(coords)
        assert not ring and order == snake_order(coords)
    two = [np.array(c, float) for c in np.ndindex(4, 2)]  # two structures: never one ring across them
    assert ring_order(two, ["A"] * 4 + ["B"] * 4) == (snake_order(two, ["A"] * 4 + ["B"] * 4), False)
    # a varied value given as a list (two correlated columns) counts as one column of the grid
    arc = [np.array([a, np.cos(t), np.sin(t)]) for a in range(4) for t in np.linspace(0, 1, 5)]
    order, ring = ring_order(arc)
    assert ring and sorted(order) == list(range(20))


def _run_pair(paces: tuple[float, float], starts: tuple[float, float]) -> tuple[list[list[int]], list[float], list]:
    """An event simulation of the engine on a ring of 40 × 5 tasks, two chains from one head.

    Each chain solves its links in turn at its own pace (seconds per task) from its start time, with the
    engine's CHAIN_AHEAD links in flight, taking a new link whenever one of either chain's finishes. Returns
    the tasks each solved, their end times and the ring order.
    """
    coords = [np.array(c, float) for c in np.ndindex(40, 5)]
    order, ring = ring_order(coords)
    chains = [links for links, _ in pair_chains(order, 2, ring)]
    clock, queues, solved = list(starts), [[], []], [[], []]

    def fill(k):
        while len(queues[k]) < CHAIN_AHEAD and (link := chains[k].take(paces[k])):
            queues[k].append(link)

    fill(0), fill(1)
    while queues[0] or queues[1]:
        k = min((c for c in (0, 1) if queues[c]), key=lambda c: clock[c] + len(queues[c][0]) * paces[c])
        link = queues[k].pop(0)
        clock[k] += len(link) * paces[k]
        solved[k] += link
        chains[k].done(len(link))
        fill(0), fill(1)
    return solved, clock, order


def test_chains_sharing_an_arc_meet_where_both_end_together():
    # the benchmark sweep's case: equal paces (6.9 ms), the head's chain starting 0.16 s after the other one
    solved, clock, order = _run_pair((0.0069, 0.0069), (0.39, 0.23))
    assert sorted(solved[0] + solved[1]) == list(range(200))  # every task once
    head = order.index(solved[0][0])  # the head, its neighbours on either side next, then outwards
    assert solved[1][0] == order[head + 1] and solved[0][1] == order[head - 1]
    # they end within one task of each other (measured 5.6 ms); halves cut in advance end 0.16 s apart
    assert abs(clock[0] - clock[1]) <= 0.0069
    assert len(solved[1]) - len(solved[0]) == pytest.approx(0.16 / 0.0069, abs=2)
    # one worker twice as fast, starting 0.2 s later: the ends within two of the slower chain's tasks
    # (measured 8 ms: a link in flight cannot be taken back; halves cut in advance: 0.2 s apart)
    solved, clock, _ = _run_pair((0.004, 0.008), (0.2, 0.0))
    assert sorted(solved[0] + solved[1]) == list(range(200))
    assert abs(clock[0] - clock[1]) <= 2 * 0.008
    # both busy until T: (T − 0.2)/0.004 + T/0.008 = 200 tasks, T = 0.667 s, the fast chain's share 116.7 tasks
    assert len(solved[0]) == pytest.approx(116.7, abs=3)


def test_a_restarted_chain_hands_out_again_what_it_took():
    links = ChainLinks([1, 2, 3, 4, 5, 6])
    first = links.take() + links.take()
    assert first == [1, 2, 3] and links.in_flight == 3
    links.restart()  # its rows were dropped (a lost speculation): solved again from the first
    assert links.in_flight == 0 and _drain(links) == [1, 2, 3, 4, 5, 6]
