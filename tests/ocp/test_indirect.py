"""The indirect method (PMP boundary-value problem, ε-continuation) against closed forms, independent
integrations and the direct method (docs/theory/indirect.md §1–§2)."""

from __future__ import annotations

import numpy as np
import pytest
from reference_problems import coupled_two_sensor, hussein2008, two_scalar_processes
from scipy.integrate import solve_ivp

from mobisense.core.config import ConfigError
from mobisense.ocp.compare import agreement
from mobisense.ocp.direct.solver import solve_direct
from mobisense.ocp.indirect.hamiltonian import hamiltonian_system
from mobisense.ocp.indirect.solver import indirect_continuation, make_bvp_solver, refine_from_direct, solve_indirect
from mobisense.ocp.model import Structure
from mobisense.ocp.problem import Problem
from mobisense.ocp.simulate import integrate

#: K-converged optimum of the default problem (direct Radau d = 3, K → ∞), from the issue tracker
DEFAULT_OPTIMUM = 15.8477720354
#: optimum of coupled_two_sensor() (direct Radau d = 3, K = 400, Ipopt tol 1e-12; K = 200 gives 51.7194934952)
COUPLED_OPTIMUM = 51.7194935074
#: the paper's example (docs/theory/ocp.md §4)
a, Q, M, beta, gamma, alpha = -0.5, 1.0, 20.0, 5.0, 3.0, 0.004


@pytest.fixture(scope="module")
def default_problem():
    return Problem.from_dict(hussein2008(tolerance=1e-12))


@pytest.fixture(scope="module")
def default_direct(default_problem):
    solution = solve_direct(default_problem)
    assert solution.success, solution.message
    return solution


@pytest.fixture(scope="module")
def default_indirect(default_problem):
    """The continuation's own collocation solution (Radau d = 3, K = 100), without the solve_bvp polish."""
    solution, bvp = indirect_continuation(default_problem.with_solver(bvp={"polish": False}))
    assert solution.success, solution.message
    return solution, bvp


@pytest.fixture(scope="module")
def default_seeded(default_direct):
    bvp = refine_from_direct(default_direct)  # scipy solve_bvp, tol 1e-8, adaptive mesh
    assert bvp.success, bvp.message
    return bvp


# ---------------------------------------------------------------------- the Hamiltonian system
def _decoupled_every_sensor_sees_every_state() -> Problem:
    """docs/theory/ocp.md §3.1 (eq. ocp.13): diagonal A, B = I, Q diagonal, two sensors each measuring both states."""
    data, _, _ = two_scalar_processes()
    for sensor in data["sensors"]:
        sensor.pop("measures")
    return Problem.from_dict(data)


