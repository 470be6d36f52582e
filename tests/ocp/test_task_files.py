"""A sweep's stacked task files and chain order (fast: synthetic datasets, no solver)."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from mobisense.core.files import write_netcdf
from mobisense.core.netcdf import open_dataset
from mobisense.ocp.batch.chains import ChainLinks, chain_links, cut_chains, pair_chains, snake_order, solve_chain_link
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


def test_pair_chains_run_outwards_from_shared_heads():
    order = list(range(100, 111))  # 11 tasks along the snake
    plan = pair_chains(order, 2)
    (a, seed_a), (b, seed_b) = plan
    assert seed_a is None and seed_b == 0  # one cold head: the second chain starts from the first chain's head
    assert a[0] + 1 == b[0] and a == list(range(a[0], 99, -1)) and b == list(range(b[0], 111))
    assert sorted(a + b) == order and abs(len(a) - len(b)) <= 1
    three = pair_chains(order, 3)  # an odd worker out keeps a chain with its own cold head
    assert [seed for _, seed in three] == [None, 0, None] and sorted(sum((c for c, _ in three), [])) == order
    four = pair_chains(order, 4)
    assert [seed for _, seed in four] == [None, 0, None, 2]
    assert pair_chains([7], 2) == [([7], None)]
