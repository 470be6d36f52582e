"""Multi-start: perturbed initial guesses for the direct method, and counting distinct local optima.

Start 0 is the ordinary ε-continuation from the coasting solution. Start k > 0 solves ε = 1 directly from
a random feasible trajectory: a smooth random control ``u(t) = Σ_m a_m sin(mπ τ + φ_m)`` (τ the normalised
time, amplitudes of the order of the problem's control scale) and the states it produces (integrated with
``solve_ivp``), so the guess satisfies the dynamics and only the optimality differs.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ocp.direct import _initial_guess, _state_grid, transcription_for
from ocp.problem import Problem
from ocp.simulate import integrate
from ocp.solution import Solution

__all__ = ["random_guess", "distinct_optima"]


def random_guess(problem: Problem, seed: int, amplitude: float = 3.0, modes: int = 3) -> np.ndarray:
    """A scaled decision vector of a random smooth control and its trajectory (see module docstring)."""
    tr = transcription_for(problem)
    values = tr.layout.values(problem)
    P = tr.layout.pack(values)
    rng = np.random.default_rng(seed)
    u_scale = float(values["control_scale"])
    nu = tr.structure.nu
    t0, tf = problem.horizon.t0, problem.horizon.tf
    a = amplitude * u_scale * rng.standard_normal((modes, nu))
    phase = rng.uniform(0, 2 * np.pi, (modes, nu))
    m = np.arange(1, modes + 1)[:, None]

    def control(t: float) -> np.ndarray:
        tau = (t - t0) / (tf - t0)
        return (a * np.sin(m * np.pi * tau + phase)).sum(axis=0)

    _, nodes = tr.times(t0, tf)
    t_grid, _ = _state_grid(tr, t0, tf)
    trajectory = integrate(tr.model, P, t_grid, control=control, rtol=1e-8)
    u = np.array([control(t) for t in nodes.ravel()]).reshape(tr.intervals, tr.colloc.degree, nu)
    # the scaling of w does not depend on cost_scale (set inside solve_direct), so this P packs it correctly
    return _initial_guess(tr, trajectory, P, u)


def distinct_optima(solutions: list[Solution], rtol: float = 1e-6) -> list[dict[str, Any]]:
    """Group converged solutions whose costs agree to ``rtol``; return one entry per optimum, best first."""
    groups: list[dict[str, Any]] = []
    for k, s in sorted(enumerate(solutions), key=lambda item: item[1].cost):
        if not s.success:
            continue
        for g in groups:
            if abs(s.cost - g["cost"]) <= rtol * max(abs(g["cost"]), 1e-12):
                g["starts"].append(k)
                break
        else:
            groups.append({"cost": s.cost, "starts": [k], "final_positions": s.p[-1].tolist()})
    return groups


def solve_multistart(
    problem: Problem, starts: int, scheduler: str | None = None, workers: int | None = None
) -> Solution:
    """Solve from ``starts`` initial guesses through the dask engine; return the best, with the optima found.

    The returned solution's ``stats["multistart"]`` holds ``starts``, ``converged`` and ``optima``
    (one entry per distinct local optimum: cost, which starts reached it, final sensor positions).
    """
    from ocp.engine import open_client, run_tasks

    payloads = [{"problem": problem.normalised(), "guess_seed": None if k == 0 else k} for k in range(starts)]
    solutions: list[Solution | None] = [None] * starts
    errors: list[str] = []

    def on_result(i: int, result: dict[str, Any]) -> None:
        if "dataset" in result:
            solutions[i] = Solution.from_dataset(result["dataset"])
        else:
            errors.append(f"start {i}: {result['row'].get('error', '')}")

    with open_client(scheduler, workers) as client:
        run_tasks(client, payloads, on_result, warm_start=False)
    done = [s for s in solutions if s is not None]
    optima = distinct_optima(done)
    converged = [s for s in done if s.success]
    if not done:
        raise RuntimeError("every multi-start task failed: " + "; ".join(errors))
    index = {id(s): k for k, s in enumerate(solutions)}
    for group in optima:
        group["starts"] = sorted(index[id(done[k])] for k in group["starts"])
    # the best optimum, represented by its lowest start (start 0, the homotopy, when it found it)
    best = solutions[optima[0]["starts"][0]] if optima else done[0]
    best.stats["multistart"] = {"starts": starts, "converged": len(converged), "optima": optima, "errors": errors}
    return best