def test_ad_costate_equations_equal_the_papers_closed_forms():
    # docs/theory/indirect.md §1.3, decoupled case: Λ_j' = −2Λ_j(a_j − Σ_j Σ_i 1/r_j^i) − K_j,
    # λ_p' = −Σ_j Λ_j Σ_j² ∂r/∂p / r², λ_v' = −λ_p, and Σ_j' = 2a_jΣ_j − Σ_j² Σ_i 1/r_j^i + Q_j (docs/theory/ocp.md,
    # eq. ocp.13), with diagonal Σ and Λ staying diagonal. Same arithmetic, different order: equal to rounding
    # (1e-12 relative).
    problem = _decoupled_every_sensor_sees_every_state()
    system = hamiltonian_system(Structure.of(problem))
    rng = np.random.default_rng(3)
    A = np.diag(problem.process.A)
    Qd = np.diag(problem.process.Q)
    Kd = np.diag(problem.cost.K)
    s = np.asarray(problem.process.locations)
    theta = np.array([sensor.noise.parameters() for sensor in problem.sensors])  # (N, 2): β, γ
    for _ in range(5):
        eps = rng.uniform(0.05, 1.0)
        P = system.layout.pack({**system.layout.values(problem), "eps": eps})
        Sigma, Lam = rng.uniform(0.5, 50.0, 2), rng.uniform(0.1, 20.0, 2)
        p, v, lam_p, lam_v = (rng.normal(size=(2, 2)) * scale for scale in (5.0, 1.0, 0.3, 0.1))
        x = np.concatenate([[Sigma[0], 0.0, Sigma[1]], p.ravel(), v.ravel()])
        lam = np.concatenate([[Lam[0], 0.0, Lam[1]], lam_p.ravel(), lam_v.ravel()])
        y = np.concatenate([x, eps * lam])  # unknowns of the BVP: [x, μ = ε λ]
        ydot = np.asarray(system.functions.rhs(y, P, np.ones(y.size))).ravel()
        x_dot, lam_dot = ydot[:11], ydot[11:] / eps

        r = theta[:, None, 0] * ((p[:, None, :] - s[None, :, :]) ** 2).sum(-1) + theta[:, None, 1]  # r[i, j]
        info = (1.0 / r).sum(axis=0)  # Σ_i 1/r_j^i
        dr_dp = 2.0 * theta[:, None, 0, None] * (p[:, None, :] - s[None, :, :])  # (i, j, xy)
        Sigma_dot = 2 * A * Sigma - Sigma**2 * info + Qd
        Lam_dot = -2 * Lam * (A - Sigma * info) - Kd
        lam_p_dot = -np.einsum("j,ij,ijk->ik", Lam * Sigma**2, 1.0 / r**2, dr_dp)
        expected_x = np.concatenate(
            [[Sigma_dot[0], 0.0, Sigma_dot[1]], v.ravel(), -eps * lam_v.ravel() / problem.cost.alpha]
        )
        expected_lam = np.concatenate([[Lam_dot[0], 0.0, Lam_dot[1]], lam_p_dot.ravel(), -lam_p.ravel()])
        np.testing.assert_allclose(x_dot, expected_x, rtol=1e-12, atol=1e-12 * np.abs(expected_x).max())
        np.testing.assert_allclose(lam_dot, expected_lam, rtol=1e-12, atol=1e-12 * np.abs(expected_lam).max())


def test_ad_costate_equations_equal_the_matrix_form_in_the_coupled_case():
    # The paper's eq. 16 (our signs): Λ' = −(A − ΣS)'Λ − Λ(A − ΣS) − K with S = Σ_i C_i' R_i(p_i)^-1 C_i,
    # so the AD costate of the upper triangle σ, converted with μ_σij = 2ε Λ_ij, must be this symmetric
    # matrix; λ_p' = −∂H/∂p from central differences of H in p (step 1e-5: error O(1e-10) relative).
    problem = Problem.from_dict(coupled_two_sensor())
    system = hamiltonian_system(Structure.of(problem))
    mats = problem.matrices()
    A, K = mats["A"], mats["K"]
    rng = np.random.default_rng(7)
    eps = 0.6
    P = system.layout.pack({**system.layout.values(problem), "eps": eps})

    def information(p: np.ndarray) -> np.ndarray:
        S = np.zeros((2, 2))
        for i, sensor in enumerate(problem.sensors):
            beta_i, gamma_i = sensor.noise.parameters()
            for c, loc in zip(problem.measurement_rows(i), problem.row_locations(i), strict=True):
                S += np.outer(c, c) / (beta_i * np.sum((p[i] - loc) ** 2) + gamma_i)
        return S

    G = rng.normal(size=(2, 2))
    Sigma = G @ G.T + np.eye(2)
    Lam = rng.normal(size=(2, 2))
    Lam = Lam + Lam.T
    p = rng.normal(size=(2, 2)) * 4.0
    lam_sigma = np.array([Lam[0, 0], 2 * Lam[0, 1], Lam[1, 1]])
    x = np.concatenate([[Sigma[0, 0], Sigma[0, 1], Sigma[1, 1]], p.ravel(), rng.normal(size=4)])
    lam = np.concatenate([lam_sigma, rng.normal(size=8) * 0.1])
    y = np.concatenate([x, eps * lam])
    lam_dot = np.asarray(system.functions.rhs(y, P, np.ones(y.size))).ravel()[11:] / eps

    F = A - Sigma @ information(p)
    expected = -F.T @ Lam - Lam @ F - K
    Lam_dot, _, _ = system.structure.state.split_costate(lam_dot)
    np.testing.assert_allclose(Lam_dot, expected, rtol=1e-12, atol=1e-12)

    def hamiltonian_part(p_flat: np.ndarray) -> float:  # Tr[Λ Σ'] terms that depend on p: −Tr[Λ Σ S(p) Σ]
        return -np.trace(Lam @ Sigma @ information(p_flat.reshape(2, 2)) @ Sigma)

    step = 1e-5
    grad = np.array(
        [
            (hamiltonian_part(p.ravel() + step * e) - hamiltonian_part(p.ravel() - step * e)) / (2 * step)
            for e in np.eye(4)
        ]
    )
    np.testing.assert_allclose(lam_dot[3:7], -grad, rtol=1e-8, atol=1e-9 * np.abs(grad).max())
    np.testing.assert_allclose(lam_dot[7:], -lam[3:7], rtol=1e-14)  # λ_v' = −λ_p


