"""The implemented collocation NLP (docs/theory/direct.md §1.7) against independent computations.

* its assembled derivatives (per-interval kernels summed by index maps) against CasADi's own automatic
  differentiation of the plain NLP expression ``(f, g)`` it hands to Ipopt;
* its sizes against the counts of (direct.2)–(direct.3) after the eliminations;
* its optimum against the independent plain transcription of benchmarks/reference_transcription.py (no
  mobisense code: Radau end states, sensor node states and x̃_0 all kept as variables).
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from reference_problems import coupled_two_sensor

from mobisense.ocp.direct.guesses import coasting_start
from mobisense.ocp.direct.transcription import DirectCollocation
from mobisense.ocp.model import Structure
from mobisense.ocp.problem import Problem

ROOT = Path(__file__).resolve().parents[2]


def _reference_module():
    path = ROOT / "benchmarks" / "reference_transcription.py"
    spec = importlib.util.spec_from_file_location("reference_transcription", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def _bounded_problem(K: int) -> Problem:
    """Two sensors, a correlated 2-state process, sensor 1 must stop at tf, sensor 2's |u| is bounded."""
    data = coupled_two_sensor(terminal_velocity=True)
    data["sensors"][1]["u_max"] = 0.5
    data["solver"]["collocation"]["intervals"] = K
    return Problem.from_dict(data)


@pytest.mark.parametrize("scheme", ["radau", "legendre"])
def test_assembled_derivatives_equal_casadi_differentiation_of_the_nlp(scheme):
    problem = _bounded_problem(3)
    tr = DirectCollocation(Structure.of(problem), scheme, 3, 3, codegen="off")
    P, w0 = coasting_start(problem, tr, eps=0.7)
    rng = np.random.default_rng(0)
    w = w0 + 0.1 * rng.standard_normal(tr.nw)  # off the guess: every term of the Hessian is active
    lam_f, lam_g = 0.8, rng.standard_normal(tr.ng)
    nlp = tr.nlp
    x, p = nlp["x"], nlp["p"]
    sf, sg = ca.MX.sym("sf"), ca.MX.sym("sg", tr.ng)
    hess, _ = ca.hessian(sf * nlp["f"] + ca.dot(sg, nlp["g"]), x)
    plain = ca.Function(
        "plain", [x, p, sf, sg], [nlp["f"], nlp["g"], ca.gradient(nlp["f"], x), ca.jacobian(nlp["g"], x), ca.triu(hess)]
    )
    f_ref, g_ref, grad_ref, jac_ref, hess_ref = (np.asarray(ca.densify(v)) for v in plain(w, P, lam_f, lam_g))
    d = tr.derivatives
    f, grad = (np.asarray(ca.densify(v)) for v in d["grad_f"](w, P))
    g, jac = (np.asarray(ca.densify(v)) for v in d["jac_g"](w, P))
    hess_asm = np.asarray(ca.densify(d["hess_lag"](w, P, lam_f, lam_g)))
    # both are exact derivatives of the same expressions, evaluated in a different order: they agree to
    # rounding (1e-12 of the largest entry), far below any error of a wrong index map (O(1) entries)
    for mine, ref in ((f, f_ref), (g, g_ref), (grad, grad_ref), (jac, jac_ref), (hess_asm, hess_ref)):
        assert mine.shape == ref.shape
        np.testing.assert_allclose(mine, ref, rtol=0, atol=1e-12 * max(1.0, np.abs(ref).max()))


@pytest.mark.parametrize("scheme,d", [("radau", 3), ("radau", 2), ("legendre", 3)])
def test_nlp_sizes_are_those_of_the_eliminated_layout(scheme, d):
    K = 7
    problem = _bounded_problem(K)
    s = Structure.of(problem)
    tr = DirectCollocation(s, scheme, d, K, codegen="off")
    ns, nu, N = s.n_sigma, s.nu, s.N
    # docs/theory/direct.md (direct.2): per interval σ at d nodes, u at d nodes, and what it hands on — (p, v)
    # at the interval end with Radau, the whole state with Legendre (no node at τ = 1); rows: those gaps,
    # d·ns collocation rows of σ, d bound rows of the one bounded sensor; + 2 terminal rows (v(tf) of sensor 1)
    handed_on = 4 * N if scheme == "radau" else s.nx
    assert tr.nw == K * (d * ns + d * nu + handed_on) == tr.nlp["x"].numel()
    assert tr.ng == K * (handed_on + d * ns + d * 1) + 2 == tr.nlp["g"].numel()


@pytest.mark.slow
def test_optimum_equals_the_independent_plain_transcription():
    ref_module = _reference_module()
    K = 30
    for n, N in ((1, 2), (2, 2)):
        data = ref_module.synthetic_problem(n, N, 0, intervals=K)
        ref = ref_module.ReferenceOCP(data, intervals=K, tol=1e-11)
        r = ref.solve()
        assert r.success, r.status
        problem = Problem.from_dict({**data, "solver": {**data["solver"], "tolerance": 1e-11}})
        tr = DirectCollocation(Structure.of(problem), "radau", 3, K, tolerance=1e-11)
        P, _ = coasting_start(problem, tr)
        xc = r.x.reshape(K, ref.d, ref.nx)
        w = tr.pack(np.vstack([ref.x0, xc[:, -1]]), xc, r.u.reshape(K, ref.d, -1), P)
        mine = tr.solve(P, w)
        assert mine.success, mine.status
        phi, running, _ = (float(v) for v in tr.cost_terms(mine.w, P))
        # the same NLP after exact eliminations: from the reference's KKT point Ipopt stays there; both solves
        # stop at tol 1e-11 on the scaled error, so J agrees to ~1e-11 — 1e-8 is the requirement
        assert abs(phi + running - r.J) <= 1e-8 * abs(r.J)
        assert mine.iterations <= 20


