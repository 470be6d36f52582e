"""The plan check: a direct solution's controls re-integrated independently of the collocation, J compared.

The reference is scipy's DOP853 (``mobisense.ocp.simulate.integrate``, rtol 1e-12) driven by the Lagrange
polynomials of the controls evaluated here from ``Solution.u`` and CasADi's collocation points — neither the
explicit RK4 steps nor CVODES of :func:`mobisense.ocp.simulate.resimulate_plan`.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from reference_problems import hussein2008

import mobisense as ms
from mobisense.ocp.direct.transcription import transcription_for
from mobisense.ocp.simulate import integrate
from mobisense.ocp.solution_warnings import plan_warning


def _dop853_cost(solution: ms.Solution) -> float:
    """J of the solution's control polynomials integrated by DOP853 (right-continuous at interval boundaries)."""
    problem = solution.problem
    scheme, d, K = solution.collocation
    nodes = np.asarray(ca.collocation_points(d, scheme))
    t0, tf = problem.horizon.t0, problem.horizon.tf
    h = (tf - t0) / K
    U = solution.u.reshape(K, d, -1)

    def control(t: float) -> np.ndarray:
        k = min(int((t - t0) / h), K - 1)
        tau = (t - t0) / h - k
        basis = [np.prod([(tau - nodes[r]) / (nodes[j] - nodes[r]) for r in range(d) if r != j]) for j in range(d)]
        return np.einsum("j,jc->c", basis, U[k])

    tr = transcription_for(problem)
    P = tr.layout.pack(tr.layout.values(problem))
    # the interval boundaries as output times: DOP853 restarts its step at each (the control jumps there)
    return integrate(tr.model, P, t0 + h * np.arange(K + 1), control, rtol=1e-12).cost


def test_a_resolved_plan_is_confirmed_to_its_discretisation_error():
    solution = ms.solve(ms.Problem.from_dict(hussein2008(collocation={"intervals": 40})))
    check = solution.stats["plan_check"]
    reference = _dop853_cost(solution)
    # the check's own integration: RK4 at 4 and 8 steps per interval extrapolated, ≈ 1e-13 here; DOP853 at
    # rtol 1e-12 over a control that jumps at every boundary agrees to ≈ 1e-10
    assert check["cost"] == pytest.approx(reference, rel=1e-9)
    # Radau-3 at K = 40: J's error is O(h⁵) ≈ 1e-9 relative (docs/theory/direct.md); far below the tolerance
    assert abs(check["relative_difference"]) < 1e-7
    assert plan_warning(solution) is None and "warning" not in solution.summary()


def test_an_unresolved_plan_is_reported_with_the_cost_of_what_it_flies():
    # the sensor rests on the process: Σ falls from 200 on a time scale r/Σ0 ≈ 0.015 s, 1/27 of an interval at
    # K = 25, which the collocation cannot follow: its J is several per cent off the plan's true cost
    data = hussein2008(collocation={"intervals": 25})
    data["sensors"][0].update(p0=[1.0, 2.0], v0=[0.0, 0.0])
    data["process"]["locations"] = [[1.0, 2.0]]
    data["cost"]["K"] = [[1.0]]
    del data["solver"]["homotopy"]  # the default strategy
    solution = ms.solve(ms.Problem.from_dict(data))
    assert solution.success, solution.message
    check = solution.stats["plan_check"]
    reference = _dop853_cost(solution)
    assert check["cost"] == pytest.approx(reference, rel=1e-7)  # the check integrates the plan correctly …
    assert abs(check["relative_difference"]) > 1e-3  # … and it is not the optimiser's J
    warning = solution.summary()["warning"]
    assert "the grid does not resolve this plan" in warning and "more than K = 25 intervals" in warning
    # the collocation's Σ even dips below zero on this grid (−2e-6 measured), which is said too
    assert solution.min_sigma_eigenvalue < 0 and "Σ(t) is not positive definite" in warning


def test_a_stiff_plan_is_reintegrated_with_its_quadrature_under_error_control():
    # Σ0 = 1e6 falling on a time scale of ~1e-10 s with the sensor on the process and K = 10: the explicit steps
    # disagree and CVODES integrates the plan; without error control on the quadratures its control energy was
    # 18584 against 17899 exactly (Gauss quadrature of the polynomials), and J 18613 against 17927.87
    data = hussein2008(collocation={"intervals": 10})
    data["process"].update(Sigma0=[[1.0e6]], locations=[[0.0, 0.0]])
    data["sensors"][0].update(p0=[0.0, 0.0], v0=[0.0, 0.0], noise={"model": "quadratic_range", "beta": 5.0,
                                                                   "gamma": 1.0e-4})  # fmt: skip
    data["cost"]["K"] = [[1.0]]
    del data["solver"]["homotopy"]
    solution = ms.solve(ms.Problem.from_dict(data))
    check = solution.stats["plan_check"]
    assert check["integrator"] == "CVODES"
    assert check["cost"] == pytest.approx(_dop853_cost(solution), rel=1e-6)