def test_control_bounds_are_rejected_at_validation():
    data = hussein2008(method="indirect")
    data["sensors"][0]["u_max"] = 1.0
    with pytest.raises(ConfigError, match=r"sensors\[0\]\.u_max"):
        Problem.from_dict(data)


# ---------------------------------------------------------------------- the BVP solutions
@pytest.mark.slow
def test_continuation_reaches_eps_one_and_the_direct_optimum(default_indirect, default_direct):
    solution, _ = default_indirect
    # both discretisations (Radau d = 3, K = 100) carry ≈ 5e-11 relative error (cost order 2d − 1 = 5)
    assert solution.cost == pytest.approx(DEFAULT_OPTIMUM, rel=1e-9)
    assert solution.cost == pytest.approx(default_direct.cost, rel=1e-9)
    assert solution.eps == 1.0 and solution.homotopy[-1].eps == 1.0
    indirect = solution.stats["indirect"]
    # The branch from the Kalman solution folds, turns back, folds again and reaches the direct optimum.
    # Independent bounds on the first fold: natural-parameter Newton on the same discrete BVP, started at ε = 0
    # and stepped in ε, still converges at ε = 0.00586 (so the branch reaches it); the direct method with
    # δ = 0.0005 jumps from the coasting branch (J_ε = 20.11) to the other (16.57) below ε = 0.0065.
    assert len(indirect["folds"]) == 2
    assert 0.00586 <= indirect["folds"][0] < 0.0065
    assert indirect["folds"][1] < indirect["folds"][0]


def test_scipy_refinement_from_the_direct_solution_agrees(default_seeded, default_direct):
    # solve_bvp with residual tolerance 1e-8 on an adaptive mesh: cost agrees to that tolerance
    assert default_seeded.terminal_cost + default_seeded.running_cost == pytest.approx(default_direct.cost, rel=1e-8)
    report = agreement(default_direct, default_seeded)
    assert report["cost_rel_diff"] < 1e-8
    assert report["max_state_diff"] < 1e-5  # direct states at Ipopt tol 1e-12; collocation error O(h^4)


def _check_boundary_conditions(bvp, tolerance: float) -> None:
    """x(t0) = x0 and transversality Λ(tf) = M, λ(tf) = 0 (eq. indirect.6), relative to each unknown's size."""
    x, mu = bvp.y[:5], bvp.y[5:]
    x0 = np.array([200.0, 10.0, 10.0, 0.0, -2.0])
    assert (np.abs(x[:, 0] - x0) / np.abs(x).max(axis=1)).max() < tolerance
    assert mu[0, -1] == pytest.approx(M, rel=tolerance)
    assert (np.abs(mu[1:, -1]) / np.abs(mu[1:]).max(axis=1)).max() < tolerance


