"""The fast paths of the cooperative filter equal the reference kernels (docs/theory/cooperative.md §2.4).

Reference: :mod:`mobisense.estimation.kalman` on numpy arrays, one run at a time (the step API with
``backend="numpy"``). Compared: component matrices (the same kernels on one array per entry), the
shared-trajectory rollout (eq. cooperative.16), the per-run rollout, and the compiled numba steps (a
second implementation, allowed only because these tests hold it to the reference).

Tolerance: 1e-12 relative to the largest magnitude of each compared quantity. The paths differ only in
the order of floating-point operations (BLAS vs loops, Cholesky vs LU, information vs Joseph form);
each 3 × 3 / N × N operation then differs by a few ulps (≈ 1e-16 × its condition number, ≤ 1e3 here),
and the filter's error dynamics are contractive, so round-off does not grow along a trajectory.
"""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from mobisense.estimation import kalman
from mobisense.estimation.components import ComponentMatrix
from mobisense.estimation.cooperative.filter import CooperativeKalmanFilter, model_sequence, run_cooperative_filter
from mobisense.estimation.cooperative.information_model import cross_formation
from mobisense.estimation.cooperative.noise_config import CooperativeNoise
from mobisense.estimation.cooperative.rollouts import component_model

RTOL = 1e-12
HAVE_NUMBA = importlib.util.find_spec("numba") is not None


def assert_close(actual: np.ndarray, reference: np.ndarray, name: str = "") -> None:
    reference = np.asarray(reference)
    scale = max(float(np.abs(reference).max()), 1e-300)
    np.testing.assert_allclose(actual, reference, rtol=0, atol=RTOL * scale, err_msg=name)


def _spd(rng: np.random.Generator, shape: tuple[int, ...], n: int) -> np.ndarray:
    X = rng.normal(size=shape + (n, n))
    return X @ np.swapaxes(X, -1, -2) + n * np.eye(n)


def _noise(rng: np.random.Generator, N: int) -> CooperativeNoise:
    """Full (non-diagonal) M, U and R: no structural zeros to hide an indexing error."""
    return CooperativeNoise(0.01 * _spd(rng, (), 3), 0.05 * _spd(rng, (), N), 0.02 * _spd(rng, (), 4))


def _trajectory(rng: np.random.Generator, K: int, N: int, runs: tuple[int, ...] = ()) -> np.ndarray:
    s = np.linspace(0.0, 4.0, K)
    angles = 2 * np.pi * np.arange(N) / N + 0.2 * rng.normal(size=N)
    shape = np.stack([1.3 * np.cos(angles), 0.8 * np.sin(angles)], -1)
    centers = np.stack([s, np.sin(s)], -1)
    base = centers[:, None, :] + shape
    return base + 0.05 * rng.normal(size=runs + base.shape)


def _sequential(positions, measurements, noise, x0, P0, H):  # noqa: ANN001, ANN202
    """The step API with the reference kernels, one run: states, covariances, priors, innovations."""
    f = CooperativeKalmanFilter(noise, x0, P0, positions[0], backend="numpy")
    out = {k: [] for k in ("x", "P", "xm", "Pm", "nu", "S")}
    for k in range(len(measurements)):
        xm, Pm = (f.state[:, 0], f.covariance) if k == 0 else f.predict(positions[k])
        x, P = f.update(measurements[k], H[k])
        for name, value in zip(out, (x, P, xm, Pm, f.innovation[:, 0], f.innovation_covariance), strict=True):
            out[name].append(np.array(value))
    return {k: np.stack(v) for k, v in out.items()}


