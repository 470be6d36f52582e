"""Solve strategies (docs/theory/direct.md §5.6) and the background kernel compile (§1.7)."""

from __future__ import annotations

import os
import time

import casadi as ca
import numpy as np
import pytest
from reference_problems import hussein2008

from mobisense.ocp.direct.kernel_cache import load_compiled
from mobisense.ocp.direct.solver import solve_direct, solve_starts
from mobisense.ocp.direct.strategy import certain_starts, share_starts
from mobisense.ocp.problem import Problem


def costs_of(solution) -> list[float | None]:  # noqa: ANN001
    return [s["cost"] for s in solution.stats["strategy"]["starts"]]


def agreeing(costs: list[float | None], rtol: float) -> int:
    solved = [c for c in costs if c is not None]
    lowest = min(solved)
    return sum(c <= lowest + rtol * abs(lowest) for c in solved)


@pytest.mark.slow
@pytest.mark.parametrize("consensus", [1, 2, 3])
def test_auto_draws_random_starts_until_consensus(consensus):
    problem = Problem.from_dict(hussein2008(collocation={"intervals": 20}, consensus=consensus))
    solution = solve_direct(problem)
    costs = costs_of(solution)
    labels = [s["start"] for s in solution.stats["strategy"]["starts"]]
    rtol = problem.solver.agreement
    drawn = [label for label in labels if label != "homotopy"]  # the continuation comes last, if at all
    assert drawn == ["cold"] + [f"random start {k}" for k in range(1, len(drawn))] and labels[: len(drawn)] == drawn
    starts = costs[: len(drawn)]
    # stopped exactly when `consensus` starts reached the lowest cost, or after every random start
    assert agreeing(starts, rtol) >= consensus or len(drawn) == 1 + problem.solver.starts
    assert len(drawn) == 1 or agreeing(starts[:-1], rtol) < consensus
    # the continuation only when the starts never agreed
    assert ("homotopy" in labels) == (agreeing(starts, rtol) < consensus)
    # the kept solution is the lowest cost found, its J recomputed from the reported trajectory
    assert solution.cost == pytest.approx(min(c for c in costs if c is not None), rel=1e-9)


def test_certain_starts_are_the_ones_auto_cannot_skip():
    def labels(**options):
        return certain_starts(Problem.from_dict(hussein2008(collocation={"intervals": 20}, **options)))

    assert labels() == ["cold", "random start 1", "random start 2"]  # consensus 3: two random starts at least
    assert labels(consensus=1) == ["cold"] and labels(consensus=5, starts=2) == labels(consensus=3)
    assert labels(strategy="thorough") == [] and labels(strategy="cold") == []
    assert share_starts(labels(), 2) == [["cold", "random start 1"], ["random start 2"]]
    assert share_starts(["cold"], 2) == [["cold"], []] and share_starts(labels(), 1) == [labels()]
    assert sum(share_starts(labels(consensus=6), 3), []) == labels(consensus=6)  # contiguous, in order


@pytest.mark.slow
def test_starts_solved_elsewhere_give_the_solve_that_solved_them_itself():
    # the records of solve_starts, handed in, stand for those starts: same decision, same bits, same steps
    problem = Problem.from_dict(hussein2008(collocation={"intervals": 20}))
    alone = solve_direct(problem)
    shares = share_starts(certain_starts(problem), 2)
    records = solve_starts(problem, shares[1]) + solve_starts(problem, shares[0])  # in any order
    steps = []
    adopted = solve_direct(problem, progress=steps.append, solved_elsewhere=records)
    assert adopted.cost == alone.cost and np.array_equal(adopted.u, alone.u)
    assert adopted.stats["strategy"] == alone.stats["strategy"]
    assert [(s.start, s.iterations, s.cost) for s in adopted.homotopy] == [
        (s.start, s.iterations, s.cost) for s in alone.homotopy
    ]
    assert [s.start for s in steps] == [s.start for s in alone.homotopy]  # reported as if solved here
    assert all(r["seconds"] > 0 for r in records)
    # another problem's records are not adopted: its own starts are solved
    data = hussein2008(collocation={"intervals": 20})
    data["cost"]["alpha"] = 0.02
    other = Problem.from_dict(data)
    mixed = solve_direct(other, solved_elsewhere=records)
    assert mixed.cost == solve_direct(other).cost != alone.cost


