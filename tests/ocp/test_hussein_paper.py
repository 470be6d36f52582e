"""Hussein (2008), §IV–V: Σ(t) along the ε-homotopy (Fig. 1(b)) and the paper's own continuation method —
natural-parameter steps of δ = 0.05 from the Kalman solution — with scipy's solve_bvp.

Theory: docs/theory/indirect.md §3.4 and §3.5.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from reference_problems import hussein2008

from mobisense.ocp.direct.solver import solve_direct
from mobisense.ocp.homotopy import fixed_schedule
from mobisense.ocp.indirect.hamiltonian import hamiltonian_system
from mobisense.ocp.indirect.solver import follow_schedule, kalman_guess, make_bvp_solver, solve_indirect
from mobisense.ocp.model import Structure
from mobisense.ocp.problem import Problem, load_problem

PROBLEMS = Path(__file__).resolve().parents[2] / "problems"

pytestmark = pytest.mark.slow  # direct and indirect solves of seconds each

#: bvp4c's defaults (the paper gives no tolerance): RelTol = 1e-3, NMax = floor(10000 / n) with n = 10 ODEs
PAPER_BVP = {"solver": "scipy", "scipy_tolerance": 1e-3, "max_nodes": 1000}


@pytest.fixture(scope="module")
def direct():
    # the paper's continuation itself: strategy homotopy without an iteration budget (docs/theory/direct.md §5.6)
    solution = solve_direct(Problem.from_dict(hussein2008(strategy="homotopy", homotopy={"budget": None})))
    assert solution.success
    return solution


def test_eps_one_covariance_is_the_lowest_at_every_time(direct):
    # The paper (§V): "the final solution is not necessarily the one with minimum covariance value at each
    # point in time". On its own example it is: Σ_ε(t) decreases with ε at every node, up to the solver
    # tolerance (largest violation 1.8e-9 relative, at the first collocation node; Ipopt tol 1e-9).
    S = direct.path_Sigma[:, :, 0, 0]  # (ε step, time)
    assert direct.path_eps[0] == 0.05 and direct.path_eps[-1] == 1.0
    assert np.all(S[-1] <= S.min(axis=0) * (1 + 1e-8))
    assert np.all(np.diff(S, axis=0) <= 1e-8 * S[1:])
    assert (S[0] / S[-1]).max() > 1.3  # the curves do differ: ε = 0.05 is 31 % above ε = 1 near t = 6


def test_cost_structure_orders_terminal_covariance_and_energy(direct):
    # J_ε = Φ + E/ε: for minimisers at ε1 < ε2, optimality at each ε gives E(ε1) ≤ E(ε2) and Φ(ε1) ≥ Φ(ε2).
    # ε = 1 spends the most control energy and reaches the lowest Σ(tf) — the opposite of the paper's
    # "compromise signal quality at the cost of improved control energy efficiency".
    steps = [h for h in direct.homotopy if h.success]
    eps = np.array([h.eps for h in steps])
    phi = 20.0 * direct.path_Sigma[:, -1, 0, 0]  # Φ = M Σ(tf), M = 20
    energy = eps * (np.array([h.cost for h in steps]) - phi)
    assert np.all(np.diff(phi) < 0) and np.all(np.diff(energy) > 0)


def test_paper_continuation_fails_at_its_first_step():
    # solve_bvp from the Kalman filter and its adjoint costates at ε = δ = 0.05: past the fold of the Kalman
    # branch (ε ≈ 0.0059) only the far branch exists; Newton stays near coasting (Σ(tf) ≈ 1.004) and the mesh
    # outgrows the node limit (also measured with 5000 and 20000 nodes, tol 1e-6 and 1e-8: indirect.md §3.4)
    problem = load_problem(PROBLEMS / "hussein2008_paper.yaml")  # the shipped file: δ = 0.05 and PAPER_BVP
    assert problem.solver.homotopy.step == 0.05
    assert problem.solver.bvp.model_dump(include=set(PAPER_BVP)) == PAPER_BVP
    solution = solve_indirect(problem)
    assert solution.status == "failed" and solution.eps == 0.0
    assert [h.eps for h in solution.homotopy] == [0.05]
    assert "maximum number of mesh nodes" in solution.homotopy[0].status


def test_small_fixed_steps_stop_at_the_fold():
    # δ = 0.001: ε = 0.001 … 0.006 converge on the Kalman branch, ε = 0.007 fails (fold at 0.005863 on the
    # K = 100 collocation mesh, ≈ 0.0062 for solve_bvp at tol 1e-3)
    data = hussein2008(method="indirect", bvp=PAPER_BVP, homotopy={"mode": "fixed", "step": 0.001})
    solution = solve_indirect(Problem.from_dict(data))
    assert solution.status == "failed"
    assert solution.eps == pytest.approx(0.006) and solution.homotopy[-1].eps == pytest.approx(0.007)
    assert solution.Sigma[-1, 0, 0] > 1.0  # still the near-coasting branch (the far branch has Σ(tf) < 0.8)


def test_paper_steps_reach_eps_one_from_the_far_branch(direct):
    # The failure is the first step only: from the far-branch solution at ε = 0.05 (reached here by arclength
    # continuation through both folds) the paper's δ = 0.05 steps with solve_bvp (tol 1e-3, 1000 nodes) reach
    # ε = 1 in 19 steps, each within 2e-8 (measured 1.9e-8 at worst, 1.3e-10 at ε = 1) of the direct optimum.
    problem = Problem.from_dict(hussein2008(method="indirect", bvp=PAPER_BVP))
    system = hamiltonian_system(Structure.of(problem))
    guess_at, _ = kalman_guess(system, problem, system.layout.values(problem))
    collocation = make_bvp_solver(problem, "collocation", guess_at(1.0))
    far = collocation.follow(collocation.solve(0.0, guess_at(0.0)), 0.05)
    assert far.success and len(far.report["folds"]) == 2
    scipy = make_bvp_solver(problem, "scipy", guess_at(1.0))
    first = scipy.solve(0.05, far)
    steps = [first, *follow_schedule(scipy, first, fixed_schedule(0.05))]
    direct_cost = {round(h.eps, 12): h.cost for h in direct.homotopy}
    assert [s.eps for s in steps] == fixed_schedule(0.05)
    for step in steps:
        assert step.success, (step.eps, step.message)
        # relative 1e-7: solve_bvp's tol 1e-3 is on the residual; the costs agree to 1.9e-8 at worst
        assert step.cost_eps == pytest.approx(direct_cost[round(step.eps, 12)], rel=1e-7)
    assert steps[-1].y[0, -1] < 0.8  # the far branch (Σ(tf) 0.79), not the near-coasting one (> 1)
