"""The matrix checks of the configuration (core/config.py) and the copy behind a sweep's tasks (core/keypath.py)."""

from __future__ import annotations

import copy
import warnings

import numpy as np
import pytest

from mobisense.core.config import check_psd
from mobisense.core.keypath import set_path, with_values


def _allclose_symmetric(a: np.ndarray) -> bool:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # np.allclose warns for an infinite atol
        return bool(np.allclose(a, a.T, rtol=1e-12, atol=1e-12 * max(1.0, float(np.abs(a).max()))))


def _passes_symmetry(a: np.ndarray) -> bool:
    try:
        check_psd("M", a)
    except ValueError as exc:
        return "symmetric matrix, got" not in str(exc)  # failed later, on the eigenvalues: symmetric
    return True


def test_symmetry_check_is_np_allclose_spelt_out():
    # the independent reference is np.allclose with the same tolerances, on matrices symmetric, off by
    # 1e-13 … 1e-9 relative (either side of rtol = 1e-12), scaled over 10 decades, and with infinities and NaN
    rng = np.random.default_rng(7)
    cases = [
        np.array([[np.inf, 1.0], [1.0, np.inf]]),
        np.array([[np.nan, 1.0], [1.0, 1.0]]),
        np.array([[1.0, np.inf], [1.0, 1.0]]),
        np.array([[1.0, -np.inf], [np.inf, 1.0]]),
        np.array([[1.0, 1e308], [1e308 * (1 + 1e-13), 1.0]]),
    ]
    for _ in range(500):
        a = rng.normal(size=(3, 3)) * 10.0 ** rng.integers(-5, 6)
        a = a + a.T
        a[0, 1] *= 1 + rng.choice([0.0, 1e-13, 1e-11, 1e-9])
        cases.append(a)
    verdicts = [(_allclose_symmetric(a), _passes_symmetry(a)) for a in cases]
    assert all(ref == ours for ref, ours in verdicts)
    assert {ref for ref, _ in verdicts} == {True, False}  # both outcomes occur
    # the same verdicts again, now from the cache of spectrum facts (keyed by the matrix's bytes)
    assert [(_allclose_symmetric(a), _passes_symmetry(a)) for a in cases] == verdicts


def test_a_matrix_changed_after_its_check_is_checked_again():
    m = np.array([[2.0, 1.0], [1.0, 2.0]])
    check_psd("M", m)  # cached: positive definite
    m[1, 1] = -5.0  # the same array object, other entries
    with pytest.raises(ValueError, match="smallest eigenvalue -5.1"):
        check_psd("M", m)
    big = np.eye(70)  # beyond CACHED_MATRIX_ENTRIES: checked directly, the same verdicts
    check_psd("M", big)
    big[0, 0] = -1.0
    with pytest.raises(ValueError, match="smallest eigenvalue -1"):
        check_psd("M", big)


def test_set_path_copies_deeply_and_leaves_the_original():
    data = {"a": {"b": [1, 2, {"c": 3.0}]}, "s": "text", "n": None}
    before = copy.deepcopy(data)
    value = {"list": [1, 2]}
    out = set_path(data, "a.b[2]", value)
    assert data == before and out == {"a": {"b": [1, 2, {"list": [1, 2]}]}, "s": "text", "n": None}
    out["a"]["b"][0] = 99
    out["a"]["b"][2]["list"].append(3)
    assert data == before and value == {"list": [1, 2]}  # nothing shared with the input or the value
    with pytest.raises(KeyError):
        set_path(data, "a.x", 1)


def test_with_values_replaces_like_set_path_and_copies_only_the_way_there():
    data = {"cost": {"alpha": 1.0, "M": [[1.0]]}, "sensors": [{"p0": [0, 0], "v0": [1, 1]}, {"p0": [5, 5]}],
            "solver": {"tol": 1e-9}, "name": "base"}  # fmt: skip
    before = copy.deepcopy(data)
    changes = {"cost.alpha": 2.0, "sensors[0].p0": [3, 4], "sensors[0].v0": [0, 0], "name": "x"}
    out = with_values(data, changes)
    expected = copy.deepcopy(data)
    for path, value in changes.items():
        expected = set_path(expected, path, value)
    assert out == expected and data == before  # the values of set_path, the original untouched
    # containers on a replaced path are new (sensors[0] once for both of its paths), the rest is shared
    assert out["sensors"] is not data["sensors"] and out["sensors"][0] is not data["sensors"][0]
    assert out["sensors"][1] is data["sensors"][1] and out["solver"] is data["solver"]
    assert out["cost"]["M"] is data["cost"]["M"]
    with pytest.raises(KeyError, match="did you mean 'alpha'"):
        with_values(data, {"cost.alpah": 1.0})
    with pytest.raises(KeyError):
        with_values(data, {"sensors[5].p0": 1.0})