# ------------------------------------------------------------------------------------ component matrices
def test_component_matrix_algebra_equals_numpy() -> None:
    rng = np.random.default_rng(0)
    batch = (7, 5)
    S, A, B = _spd(rng, batch, 4), rng.normal(size=batch + (3, 4)), rng.normal(size=batch + (4, 2))
    cS, cA, cB = (ComponentMatrix.from_array(a) for a in (S, A, B))
    assert_close(kalman.congruence(cA, cS).to_array(), A @ S @ np.swapaxes(A, -1, -2))
    assert_close((cA @ cB).to_array(), A @ B)
    assert_close(kalman.solve(cS, cB).to_array(), np.linalg.solve(S, B))
    assert_close(kalman.inverse(cS).to_array(), np.linalg.inv(S))
    assert_close(kalman.whiten(cS, cB).to_array(), np.linalg.solve(np.linalg.cholesky(S), B))
    assert_close((cA.T @ cA).to_array(), np.swapaxes(A, -1, -2) @ A)
    assert_close(kalman.symmetrize(cA.T @ cA + cS[..., :4] * 0.5).to_array(),
                 kalman.symmetrize(np.swapaxes(A, -1, -2) @ A + 0.5 * S))  # fmt: skip
    assert_close((2.0 - cS + S[0, 0]).to_array(), 2.0 - S + S[0, 0])
    # structural entries: constants stay floats, products with 0 and 1 are skipped, results unchanged
    F = np.broadcast_to(np.array([[1.0, 0.3, -0.2], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]), batch + (3, 3)).copy()
    F[..., 0, 1] = rng.normal(size=batch)
    cF = ComponentMatrix.from_array(F)
    assert [type(e) for e in cF.rows[1]] == [float, float, float] and isinstance(cF.rows[0][1], np.ndarray)
    P = _spd(rng, batch, 3)
    assert_close(kalman.congruence(cF, ComponentMatrix.from_array(P)).to_array(), F @ P @ np.swapaxes(F, -1, -2))


def test_kalman_kernels_on_component_matrices_equal_batched_numpy() -> None:
    rng = np.random.default_rng(1)
    batch, n, m = (40,), 3, 5
    x, y = rng.normal(size=batch + (n, 1)), rng.normal(size=batch + (m, 1))
    P, R, Q = _spd(rng, batch, n), _spd(rng, batch, m), _spd(rng, (), n)
    F, H, u = rng.normal(size=batch + (n, n)), rng.normal(size=batch + (m, n)), rng.normal(size=batch + (n, 1))
    c = {k: ComponentMatrix.from_array(v) for k, v in dict(x=x, y=y, P=P, R=R, F=F, H=H, u=u).items()}
    cQ = ComponentMatrix.from_array(Q, constant=True)
    for got, ref in zip(kalman.predict(c["x"], c["P"], c["F"], cQ, c["u"]), kalman.predict(x, P, F, Q, u), strict=True):
        assert_close(got.to_array(), ref)
    for got, ref in zip(kalman.update(c["x"], c["P"], c["y"], c["H"], c["R"]), kalman.update(x, P, y, H, R),
                        strict=True):  # fmt: skip
        assert_close(got.to_array(), ref)
    J, j = kalman.information_contribution(c["y"], c["H"], c["R"])
    Jn, jn = kalman.information_contribution(y, H, R)
    assert_close(J.to_array(), Jn)
    assert_close(j.to_array(), jn)
    for got, ref in zip(kalman.information_update(c["x"], c["P"], J, j), kalman.information_update(x, P, Jn, jn),
                        strict=True):  # fmt: skip
        assert_close(got.to_array(), ref)


def test_component_model_equals_model_sequence() -> None:
    rng = np.random.default_rng(2)
    K, N, B = 20, 5, 6
    positions = _trajectory(rng, K, N, (B,))
    H = rng.normal(size=(B, K, 2, 2))  # non-symmetric: vec(H) ordering matters
    noise = _noise(rng, N)
    reference = model_sequence(positions, H, noise)
    components = component_model(positions, H, noise)
    for name in ("F", "u", "C", "R"):
        assert_close(np.moveaxis(components[name].to_array((K, B)), 0, 1), reference[name], name)
    assert_close(np.moveaxis(components["DH"].to_array((K, B))[..., 0], 0, 1), reference["DH"], "DH")
    assert_close(components["centers"], reference["centers"], "centers")


