"""Buffered CasADi calls give the plain call's bits; the per-parameter memory recomputes only for new vectors."""

from __future__ import annotations

import threading

import casadi as ca
import numpy as np
import pytest

from mobisense.ocp.direct.numeric_calls import BufferedFunction, ParameterMemo


def _function() -> ca.Function:
    a, b, s = ca.SX.sym("a", 3, 4), ca.SX.sym("b", 4), ca.SX.sym("s")
    return ca.Function("f", [a, b, s], [ca.mtimes(a, b) * s, ca.sin(a).T, ca.sum1(ca.sum2(a)) + s], ["a", "b", "s"],
                       ["ab", "sin_at", "total"])  # fmt: skip


def test_results_are_the_plain_calls_bits_in_its_shapes():
    f, rng = _function(), np.random.default_rng(1)
    buffered = BufferedFunction(f)
    for _ in range(5):  # the buffer is re-used: each call's results are its own
        a, b, s = rng.standard_normal((3, 4)), rng.standard_normal(4), float(rng.standard_normal())
        plain = [np.asarray(v) for v in f(a, b, s)]
        mine = buffered(a, b, s)
        for p, m in zip(plain, mine, strict=True):
            assert m.shape == p.shape and np.array_equal(m, p)
        named, _ = buffered.call({"a": a, "b": b, "s": s})
        assert np.array_equal(named["sin_at"], plain[1])
    first = buffered(a, b, s)[0]
    buffered(a * 2, b, s)
    assert np.array_equal(first, np.asarray(f(a, b, s)[0]))  # results are copies, not views of the buffer


def test_wrong_shapes_and_names_are_refused():
    buffered = BufferedFunction(_function())
    with pytest.raises(ValueError, match="input a has shape"):
        buffered(np.zeros((4, 3)), np.zeros(4), 1.0)  # the transpose: same size, other meaning
    with pytest.raises(ValueError, match="expected 3 arguments"):
        buffered(np.zeros((3, 4)), np.zeros(4))
    with pytest.raises(ValueError, match="unknown inputs"):
        buffered.call({"c": 1.0})


def test_sparse_functions_are_called_the_plain_way():
    x = ca.SX.sym("x", 3)
    f = ca.Function("f", [x], [ca.diag(x)])  # a sparse result
    buffered = BufferedFunction(f)
    assert not buffered.dense
    assert np.array_equal(buffered(np.array([1.0, 2.0, 3.0])), np.diag([1.0, 2.0, 3.0]))


def test_threads_each_use_their_own_buffer():
    f = _function()
    buffered = BufferedFunction(f)
    errors = []

    def work(seed: int) -> None:
        rng = np.random.default_rng(seed)
        for _ in range(300):
            a, b = rng.standard_normal((3, 4)), rng.standard_normal(4)
            if not np.array_equal(buffered(a, b, 1.5)[0], np.asarray(f(a, b, 1.5)[0])):
                errors.append(seed)

    threads = [threading.Thread(target=work, args=(seed,)) for seed in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []


def test_an_nlp_solve_through_the_buffer_is_the_plain_solve():
    # the transcription's Ipopt calls: same iterate, multipliers, status and iteration count, bit for bit
    from mobisense.ocp.direct.guesses import coasting_start
    from mobisense.ocp.direct.transcription import transcription_for
    from mobisense.ocp.problem import load_problem

    problem = load_problem("hussein2008").with_solver(collocation={"intervals": 20})
    tr = transcription_for(problem)
    P, w0 = coasting_start(problem, tr)
    mine = tr.solve(P, w0)
    lbw, ubw, lbg, ubg = tr.bounds()
    solver = tr._solver(False).function
    plain = solver(x0=w0, p=P, lbx=lbw, ubx=ubw, lbg=lbg, ubg=ubg)
    assert mine.success and mine.iterations == solver.stats()["iter_count"]
    assert np.array_equal(mine.w, np.asarray(plain["x"]).ravel())
    assert np.array_equal(mine.lam_g, np.asarray(plain["lam_g"]).ravel())
    assert mine.objective == float(plain["f"])
    warm = tr.solve(P, mine.w, mine.lam_w, mine.lam_g)
    plain = tr._solver(True).function(x0=mine.w, p=P, lbx=lbw, ubx=ubw, lbg=lbg, ubg=ubg, lam_x0=mine.lam_w,
                                      lam_g0=mine.lam_g)  # fmt: skip
    assert np.array_equal(warm.w, np.asarray(plain["x"]).ravel())


def test_a_failing_evaluation_raises_casadis_own_error():
    x = ca.MX.sym("x", 2)
    nlp = {"x": x, "f": (x[0] - 1) ** 2 + 100 * (x[1] - x[0] ** 2) ** 2}
    options = {"ipopt": {"max_iter": 1, "print_level": 0, "sb": "yes"}, "print_time": False}
    failing = BufferedFunction(ca.nlpsol("s", "ipopt", nlp, {**options, "error_on_fail": True}))
    with pytest.raises(RuntimeError, match="nlpsol process failed"):
        failing.call({"x0": [-1.2, 1.0]})
    quiet = BufferedFunction(ca.nlpsol("s", "ipopt", nlp, {**options, "error_on_fail": False}))
    _, stats = quiet.call({"x0": [-1.2, 1.0]})
    assert stats["return_status"] == "Maximum_Iterations_Exceeded"


def test_the_parameter_memory_recomputes_only_for_new_vectors_and_is_bounded():
    memo, calls = ParameterMemo(size=3), []

    def compute(P: np.ndarray) -> np.ndarray:
        calls.append(P.copy())
        return 2 * P

    P = np.arange(4.0)
    first = memo.get("double", P, compute)
    assert np.array_equal(memo.get("double", P.copy(), compute), 2 * P) and len(calls) == 1
    with pytest.raises(ValueError, match="read-only"):
        first[0] = 5.0
    memo.get("double", P + 1e-15 * (P + 1), compute)  # any other vector, however close, is another entry
    assert len(calls) == 2
    for k in range(5):
        memo.get("double", P + k + 10, compute)
    memo.get("double", P, compute)  # forgotten: only the last three vectors are kept
    assert len(calls) == 8