def test_large_nlp_solves_carry_the_interrupt_check_and_a_spent_budget_does_not_stop_the_next_solve(monkeypatch):
    """Above INTERRUPT_CHECK_VARIABLES every solve runs with the iteration callback, so that Ctrl-C stops Ipopt
    within an iteration; a budgeted solve on it must not leave its budget to the next, unbudgeted one."""
    from mobisense.core import interrupts
    from mobisense.ocp.direct import transcription as module

    problem = _bounded_problem(30)
    tr = DirectCollocation(Structure.of(problem), "radau", 3, 30)
    monkeypatch.setattr(module, "INTERRUPT_CHECK_VARIABLES", tr.nw)  # this NLP counts as large
    P, w0 = coasting_start(problem, tr)
    cut = tr.solve(P, w0, max_iterations=2)
    assert cut.status == "User_Requested_Stop" and cut.iterations == 2
    whole = tr.solve(P, w0)  # the same Ipopt instance (warm = False, callback attached), no budget now
    assert whole.success and whole.iterations > 2, (whole.status, whole.iterations)
    assert len(tr._solvers) == 1  # one instance serves both
    # a signal arriving during the third iteration (what the callback sees): Ipopt stops there
    from mobisense.ocp.direct import iteration_limit

    calls = []
    monkeypatch.setattr(iteration_limit, "interrupt_received", lambda: calls.append(1) or len(calls) >= 3)
    stopped = tr.solve(P, w0)
    assert stopped.status == "User_Requested_Stop" and stopped.iterations == 2  # Ipopt counts from iteration 0
    # a signal recorded before Ipopt starts: nothing is solved, the interrupt is raised
    monkeypatch.setattr(interrupts, "_received", [2])
    with pytest.raises(KeyboardInterrupt):
        tr.solve(P, w0)
    monkeypatch.setattr(interrupts, "_received", [])
    monkeypatch.undo()
    monkeypatch.setattr(module, "INTERRUPT_CHECK_VARIABLES", tr.nw + 1)  # now small: no callback, a new instance
    assert tr.solve(P, w0).success and len(tr._solvers) == 2


def test_watched_iterations_are_reported_with_ipopts_objective_and_violation(monkeypatch):
    """Inside watch_iterations a solve with the callback reports each iteration: counted from 0, the last one
    Ipopt's final objective and a violation within its tolerance; a listener that raises is dropped, the solve
    goes on."""
    from mobisense.ocp.direct import transcription as module
    from mobisense.ocp.direct.iteration_limit import watch_iterations

    problem = _bounded_problem(20)
    tr = DirectCollocation(Structure.of(problem), "radau", 3, 20)
    monkeypatch.setattr(module, "INTERRUPT_CHECK_VARIABLES", tr.nw)
    P, w0 = coasting_start(problem, tr)
    seen = []
    with watch_iterations(seen.append):
        result = tr.solve(P, w0)
    assert result.success
    assert [it.iteration for it in seen] == list(range(result.iterations + 1))  # iteration 0 is the start
    assert seen[-1].objective == pytest.approx(result.objective, rel=1e-12)
    # the scaled violation at convergence: Ipopt's tol 1e-9 bounds it (its constr_viol_tol 1e-4 is looser)
    assert seen[-1].violation <= 1e-8
    assert seen[0].violation > 1e-3  # the coasting guess breaks the terminal velocity of sensor 1

    def broken(_):
        raise RuntimeError("a display error")

    with watch_iterations(broken):
        again = tr.solve(P, w0)
    assert again.success and again.iterations == result.iterations  # the same solve, undisturbed
    seen.clear()
    again = tr.solve(P, w0)  # outside the block: nothing reported
    assert seen == []


def test_coasting_start_scales_the_cost_as_the_solver_does_however_small():
    """The cost scale is the coasting cost itself, also below 1e-8 (docs/theory/direct.md §1.3).

    ``coasting_start`` (the tests' and benchmarks' cold start) once floored it at 1e-8 while the solver did not,
    so the two started different NLPs on a problem of tiny cost; here M = 20e-20 gives J_coast ≈ 1.6e-17.
    """
    from reference_problems import hussein2008

    from mobisense.ocp.direct.guesses import coasting_baseline

    data = hussein2008()
    data["cost"]["M"] = [[20e-20]]
    problem = Problem.from_dict(data)
    tr = DirectCollocation(Structure.of(problem), "radau", 3, 20, codegen="off")
    P, _ = coasting_start(problem, tr)
    t = np.array([problem.horizon.t0, problem.horizon.tf])
    j_coast = coasting_baseline(problem, t, tr).cost
    assert 0 < j_coast < 1e-15
    # the same coasting integration on the same grid: equal to round-off (1e-12 relative)
    np.testing.assert_allclose(np.asarray(tr.layout.unpack(P)["cost_scale"]).item(), j_coast, rtol=1e-12)