@pytest.mark.slow
def test_background_compile_serves_the_next_run(tmp_path):
    # a cache miss with background=True answers at once with the virtual-machine functions; a detached process
    # compiles them, after which the same key loads the library, whose values equal the SX function's
    x = ca.SX.sym("x", 3)
    functions = {"bg_kernel": ca.Function("bg_kernel", [x], [ca.sin(x) * x[0] + x[2] ** 2])}
    t0 = time.perf_counter()
    first, how = load_compiled(functions, "test key", tmp_path, background=True)
    assert time.perf_counter() - t0 < 1.0  # nothing compiled in this process (a compile takes seconds)
    assert first is functions and "background" in how
    again, how_again = load_compiled(functions, "test key", tmp_path, background=True)
    assert again is functions and "another process" in how_again  # no second compile of the same key
    other = {"bg_other": ca.Function("bg_other", [x], [ca.cos(x)])}
    waiting, how_other = load_compiled(other, "another key", tmp_path, background=True)
    assert waiting is other and "later run" in how_other  # one background compiler at a time
    assert not list(tmp_path.glob(".kernels_*bg_other*"))  # nothing saved for the key left waiting
    deadline = time.time() + 120
    done = lambda: list(tmp_path.glob("kernels_*.so")) and not list(tmp_path.glob(".kernels_*"))  # noqa: E731
    while not done() and time.time() < deadline:
        time.sleep(0.2)
    loaded, how = load_compiled(functions, "test key", tmp_path, background=True)
    assert how == "compiled (cached)"
    point = [0.3, -1.2, 2.0]
    np.testing.assert_allclose(np.asarray(loaded["bg_kernel"](point)), np.asarray(functions["bg_kernel"](point)))
    assert not list(tmp_path.glob(".kernels_*"))  # saved functions, source and marker removed


def test_the_cache_keeps_the_most_recently_used_libraries(tmp_path):
    from mobisense.ocp.direct.kernel_cache import prune

    for k in range(5):  # five libraries, used k seconds apart (the oldest first), each with its key file
        library = tmp_path / f"kernels_{k:020d}.so"
        library.write_bytes(b"x")
        library.with_suffix(".json").write_text("{}")
        os.utime(library, (1000.0 + k, 1000.0 + k))
    os.utime(tmp_path / f"kernels_{0:020d}.so", (2000.0, 2000.0))  # the oldest was loaded again last
    removed = prune(tmp_path, keep=3)
    assert sorted(p.name for p in removed) == [f"kernels_{1:020d}.so", f"kernels_{2:020d}.so"]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        f"kernels_{k:020d}.{ext}" for k in (0, 3, 4) for ext in ("so", "json")
    )


def test_when_no_start_converges_the_one_that_got_furthest_is_kept():
    # every Ipopt call stops at once (1e-9 s): no start solves any ε, so the tie goes to the first start, the
    # cold solve, whose Ipopt status and worst-violated constraint are reported — not the continuation, which
    # had no iterations left to try anything (its budget is what the starts took: 0)
    problem = Problem.from_dict(hussein2008(collocation={"intervals": 20}, time_limit=1e-9))
    solution = solve_direct(problem)
    assert solution.status == "failed" and solution.stats["strategy"]["kept"] == "cold"
    assert [s["start"] for s in solution.stats["strategy"]["starts"]][-1] == "homotopy"  # it was there
    assert solution.message.startswith("Ipopt returned Maximum_WallTime_Exceeded at ε = 1; last ε solved = 0;")


def test_a_kept_start_that_never_failed_on_its_own_says_why_it_did_not_converge(monkeypatch):
    # a strategy (a plug-in, say) that keeps a continuation whose budget was spent before its first step:
    # the message must not claim convergence; it names the budget and the last Ipopt failure of the solve
    import mobisense.ocp.direct.strategy as strategy

    def spent(ctx):  # noqa: ANN001, ANN202
        runs = [strategy.solve_labelled(ctx, "cold"), ctx.start("homotopy", budget=0)]
        assert not runs[1].attempt(0.05) and runs[1].failed is None  # nothing tried: no failure of its own
        return runs, runs[1]

    # what run_strategy runs for strategy "cold" in this test (a valid name; no registry entry added)
    monkeypatch.setattr(strategy, "STRATEGIES", {"cold": spent})
    problem = Problem.from_dict(hussein2008(collocation={"intervals": 20}, time_limit=1e-9, strategy="cold"))
    solution = solve_direct(problem)
    assert solution.status == "failed"
    assert solution.message == (
        "no start converged at ε = 1: homotopy stopped at ε = 0 (its iteration budget was used up); "
        "the last failure: Ipopt returned Maximum_WallTime_Exceeded at ε = 1 (cold)"
    )


