"""Steady state and formation design (docs/theory/steady_state.md) and the ``mobisense steady-state`` command."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mobisense.cli import main
from mobisense.estimation import kalman
from mobisense.estimation.cooperative.formation_design import adaptive_shape_step, design_cross_formation
from mobisense.estimation.cooperative.information_model import cross_formation, taylor_matrices
from mobisense.estimation.cooperative.noise_config import CooperativeNoise
from mobisense.estimation.cooperative.steady_state import (
    cross_steady_state,
    cross_trace,
    cross_trace_function,
    steady_state,
)

ROOT = Path(__file__).resolve().parents[2]
SIGMAS = [(0.1, 0.5, 1.0), (1.0, 1.0, 1.0), (0.3, 0.2, 0.0), (2.0, 0.05, 3.0)]


def _exact_steady_state(positions: np.ndarray, noise: CooperativeNoise) -> np.ndarray:
    """P∞(+) to 80 digits: J = C'(DUD' + R)⁻¹C and the doubling algorithm (SDA) on the filter DARE, in mpmath."""
    import mpmath as mp

    mp.mp.dps = 80
    centred = [[mp.mpf(float(v)) for v in p] for p in positions - positions.mean(axis=0)]
    C = mp.matrix([[1, x, y] for x, y in centred])
    D = mp.matrix([[x * x / 2, x * y / 2, x * y / 2, y * y / 2] for x, y in centred])
    S = D * mp.matrix(noise.hessian_error.tolist()) * D.T + mp.matrix(noise.measurement_matrix(len(positions)).tolist())
    J = C.T * mp.inverse(S) * C
    A, G, H = mp.eye(3), J.copy(), mp.matrix(noise.process.tolist())  # P⁻ = A P⁻ (I + G P⁻)⁻¹ A' + H
    for _ in range(200):
        W = mp.inverse(mp.eye(3) + G * H)
        A, G, H = A * W * A, G + A * W * G * A.T, H + A.T * H * W * A
        if mp.mnorm(A, 1) < mp.mpf(10) ** -70:
            break
    posterior = mp.inverse(mp.inverse(H) + J)
    return np.array([[float(posterior[i, j]) for j in range(3)] for i in range(3)])


@pytest.mark.parametrize(
    ("positions", "noise", "rtol"),
    [
        # a cross of 1000 L with noise in other units: J spans 1e-5 … 2e10 (was refused as "nearly collinear")
        (cross_formation(1000.0, 1000.0), CooperativeNoise.from_sigmas(10.0, 0.01, 1e-3), 1e-10),
        # one platform 1e4 L from three at unit distance: cond(DUD' + R) ≈ 1e16 (was refused; scipy's DARE on
        # the full S is 20 % off, the exactly rounded J with a double-precision DARE 1e-5)
        (
            np.array([[1e4, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]]),
            CooperativeNoise(0.01 * np.eye(3), 0.1, 0.01 * np.eye(4)),
            1e-7,
        ),
        # a formation 5e-5 as wide as long (the narrowest accepted is MIN_ASPECT = 1e-6: error 2e-8 there)
        (
            np.array([[0.0, 0.0], [1.0, 1e-4], [2.0, 0.0], [3.0, -1e-4]]),
            CooperativeNoise.from_sigmas(0.1, 0.2, 0.3),
            1e-9,
        ),
    ],
    ids=["cross-1000", "far-platform", "thin"],
)
def test_ill_conditioned_steady_states_match_an_80_digit_reference(positions, noise, rtol) -> None:  # noqa: ANN001
    # rtol: about 10x the error measured on each case (1e-11, 7.5e-9, 7e-12), room for another platform's round-off
    exact = _exact_steady_state(positions, noise)
    result = steady_state(positions, noise)
    np.testing.assert_allclose(result.posterior, exact, rtol=0, atol=rtol * np.abs(exact).max())


def test_too_thin_a_formation_is_refused_before_the_riccati_equation() -> None:
    thin = np.array([[0.0, 0.0], [1.0, 1e-7], [2.0, 0.0], [3.0, -1e-7]])  # width 5e-8 of its length
    with pytest.raises(ValueError, match=r"positions: nearly collinear formation \(width 4\.9e-08 of its length"):
        steady_state(thin, CooperativeNoise.from_sigmas(0.1, 0.2, 0.3))
    # without process noise in a direction there is no stabilising solution (its covariance falls like 1/k)
    singular = CooperativeNoise(np.diag([1e-2, 0.0, 0.0]), 0.04, 0.09 * np.eye(4))
    with pytest.raises(ValueError, match="noise.process: expected a positive definite M"):
        steady_state(cross_formation(1.0, 1.0), singular)
    # the same shape in other units is not refused: only the geometry decides
    assert np.isfinite(
        steady_state(1e-3 * cross_formation(1.0, 2.0), CooperativeNoise.from_sigmas(1.0, 1e-3, 1.0)).trace
    )


@pytest.mark.parametrize("sigmas", SIGMAS)
def test_closed_form_equals_dare_and_is_diagonal(sigmas: tuple[float, float, float]) -> None:
    noise = CooperativeNoise.from_sigmas(*sigmas)
    for a, b, theta in [(0.7, 1.3, 0.0), (2.0, 0.4, 0.0), (1.1, 1.1, 0.0)]:
        closed = cross_steady_state(a, b, *sigmas)
        dare = steady_state(cross_formation(a, b, orientation=theta), noise)
        np.testing.assert_allclose(closed.posterior, dare.posterior, rtol=0, atol=1e-10 * dare.trace)
        np.testing.assert_allclose(closed.gain, dare.gain, atol=1e-10)
        assert np.count_nonzero(np.abs(dare.posterior - np.diag(np.diag(dare.posterior))) > 1e-14) == 0
        # the gain two ways: P∞(−) C' S⁻¹ (python-control's prior) = P∞(+) C' (DUD' + R)⁻¹
        C, D = taylor_matrices(dare.positions)
        S = C @ dare.prior @ C.T + noise.total_measurement_covariance(D)
        np.testing.assert_allclose(dare.prior @ C.T @ np.linalg.inv(S), dare.gain, atol=1e-12)
        # a fixed point of one filter step with A = I
        _, P_next = kalman.predict(np.zeros((3, 1)), dare.posterior, np.eye(3), noise.process)
        _, P_next, _, _ = kalman.update(
            np.zeros((3, 1)), P_next, np.zeros((4, 1)), C, noise.total_measurement_covariance(D)
        )
        np.testing.assert_allclose(P_next, dare.posterior, atol=1e-13)
    # a rotated cross has the rotated covariance: trace unchanged
    rotated = steady_state(cross_formation(0.7, 1.3, orientation=0.6), noise)
    assert rotated.trace == pytest.approx(cross_steady_state(0.7, 1.3, *sigmas).trace, rel=1e-12)


def test_casadi_derivatives_match_finite_differences() -> None:
    f = cross_trace_function()
    x, sig = np.array([0.8, 1.7]), [0.1, 0.5, 1.0]
    value, g, H = (np.asarray(v, dtype=float) for v in f(x, sig))
    assert value.item() == pytest.approx(float(cross_trace(0.8, 1.7, *sig)), rel=1e-15)
    h = 1e-5
    for i in range(2):
        e = np.eye(2)[i] * h
        fd_g = (cross_trace(*(x + e), *sig) - cross_trace(*(x - e), *sig)) / (2 * h)
        fd_H = (np.asarray(f(x + e, sig)[1]) - np.asarray(f(x - e, sig)[1])).ravel() / (2 * h)
        assert g.ravel()[i] == pytest.approx(fd_g, abs=1e-9)  # O(h²) truncation ~1e-10
        np.testing.assert_allclose(H[:, i], fd_H, atol=1e-8)


def _brute_force(sigmas, bounds, equal: bool = False) -> np.ndarray:  # noqa: ANN001
    """Independent: fine grid of the closed form, then Nelder–Mead on the clipped objective."""
    from scipy.optimize import minimize

    (a0, a1), (b0, b1) = bounds
    a, b = np.linspace(a0, a1, 401), np.linspace(b0, b1, 401)
    if equal:
        i = np.argmin(cross_trace(a, a, *sigmas))
        start = np.array([a[i]])

        def fun(t: np.ndarray) -> float:
            s = np.clip(t[0], a0, a1)
            return float(cross_trace(s, s, *sigmas))

        t = minimize(fun, start, method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-16}).x[0]
        return np.clip(np.array([t, t]), a0, a1)
    T = cross_trace(a[:, None], b[None, :], *sigmas)
    i, j = np.unravel_index(np.argmin(T), T.shape)
    lo, hi = np.array([a0, b0]), np.array([a1, b1])
    res = minimize(
        lambda x: float(cross_trace(*np.clip(x, lo, hi), *sigmas)),
        [a[i], b[j]],
        method="Nelder-Mead",
        options={"xatol": 1e-10, "fatol": 1e-16},
    )
    return np.clip(res.x, lo, hi)


@pytest.mark.parametrize(
    ("sigmas", "equal", "kind"),
    [
        ((0.1, 0.5, 1.0), False, "boundary"),  # the example: the optimum runs to b = d_max
        ((0.1, 0.5, 1.0), True, "saddle"),  # a = b imposed: its 1-D optimum is a 2-D saddle
        ((1.0, 0.1, 0.1), False, "minimum"),  # interior minimum
        ((1.0, 0.1, 0.1), True, "minimum"),
    ],
)
def test_bounded_optimum_matches_brute_force_and_is_classified(sigmas, equal: bool, kind: str) -> None:  # noqa: ANN001
    bounds = ((0.2, 3.0), (0.2, 3.0))
    design = design_cross_formation(*sigmas, bounds, equal_sides=equal)
    reference = _brute_force(sigmas, bounds, equal)
    # tr P(a, b) is symmetric in (a, b): compare up to the swap
    x = design.x if np.abs(design.x - reference).max() < np.abs(design.x[::-1] - reference).max() else design.x[::-1]
    # Nelder–Mead with xatol 1e-10 on a function whose curvature is ~1e-3: optimum located to ~1e-5
    np.testing.assert_allclose(x, reference, atol=2e-5)
    assert design.fun <= float(cross_trace(*reference, *sigmas)) + 1e-14
    assert design.stationary_point == kind
    if kind == "boundary":
        assert design.on_bound["b"] == "upper" or design.on_bound["a"] == "upper"
        free = 0 if design.on_bound["a"] is None else 1
        assert abs(design.jac[free]) < 1e-12  # stationary along the free direction
    else:
        assert np.abs(design.jac.sum() if equal else design.jac).max() < 1e-12
    eig = design.hess_eigenvalues
    assert (eig.min() < 0) == (kind == "saddle")


@pytest.mark.slow
def test_adaptive_step_minimises_the_filter_covariance() -> None:
    """Step (3A): J_k at the chosen shape is ½ tr P(+) of a filter update, and no grid shape does better."""
    noise = CooperativeNoise.from_sigmas(0.1, 0.5, 1.0)
    prior = np.array([[0.5, 0.05, 0.0], [0.05, 0.2, 0.02], [0.0, 0.02, 0.05]])
    bounds, theta = ((0.2, 3.0), (0.2, 3.0)), 0.3
    design = adaptive_shape_step(prior, noise, bounds, orientation=theta)

    def half_trace_posterior(a: float, b: float) -> float:
        C, D = taylor_matrices(cross_formation(a, b, orientation=theta))
        _, P, _, _ = kalman.update(np.zeros((3, 1)), prior, np.zeros((4, 1)), C, noise.total_measurement_covariance(D))
        return 0.5 * float(np.trace(P))

    assert design.fun == pytest.approx(half_trace_posterior(*design.x), rel=1e-12)
    grid = np.linspace(0.2, 3.0, 57)
    assert design.fun <= min(half_trace_posterior(a, b) for a in grid for b in grid) + 1e-15


# ----------------------------------------------------------------------------------------------- CLI
@pytest.mark.parametrize(
    ("name", "kind"),
    [
        ("formation_cross", "boundary"),
        ("formation_cross_equal_sides", "saddle"),
        ("formation_cross_interior", "minimum"),
    ],
)
@pytest.mark.slow
def test_cli_steady_state(tmp_path: Path, name: str, kind: str) -> None:
    out = tmp_path / name
    assert main(["steady-state", str(ROOT / "problems" / f"{name}.yaml"), "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert {"a", "b", "trace", "P_diag", "gain", "on_bound", "stationary_point"} <= set(summary)
    assert summary["stationary_point"] == kind
    closed = cross_steady_state(summary["a"], summary["b"], *summary["noise"].values())
    assert summary["trace"] == pytest.approx(closed.trace, rel=1e-12)
    np.testing.assert_allclose(summary["P_diag"], np.diag(closed.posterior), rtol=1e-12)
    assert np.asarray(summary["gain"]).shape == (3, 4)
    assert (out / "trace_contour.png").stat().st_size > 10_000 and (out / "trace_grid.nc").exists()


def test_cli_custom_formation_and_invalid_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    custom = tmp_path / "pentagon.yaml"
    angles = 2 * np.pi * np.arange(5) / 5
    pts = np.round(np.stack([np.cos(angles), np.sin(angles)], -1), 6).tolist()
    custom.write_text(
        "formation: custom\nnoise: {sigma_process: 0.1, sigma_measurement: 0.5, sigma_hessian: 1.0}\n"
        f"positions: {pts}\n"
    )
    assert main(["steady-state", str(custom), "--out", str(tmp_path / "c")]) == 0
    summary = json.loads((tmp_path / "c" / "summary.json").read_text())
    expected = steady_state(np.array(pts), CooperativeNoise.from_sigmas(0.1, 0.5, 1.0))
    assert summary["trace"] == pytest.approx(expected.trace, rel=1e-12)
    bad = {
        "typo.yaml": ("formation: cross\nnoise: {sigma_process: 0.1, sigma_measurment: 0.5}\n"
                      "bounds: {a: [0.2, 3.0], b: [0.2, 3.0]}\n",
                      "noise.sigma_measurment: unknown key; did you mean 'sigma_measurement'"),
        "order.yaml": ("formation: cross\nnoise: {sigma_process: 0.1, sigma_measurement: 0.5}\n"
                       "bounds: {a: [3.0, 0.2], b: [0.2, 3.0]}\n", "bounds.a: expected [min, max]"),
        "line.yaml": ("formation: custom\nnoise: {sigma_process: 0.1, sigma_measurement: 0.5}\n"
                      "positions: [[0, 0], [1, 0], [2, 0]]\n", "not all on or near one line"),
        # width 5e-10 of the length: below MIN_ASPECT, where the steady state loses its digits to round-off
        "thin.yaml": ("formation: custom\nnoise: {sigma_process: 0.1, sigma_measurement: 0.5}\n"
                      "positions: [[0, 0], [1, 1.0e-9], [2, 0], [3, -1.0e-9]]\n", "not all on or near one line"),
        "nobounds.yaml": ("noise: {sigma_process: 0.1, sigma_measurement: 0.5}\n", "bounds: required"),
    }  # fmt: skip
    for name, (text, message) in bad.items():
        path = tmp_path / name
        path.write_text(text)
        out = tmp_path / f"out_{name}"
        assert main(["steady-state", str(path), "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1 and "Traceback" not in err
        assert not out.exists()  # nothing written for an invalid file
