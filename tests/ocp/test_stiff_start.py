"""A failed solve on a grid too coarse for the covariance's decay says so, and how many intervals would do."""

from __future__ import annotations

import re

import numpy as np
import pytest
from reference_problems import hussein2008

import mobisense as ms
from mobisense.ocp.direct.guesses import coasting_baseline, state_grid
from mobisense.ocp.direct.stiff_start import riccati_rates
from mobisense.ocp.direct.transcription import transcription_for


def _constant_noise(intervals: int) -> ms.Problem:
    """The default problem with a position-independent noise r = 3: the optimum is u ≡ 0 (the coasting plan)."""
    data = hussein2008(collocation={"intervals": intervals})
    data["sensors"][0]["noise"] = {"model": "constant", "variance_value": 3.0}
    return ms.Problem.from_dict(data)


def test_the_decay_rate_at_t0_is_twice_sigma0_over_r() -> None:
    problem = _constant_noise(30)
    tr = transcription_for(problem)
    t, _ = state_grid(tr, 0.0, 10.0)
    coasting = coasting_baseline(problem, t, tr)
    rates = riccati_rates(tr, coasting, tr.layout.pack(tr.layout.values(problem)))
    assert rates[0] == pytest.approx(2 * 200.0 / 3.0, rel=1e-12)  # λ = 2 Σ0 / r, Σ0 = 200 (exact data)
    assert rates[-1] < 2.0  # Σ settles near its steady state 0.79: 2 Σ∞ / r ≈ 0.53


def test_a_grid_too_coarse_for_the_decay_is_named_in_the_failure() -> None:
    failed = ms.solve(_constant_noise(30))  # h λ0 = 44: the Radau stage equations have no real solution
    assert not failed.success
    hint = re.search(r"h × rate = ([\d.]+).*more intervals \(K ≥ (\d+)\)", failed.message)
    assert hint is not None, failed.message
    needed = int(hint.group(2))
    assert float(hint.group(1)) == pytest.approx(10 / 30 * 400 / 3, rel=1e-2) and needed == 84
    solved = ms.solve(_constant_noise(needed))
    # u ≡ 0 is optimal when the noise does not depend on position: J is the coasting cost, up to the
    # discretisation of the collocation (5e-8 relative at K = 84)
    assert solved.success and "intervals" not in solved.message
    assert solved.cost == pytest.approx(solved.baseline["cost"], rel=1e-6)
    assert np.max(np.abs(solved.sample(np.linspace(0, 10, 21)).u)) < 1e-3


def test_a_plan_forced_away_by_a_coarse_grid_is_blamed_on_the_grid() -> None:
    """r = 0.015 |p − s|² + 3: near the process the decay is too fast for K = 30 (h λ0 = 22), so the NLP's
    feasible plans keep away from it: its optimum, flown (the plan check agrees), costs 6.4 x the coasting plan.
    The warning names the grid and K, not a local optimum; at that K the optimum is the converged one."""
    from mobisense.ocp.solution_warnings import solution_warnings

    data = hussein2008(collocation={"intervals": 30})
    data["sensors"][0]["noise"] = {"model": "quadratic_range", "beta": 0.015, "gamma": 3.0}
    coarse = ms.solve(ms.Problem.from_dict(data))
    assert coarse.success and coarse.worse_than_baseline
    (warning,) = [w for w in solution_warnings(coarse, 1.0) if "costs more than not moving" in w]
    needed = int(re.search(r"more intervals \(K ≥ (\d+)\)", warning).group(1))
    assert needed == 42  # ⌈T λ0 / 16⌉, λ0 = 2 · 200 / (0.015 · 200 + 3)
    data["solver"]["collocation"]["intervals"] = needed
    resolved = ms.solve(ms.Problem.from_dict(data))
    # J at K = 400 is 15.8308747987 (plan check 4e-13); K = 42 is 2.7e-7 below it (discretisation)
    assert resolved.cost == pytest.approx(15.8308747987, rel=1e-6) and not resolved.worse_than_baseline