# ------------------------------------------------------------------------------------ rollouts
@pytest.mark.parametrize("per_run", [False, True], ids=["shared trajectory", "trajectory per run"])
@pytest.mark.parametrize("outputs", ["all", "posterior"])
def test_batched_rollouts_equal_the_sequential_filter(per_run: bool, outputs: str) -> None:
    rng = np.random.default_rng(3)
    K, N, B = 30, 4, 5
    positions = _trajectory(rng, K, N, (B,) if per_run else ())
    noise = _noise(rng, N)
    H = rng.normal(size=(B, K, 2, 2))  # a Hessian input per run
    meas, x0, P0 = rng.normal(size=(B, K, N)), rng.normal(size=(B, 3)), _spd(rng, (), 3)
    result = run_cooperative_filter(positions, meas, noise, x0, P0, H, engine="numpy", outputs=outputs)
    assert result.meta["rollout"] == ("components" if per_run else "shared")
    fields = {"x": "states", "P": "covariances", "xm": "states_prior", "Pm": "covariances_prior",
              "nu": "innovations", "S": "innovation_covariances"}  # fmt: skip
    for b in range(B):
        ref = _sequential(positions[b] if per_run else positions, meas[b], noise, x0[b], P0, H[b])
        for key, name in fields.items():
            value = getattr(result, name)
            if outputs == "posterior" and key not in ("x", "P"):
                assert value is None
                continue
            per_run_field = per_run or key in ("x", "xm", "nu")  # shared covariances are unbatched
            assert_close(value[b] if per_run_field else value, ref[key], f"{name} run {b}")


def test_rollouts_keep_any_batch_shape_and_per_run_covariances() -> None:
    rng = np.random.default_rng(4)
    K, N = 12, 3
    positions = _trajectory(rng, K, N)
    noise = _noise(rng, N)
    meas, x0 = rng.normal(size=(2, 3, K, N)), rng.normal(size=(3,))
    P0 = _spd(rng, (2, 3), 3)  # one prior covariance per run: the per-run rollout even with shared positions
    result = run_cooperative_filter(positions, meas, noise, x0, P0)
    assert result.meta["rollout"] == "components" and result.states.shape == (2, 3, K, 3)
    assert result.covariances.shape == (2, 3, K, 3, 3) and result.innovations.shape == (2, 3, K, N)
    ref = _sequential(positions, meas[1, 2], noise, x0, P0[1, 2], np.zeros((K, 2, 2)))
    assert_close(result.states[1, 2], ref["x"])
    assert_close(result.covariances[1, 2], ref["P"])
    assert_close(result.innovations[1, 2], ref["nu"])
    shared = run_cooperative_filter(positions, meas, noise, x0, P0[0, 0], engine="numpy")
    assert shared.states.shape == (2, 3, K, 3) and shared.covariances.shape == (K, 3, 3)
    assert_close(shared.states[0, 0], _sequential(positions, meas[0, 0], noise, x0, P0[0, 0], np.zeros((K, 2, 2)))["x"])


def test_posterior_outputs_are_named_when_missing() -> None:
    rng = np.random.default_rng(5)
    positions = _trajectory(rng, 8, 4)
    result = run_cooperative_filter(positions, rng.normal(size=(3, 8, 4)), _noise(rng, 4), np.zeros(3), np.eye(3),
                                    outputs="posterior")  # fmt: skip
    with pytest.raises(ValueError, match="outputs='posterior'"):
        result.nis()
    ds = result.to_dataset()
    assert "estimate" in ds and "innovation" not in ds
    assert result.nees(np.zeros((8, 3))).shape == (3, 8)
    with pytest.raises(ValueError, match="outputs: expected"):
        run_cooperative_filter(positions, np.zeros((8, 4)), _noise(rng, 4), np.zeros(3), np.eye(3), outputs="states")


# ------------------------------------------------------------------------------------ compiled steps
@pytest.mark.skipif(not HAVE_NUMBA, reason="numba not installed (extra mobisense[fast])")
@pytest.mark.parametrize("N", [2, 3, 4, 6])
def test_numba_steps_equal_the_reference_kernels(N: int) -> None:
    rng = np.random.default_rng(10 + N)
    K = 150
    positions = _trajectory(rng, K, N)
    noise = _noise(rng, N)
    H = rng.normal(size=(K, 2, 2))
    meas, x0, P0 = rng.normal(size=(K, N)), rng.normal(size=3), _spd(rng, (), 3)
    fast = CooperativeKalmanFilter(noise, x0, P0, positions[0], backend="numba")
    ref = CooperativeKalmanFilter(noise, x0, P0, positions[0], backend="numpy")
    assert (fast.backend, ref.backend) == ("numba", "numpy")
    for k in range(K):
        if k:
            fp, rp = fast.predict(positions[k]), ref.predict(positions[k])
            for a, b in zip(fp, rp, strict=True):
                assert_close(a, b, f"prior, step {k}")
        prior = fast.covariance
        fu, ru = fast.update(meas[k], H[k]), ref.update(meas[k], H[k])
        for a, b in zip(fu, ru, strict=True):
            assert_close(a, b, f"posterior, step {k}")
        assert_close(fast.innovation, ref.innovation, f"innovation, step {k}")
        assert_close(fast.innovation_covariance, ref.innovation_covariance, f"S, step {k}")
        assert prior is not fast.covariance  # each step makes new arrays: a returned prior stays the prior


