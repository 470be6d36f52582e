"""Path geometry of the dynamic formation parameters and the deviation metric.

Theory: docs/theory/leader_follower.md §4.3, §5; source: Karasalo & Hu (2010), §8.3, Fig. 13 and eq. 54.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from mobisense.formation.leader_follower.paths import chord_window, enclosed_areas, path_deviation
from mobisense.formation.leader_follower.references import PathReference


def _arc(radius: float, total_angle: float, n: int) -> np.ndarray:
    """Counter-clockwise arc ending at angle 0, n + 1 samples, oldest first."""
    theta = np.linspace(-total_angle, 0.0, n + 1)
    return radius * np.stack([np.cos(theta), np.sin(theta)], axis=-1)


def test_enclosed_areas_equal_the_inscribed_polygon_area():
    """Vertices on a circle: area(P_j..P_m + chord) = R²/2 (n sin Δθ − sin(n Δθ)) exactly, n = m − j."""
    radius, n = 3.0, 40
    path = _arc(radius, 2.0, n)
    dtheta = 2.0 / n
    segments = n - np.arange(n + 1)
    exact = 0.5 * radius**2 * (segments * math.sin(dtheta) - np.sin(segments * dtheta))
    # shoelace on O(3) coordinates: round-off ~1e-15 per term, 40 terms
    np.testing.assert_allclose(enclosed_areas(path), exact, rtol=0, atol=1e-13)
    # translation invariance (coordinates far from the origin)
    np.testing.assert_allclose(enclosed_areas(path + 1e4), exact, rtol=0, atol=1e-9)


def test_chord_window_hits_the_area_bound_exactly_on_a_curve():
    """On a circle the area constraint binds; interpolation on the crossing segment makes area = A_max."""
    path = _arc(2.0, 3.0, 300)
    point = chord_window(path, max_area=0.05, max_chord=10.0)
    # the area along a segment is linear in the interpolation parameter: exact up to round-off
    assert abs(point.area - 0.05) < 1e-12
    # continuous circle: R²/2 (θ − sin θ) = A gives θ*; sampled at Δθ = 0.01 the chord differs by O(R Δθ²)
    theta = brentq(lambda th: 0.5 * 4.0 * (th - math.sin(th)) - 0.05, 1e-6, 3.0)
    assert abs(point.chord - 2 * 2.0 * math.sin(theta / 2)) < 2e-4  # measured 3e-5
    # tangent–chord angle of a circle is half the subtended angle (β0 > 0: predecessor turns left)
    reference = PathReference(0.05, 10.0, 1.2).at(0.0, path)
    # vertex tangents are exact on a circle, interpolated between them: O(Δθ²) = 1e-4
    assert abs(reference.bearing - theta / 2) < 2e-4  # measured 1e-5
    assert reference.distance == point.chord


def test_chord_window_on_a_straight_path_is_capped_at_max_distance():
    path = np.stack([np.linspace(-5, 0, 51), np.zeros(51)], axis=-1)
    point = chord_window(path, max_area=0.005, max_chord=1.6)
    assert abs(point.chord - 1.6) < 1e-13 and point.area == 0.0
    reference = PathReference(0.005, 1.6, 1.0).at(0.0, path)
    assert reference.bearing == 0.0 and abs(reference.distance - 1.6) < 1e-13
    # initial history: a straight run behind the predecessor gives the same reference at t = 0
    seeded = PathReference(0.005, 1.6, 1.0)
    history = seeded.initial_history(np.array([2.0, 1.0, 0.5]))
    ref0 = seeded.at(0.0, history)
    assert abs(ref0.distance - 1.6) < 1e-12 and abs(ref0.bearing) < 1e-12


def test_path_reference_clips_the_bearing_and_handles_short_paths():
    sharp = _arc(0.2, 3.0, 300)  # tight turn: half-angle would exceed the bound
    ref = PathReference(1.0, 10.0, 0.3).at(0.0, sharp)
    assert ref.bearing == 0.3
    assert PathReference(0.1, 1.0, 1.0).at(0.0, np.zeros((1, 2))) is None


def test_path_deviation_on_parallel_lines_is_the_offset():
    t = np.linspace(0, 10, 101)
    predecessor = np.stack([t, np.zeros_like(t)], axis=-1)
    follower = np.stack([t - 1.0, np.full_like(t, 0.3)], axis=-1)
    dev = path_deviation(predecessor, follower)
    # once the follower is past the predecessor's start (t ≥ 1), the closest path point is straight across
    np.testing.assert_allclose(dev[t >= 1.0], 0.3, rtol=0, atol=1e-14)
    np.testing.assert_allclose(dev[0], math.hypot(1.0, 0.3), rtol=1e-14)


def test_path_deviation_matches_brute_force_on_a_random_path():
    rng = np.random.default_rng(4)
    predecessor = np.cumsum(rng.normal(0, 0.2, (60, 2)), axis=0)
    follower = predecessor + rng.normal(0, 0.3, (60, 2))
    dev = path_deviation(predecessor, follower)
    # independent computation: dense points on the segments (2000 per segment), min over τ ≤ t
    s = np.linspace(0, 1, 2001)[:-1]
    dense = (predecessor[:-1, None, :] + s[None, :, None] * np.diff(predecessor, axis=0)[:, None, :]).reshape(-1, 2)
    dense = np.vstack([dense, predecessor[-1:]])
    half_spacing = 0.5 * np.max(np.hypot(*np.diff(predecessor, axis=0).T)) / 2000
    for k in range(60):
        candidates = dense[: k * 2000 + 1]
        brute = np.min(np.hypot(*(candidates - follower[k]).T))
        # the dense grid over-estimates the true minimum by at most half a spacing
        assert -1e-12 <= brute - dev[k] <= half_spacing