@pytest.mark.slow
@pytest.mark.parametrize("which", ["continuation (collocation)", "direct-seeded (scipy)"])
def test_bvp_solution_satisfies_the_odes(which, default_indirect, default_seeded, default_problem):
    # Independent of the solvers: (1) re-simulate the Riccati + sensor ODE with solve_ivp (rtol 1e-12) under the BVP's
    # control u(t) = −λ_v(t)/α; (2) integrate the paper's closed-form adjoint (docs/theory/indirect.md §1.3, n = N = 1,
    # no CasADi) backwards from Λ(tf) = M, λ(tf) = 0 along the BVP's states. Expected size of the differences: scipy —
    # its residual tolerance 1e-8 (measured 2e-11 states, 4e-9 costates); collocation — its stage error O(h^4) between
    # nodes, h = 0.1 (measured 6e-7 states, 5e-6 costates, relative). Boundary conditions hold to the solver tolerance:
    # Newton 1e-10 (scaled) / solve_bvp bc_tol = tol = 1e-8.
    collocation = which.startswith("continuation")
    bvp = default_indirect[1] if collocation else default_seeded
    state_tol, costate_tol, bc_tol = (2e-6, 2e-5, 1e-10) if collocation else (1e-8, 1e-8, 1e-8)
    _check_boundary_conditions(bvp, bc_tol)
    system = hamiltonian_system(Structure.of(default_problem))
    P = system.layout.pack(system.layout.values(default_problem))
    sim = integrate(system.model, P, bvp.t, control=lambda t: -bvp.evaluate(np.array([t]))[8:10, 0] / alpha, rtol=1e-12)
    x = bvp.y[:5].T
    assert (np.abs(sim.x - x).max(axis=0) / np.abs(x).max(axis=0)).max() < state_tol
    assert sim.cost == pytest.approx(bvp.terminal_cost + bvp.running_cost, rel=state_tol)

    def adjoint(t: float, lam: np.ndarray) -> np.ndarray:
        y = bvp.evaluate(np.array([t]))[:, 0]
        Sigma, p = y[0], y[1:3]
        r = beta * p @ p + gamma
        return np.concatenate([[-2 * lam[0] * (a - Sigma / r)], -lam[0] * Sigma**2 / r**2 * 2 * beta * p, -lam[1:3]])

    ivp = solve_ivp(adjoint, (10.0, 0.0), [M, 0, 0, 0, 0], t_eval=bvp.t[::-1], rtol=1e-12, atol=1e-15, method="DOP853")
    lam = ivp.y[:, ::-1].T
    lam_bvp = bvp.y[5:].T  # ε = 1: μ = λ
    assert (np.abs(lam - lam_bvp).max(axis=0) / np.abs(lam_bvp).max(axis=0)).max() < costate_tol


def test_collocation_converges_from_a_perturbed_solution(default_indirect, default_problem):
    # OptimalControl.jl's check: Newton on the collocation BVP recovers the solution from a 5 % perturbation
    # of every state and costate trajectory (smooth, random, seeded); same mesh, so the same discrete solution.
    _, exact = default_indirect
    rng = np.random.default_rng(11)
    amplitude, phase = rng.uniform(-0.05, 0.05, (10, 1)), rng.uniform(0, 2 * np.pi, (10, 1))

    def perturbed(t: np.ndarray) -> np.ndarray:
        return exact.evaluate(t) * (1.0 + amplitude * np.sin(0.7 * t[None, :] + phase))

    solver = make_bvp_solver(default_problem, "collocation", exact.evaluate)
    result = solver.solve(1.0, perturbed)
    assert result.success, result.message
    assert result.terminal_cost + result.running_cost == pytest.approx(
        exact.terminal_cost + exact.running_cost, rel=1e-12
    )


@pytest.mark.parametrize("scheme,degree", [("radau", 2), ("legendre", 2)])
def test_collocation_bvp_converges_at_the_scheme_order(default_indirect, default_problem, scheme, degree):
    # Cost error of the collocation BVP at ε = 1 against the K-converged optimum (known to ±5e-11, far below
    # the errors measured here) for K = 25, 50: order 2d − 1 (Radau) or 2d (Legendre) at the mesh points.
    _, exact = default_indirect
    errors = []
    for K in (25, 50):
        problem = default_problem.with_solver(collocation={"scheme": scheme, "degree": degree}, bvp={"intervals": K})
        result = make_bvp_solver(problem, "collocation", exact.evaluate).solve(1.0, exact)
        assert result.success, result.message
        errors.append(abs(result.terminal_cost + result.running_cost - DEFAULT_OPTIMUM))
    expected = 2 * degree - 1 if scheme == "radau" else 2 * degree
    assert np.log2(errors[0] / errors[1]) > expected - 0.5, errors


