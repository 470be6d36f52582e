"""Invalid arguments of the formation-control classes are refused at construction, naming the argument.

Each refusal is a ``ValueError`` with a one-line message (argument, what was expected, what was given); the
companion tests keep the legitimate edge cases: an infinite limit (no limit), a negative or time-varying angular
speed, numpy integers for a platform count, the largest Jacobi transform allowed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mobisense.formation.jacobi import MAX_PLATFORMS, JacobiTransform, default_tree, jacobi_matrix
from mobisense.formation.platforms import PlatformLimits
from mobisense.formation.shape_control import FixedShapeController, RotatingShapeController


# ------------------------------------------------------------------------------------- 6. PlatformLimits
@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(max_force=-1.0), "max_force: expected a number > 0, got -1.0"),
        (dict(max_force=0.0), "max_force: expected a number > 0, got 0.0"),
        (dict(max_speed=math.nan), "max_speed: expected a number > 0, got nan"),
        (dict(max_speed=-math.inf), "max_speed: expected a number > 0, got -inf"),
    ],
)
def test_platform_limits_refuse_limits_that_flip_or_vanish(kwargs, match):
    with pytest.raises(ValueError, match=match):
        PlatformLimits(**kwargs)


def test_platform_limits_take_infinity_as_no_limit():
    forces, velocities = np.array([[3.0, 4.0], [0.0, 1.0]]), np.array([[1.0, 0.0], [0.0, 100.0]])
    limits = PlatformLimits(max_force=math.inf, max_speed=math.inf)
    np.testing.assert_array_equal(limits.apply(forces, velocities), forces)
    np.testing.assert_allclose(PlatformLimits(max_force=1.0).apply(forces, velocities)[0], [0.6, 0.8])


# ------------------------------------------------------------------------------------ 7. shape controllers
@pytest.mark.parametrize(
    "args,match",
    [
        ((np.zeros((1, 2)), 1.0, math.nan, math.nan, math.nan), "shape_stiffness: expected a finite .*, got nan"),
        ((np.zeros((1, 2)), 1.0, 1.0, math.inf, 1.0), "shape_damping: expected a finite number > 0, got inf"),
        ((np.zeros((1, 2)), 1.0, 1.0, 1.0, 0.0), "angular_gain: expected a finite number > 0, got 0.0"),
        ((np.zeros((1, 2)), math.nan, 1.0, 1.0, 1.0), "angular_speed: expected a finite number, got nan"),
        ((np.zeros((1, 2)), "fast", 1.0, 1.0, 1.0), "angular_speed: expected a finite number, got 'fast'"),
        ((np.zeros((3, 5)), 1.0, 1.0, 1.0, 1.0), r"p_desired: expected .*\(N−1, 2\) with N >= 2, got shape \(3, 5\)"),
        ((np.zeros((0, 2)), 1.0, 1.0, 1.0, 1.0), r"p_desired: expected .*got shape \(0, 2\)"),
        ((np.full((1, 2), np.inf), 1.0, 1.0, 1.0, 1.0), "p_desired: expected finite numbers"),
    ],
)  # fmt: skip
def test_rotating_controller_refuses_bad_gains_speeds_and_shapes(args, match):
    with pytest.raises(ValueError, match=match):
        RotatingShapeController(*args)


def test_rotating_controller_accepts_any_finite_or_time_varying_speed():
    for speed in (-1.2, 0, np.float32(0.5), lambda t: (0.1 * t, 0.1)):
        control = RotatingShapeController([[1.0, 0.0]], speed, 5.0, 2.0, 1.5)
        u, dpsi, _ = control(1.0, np.array([[1.0, 0.0]]), np.zeros((1, 2)), 0.0, 0.0)
        assert u.shape == (1, 2) and np.all(np.isfinite(u)) and dpsi == 0.0


@pytest.mark.parametrize(
    "args,match",
    [
        ((math.inf, math.inf), "stiffness: expected a finite number > 0, got inf"),
        ((1.0, math.nan), "damping: expected a finite number > 0, got nan"),
        ((1.0, -1.0), "damping: expected a finite number > 0, got -1.0"),
    ],
)
def test_fixed_controller_refuses_bad_gains(args, match):
    with pytest.raises(ValueError, match=match):
        FixedShapeController(*args)


# ------------------------------------------------------------------------------------ 8. JacobiTransform
@pytest.mark.parametrize(
    "n,match",
    [
        (10**6, f"n_platforms: expected 2 … {MAX_PLATFORMS} platforms .*got 1000000"),
        (MAX_PLATFORMS + 1, f"n_platforms: expected 2 … {MAX_PLATFORMS} platforms"),
        (1, "a formation needs at least 2"),
        (4.0, "n_platforms: expected an integer, got 4.0"),
        (True, "n_platforms: expected an integer, got True"),
    ],
)
def test_jacobi_transform_bounds_its_size_before_allocating(n, match):
    for build in (JacobiTransform, jacobi_matrix, default_tree):
        with pytest.raises(ValueError, match=match):
            build(n)


def test_jacobi_transform_accepts_numpy_integers_and_the_largest_count():
    jt = JacobiTransform(np.int64(4))
    assert jt.matrix.shape == (4, 4)
    tree = default_tree(MAX_PLATFORMS)  # the bound itself is allowed (its Ψ is 134 MB, not built here)
    assert isinstance(tree, tuple)