def test_a_continuation_cut_by_its_budget_is_reported_when_homotopy_was_asked_for():
    # strategy homotopy with the default budget (1.5 × the cold solve's iterations) falls back to the cold solve
    # when the 21-step continuation costs more (K = 40: stopped before its first step); the user is told
    import mobisense as ms

    def solved(budget):
        data = hussein2008(collocation={"intervals": 40}, strategy="homotopy",
                           homotopy={"mode": "fixed", "step": 0.05, "budget": budget})  # fmt: skip
        return ms.solve(ms.Problem.from_dict(data))

    cut = solved(1.5)
    assert cut.stats["strategy"]["kept"] == "cold"
    warning = cut.summary()["warning"]
    reached = next(s for s in cut.stats["strategy"]["starts"] if s["start"] == "homotopy")["eps_reached"]
    # "stopped at ε = 0" read as a step at ε = 0 (red team): ε = 0 solved is the coasting start, no step yet
    where = f"after solving ε = {reached:g}" if reached > 0 else "within its first ε step"
    assert warning.startswith(f"strategy homotopy: the continuation stopped {where} when it spent its budget")
    assert "spent its budget of" in warning and "the cold solve's plan is kept" in warning
    free = solved(None)  # no budget: the continuation runs to ε = 1 and is kept, nothing to say
    assert free.stats["strategy"]["kept"] == "homotopy" and "warning" not in free.summary()


@pytest.mark.slow
def test_thorough_gives_the_continuation_as_many_iterations_as_the_other_starts_took():
    # three states, three sensors (reference-optima audit): the cold solve and two random starts agree on
    # J = 19.99940 and auto stops there; the continuation budgeted by 1.5 × the cold solve's 56 iterations was cut
    # short, so thorough kept 19.74653 (random start 4). Given as many iterations as the other starts took, it
    # reaches 19.65240935: the audit's own transcription (Gauss–Legendre, 20 starts, K = 100 … 400) converged to
    # 19.6524093514, so 1e-8 relative is the grid's error at K = 100 (mobisense at K = 400: 19.65240935 too)
    data = {
        "name": "three_states_three_sensors",
        "horizon": {"t0": 0.0, "tf": 5.0},
        "process": {"A": [[-0.2, 0.3, 0.0], [-0.3, -0.2, 0.1], [0.0, 0.0, 0.1]], "B": np.eye(3).tolist(),
                    "Q": [[0.5, 0.1, 0.0], [0.1, 0.5, 0.0], [0.0, 0.0, 0.3]],
                    "Sigma0": [[10.0, 1.0, 0.0], [1.0, 10.0, 0.0], [0.0, 0.0, 15.0]],
                    "locations": [[0.0, 0.0], [3.0, 4.0], [-4.0, 2.0]]},
        "sensors": [
            {"name": "s1", "p0": [5.0, -2.0], "v0": [0.0, 0.0], "terminal": {"p": [2.0, 2.0]},
             "noise": {"model": "quadratic_range", "beta": 1.0, "gamma": 1.0}},
            {"name": "s2", "p0": [-5.0, -3.0], "v0": [0.5, 0.5], "measures": [[1.0, 0.0, 1.0]],
             "noise": {"model": "quadratic_range", "beta": 0.5, "gamma": 2.0}},
            {"name": "s3", "p0": [0.0, 7.0], "v0": [0.0, -1.0], "measures": [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
             "noise": {"model": "quadratic_range", "beta": 2.0, "gamma": 0.5}},
        ],
        "cost": {"M": [[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.5]],
                 "K": [[0.5, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.0, 0.2]], "alpha": 0.05},
        "solver": {"strategy": "thorough"},
    }  # fmt: skip
    solution = solve_direct(Problem.from_dict(data))
    record = solution.stats["strategy"]
    starts = {s["start"]: s for s in record["starts"]}
    assert record["kept"] == "homotopy" and solution.cost == pytest.approx(19.6524093514, rel=1e-8)
    others = sum(s["iterations"] for label, s in starts.items() if label != "homotopy")
    assert record["homotopy_budget"] == others > 1.5 * starts["cold"]["iterations"]
    assert min(s["cost"] for label, s in starts.items() if label != "homotopy") > solution.cost * (1 + 1e-3)