@pytest.mark.slow
def test_direct_multiplier_costates_converge_to_the_pmp_costates(default_direct, default_seeded):
    # The direct method's costates (collocation multipliers / quadrature weights) are O(h^d) = O(h^3)
    # approximations of the PMP costates; the scipy BVP (tol 1e-8) is the reference. Measured: 1.6e-3
    # (K = 50) and 2.1e-4 (K = 100), relative to each costate's peak: require < 5e-4 and order > 2.5.
    fine = agreement(default_direct, default_seeded)["max_costate_diff"]
    coarse_direct = solve_direct(Problem.from_dict(hussein2008(tolerance=1e-12, collocation={"intervals": 50})))
    coarse = agreement(coarse_direct, refine_from_direct(coarse_direct))["max_costate_diff"]
    assert fine < 5e-4
    assert np.log2(coarse / fine) > 2.5


@pytest.mark.slow
def test_two_sensors_with_a_fixed_terminal_velocity():
    # Coupled, correlated n = 2 process, two sensors, sensor s1 must stop at tf (λ_v(tf) free for s1 only).
    problem = Problem.from_dict(coupled_two_sensor(terminal_velocity=True))
    direct = solve_direct(problem)
    indirect = solve_indirect(problem)
    assert direct.success and indirect.success, indirect.message
    # (1) the continuation's collocation solution and the direct one share scheme and mesh (Radau d = 3,
    # K = 50): their costs differ by the two discretisations' errors, measured 4e-10 relative
    polish = indirect.stats["indirect"]["polish"]
    assert polish["collocation_cost"] == pytest.approx(direct.cost, rel=1e-8)
    # (2) the polished solution (solve_bvp, tol 1e-8, adaptive mesh) is mesh-converged: it matches the direct
    # method at K = 400 (51.7194935074, measured) to 1e-9, and the direct K = 50 cost to its own
    # discretisation error (2.2e-7) — within the 1e-6
    assert indirect.cost == pytest.approx(COUPLED_OPTIMUM, rel=1e-9)
    assert indirect.cost == pytest.approx(direct.cost, rel=1e-6)
    # boundary conditions to solve_bvp's bc_tol = 1e-8 (relative to each unknown's scale)
    np.testing.assert_allclose(indirect.v[-1, 0], [0.0, 0.0], atol=1e-8 * np.abs(indirect.v).max())
    np.testing.assert_allclose(indirect.Lam[-1], problem.matrices()["M"], rtol=1e-8)  # Λ(tf) = M, incl. Λ_01
    assert np.abs(indirect.lam_p[-1]).max() < 1e-8 * np.abs(indirect.lam_p).max()
    assert np.abs(indirect.lam_v[-1, 1]).max() < 1e-8 * np.abs(indirect.lam_v).max()
    assert np.abs(indirect.lam_v[-1, 0]).max() > 1e-3 * np.abs(indirect.lam_v).max()  # the multiplier of v(tf) = 0


@pytest.mark.slow
def test_scipy_continuation_where_the_path_has_no_fold():
    # With α = 1 the solution curve is a graph over ε: natural-parameter steps of solve_bvp reach ε = 1 and
    # agree with the collocation solver within solve_bvp's tolerance 1e-8.
    data = hussein2008(homotopy={"mode": "fixed", "step": 0.25})
    data["cost"]["alpha"] = 1.0
    scipy = solve_indirect(Problem.from_dict({**data, "solver": {**data["solver"], "bvp": {"solver": "scipy"}}}))
    collocation = solve_indirect(Problem.from_dict(data))
    assert scipy.success and collocation.success
    assert scipy.cost == pytest.approx(collocation.cost, rel=1e-8)
    assert collocation.stats["indirect"]["folds"] == []


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["adaptive", "none"])
def test_homotopy_modes_reach_the_same_optimum(default_indirect, mode):
    solution = solve_indirect(
        Problem.from_dict(hussein2008(tolerance=1e-12, homotopy={"mode": mode}, bvp={"polish": False}))
    )
    assert solution.success, solution.message
    assert solution.cost == pytest.approx(default_indirect[0].cost, rel=1e-11)  # same discrete BVP