@pytest.mark.slow
@pytest.mark.skipif(not HAVE_NUMBA, reason="numba not installed (extra mobisense[fast])")
def test_numba_backend_on_the_benchmark_filter_over_a_long_run() -> None:
    """The filter of benchmarks/bench_filters.py (cross of 4, σ = 0.05, 0.3, 0.2), 3000 steps."""
    rng = np.random.default_rng(20)
    K = 3000
    s = np.linspace(0.0, 0.01 * K, K)
    positions = cross_formation(1.0, 1.4, center=np.stack([s, np.sin(s)], -1), orientation=0.2 * np.sin(s))
    H = np.broadcast_to(np.array([[0.3, 0.1], [0.1, -0.2]]), (K, 2, 2))
    noise = CooperativeNoise.from_sigmas(0.05, 0.3, 0.2)
    meas = rng.normal(size=(K, 4))
    ref = _sequential(positions, meas, noise, np.zeros(3), np.eye(3), H)
    f = CooperativeKalmanFilter(noise, np.zeros(3), np.eye(3), positions[0])  # auto: numba
    assert f.backend == "numba"
    states = []
    for k in range(K):
        if k:
            f.predict(positions[k])
        states.append(f.update(meas[k], H[k])[0].copy())
    assert_close(np.array(states), ref["x"])


def test_backend_choice_and_errors() -> None:
    noise = CooperativeNoise.from_sigmas(0.1, 0.2, 0.1)
    positions = cross_formation(1.0, 1.0)
    batched = CooperativeKalmanFilter(noise, np.zeros((5, 3)), np.eye(3), positions)
    assert batched.backend == "numpy"  # auto: the compiled steps filter a single run
    with pytest.raises(ValueError, match="single run"):
        CooperativeKalmanFilter(noise, np.zeros((5, 3)), np.eye(3), positions, backend="numba")
    with pytest.raises(ValueError, match="backend: expected"):
        CooperativeKalmanFilter(noise, np.zeros(3), np.eye(3), positions, backend="fortran")
    single = CooperativeKalmanFilter(noise, np.zeros(3), np.eye(3), positions)
    assert single.backend == ("numba" if HAVE_NUMBA else "numpy")
    if HAVE_NUMBA:
        with pytest.raises(ValueError, match="single run"):
            single.update(np.zeros(4), np.zeros((3, 2, 2)))


def test_without_numba_auto_falls_back_to_the_reference_kernels(monkeypatch: pytest.MonkeyPatch) -> None:
    """What an install without the extra ``fast`` does: ``auto`` filters with numpy, ``numba`` says what to install."""
    from mobisense.estimation.cooperative import filter as filter_module

    real = importlib.util.find_spec
    monkeypatch.setattr(filter_module.importlib.util, "find_spec",
                        lambda name, *a: None if name == "numba" else real(name, *a))  # fmt: skip
    rng = np.random.default_rng(6)
    K, N = 10, 4
    positions, noise = _trajectory(rng, K, N), _noise(rng, N)
    meas, H = rng.normal(size=(K, N)), rng.normal(size=(K, 2, 2))
    f = CooperativeKalmanFilter(noise, np.zeros(3), np.eye(3), positions[0])
    assert f.backend == "numpy"
    for k in range(K):
        if k:
            f.predict(positions[k])
        f.update(meas[k], H[k])
    ref = _sequential(positions, meas, noise, np.zeros(3), np.eye(3), H)
    assert_close(f.state[:, 0], ref["x"][-1])
    assert_close(f.covariance, ref["P"][-1])
    with pytest.raises(ImportError, match=r"mobisense\[fast\]"):
        CooperativeKalmanFilter(noise, np.zeros(3), np.eye(3), positions[0], backend="numba")
