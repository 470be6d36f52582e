"""Memory and time estimates of the closed-loop simulations, from a validated scenario's sizes alone.

For the pre-flight budget (:func:`mobisense.core.budget.check_budget`) of ``mobisense replay`` and
``mobisense simulate``: what each simulation keeps per output step (the dataset's variables, times the copies
made while assembling it) and a low estimate of its time per step. Per-step sizes were measured on the shipped
scenarios (``problems/*.yaml``: 100–400 bytes per agent-step in the datasets, ×4 for the copies), times divided
by four from those measured on a loaded core (leader–follower 2.7–3.5 ms per run-step, distributed filter
≈ 1 ms per cell-step, field replay 20–25 ms per step, Monte Carlo ≈ 3 µs per run-step), so only work that
certainly exceeds the limits is refused.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from ..core.budget import Estimate

__all__ = ["scenario_estimates"]

#: copies of the per-step data made while a result is assembled (lists → arrays → dataset → file)
_COPIES = 4


def _steps(duration: float, step: float) -> int:
    return int(math.ceil(duration / step)) + 1


def _fastest_rate(config: Any) -> float:
    """The fastest rate (1/s) of a leader–follower loop: turning, the gain, speeds over the formation distance.

    The integrator needs ≈ 17 evaluations per unit of rate × time (measured on the shipped scenarios).
    """
    leader = config.leader
    distances = []
    for _, _, reference, _ in config.resolved_runs():
        for name in ("distance", "max_distance"):
            value = getattr(reference, name, None)
            if isinstance(value, float) and value > 0:
                distances.append(value)
    period = 2 * math.pi / leader.turn_rate_period if leader.turn_rate_amplitude else 0.0
    nearest = min(distances, default=1.0)
    speed = abs(leader.speed) / nearest
    poses = [leader.pose] + [f.pose for f in config.followers]
    gaps = [math.hypot(a[0] - b[0], a[1] - b[1]) for a, b in zip(poses, poses[1:], strict=False)]
    approach = config.gain * max(gaps, default=0.0) / nearest  # a follower's start speed ~ k × its gap, over d0
    return max(1.0, abs(leader.turn_rate) + leader.turn_rate_amplitude, period, config.gain, speed, approach)


def _leader_follower(config: Any) -> list[Estimate]:
    steps, agents, runs = _steps(config.duration, config.step), len(config.followers) + 1, len(config.runs)
    pairs = max((len(s.pairs) for _, _, _, s in config.resolved_runs() if hasattr(s, "pairs")), default=0)
    floats = runs * steps * (40 * agents + 4 * pairs + 20)
    what = f"{runs} run(s) of {steps:.3g} steps of {agents} agents (duration / step)"
    per_step = 0.3e-3 + 0.2e-3 * (agents - 1) + (0.5e-3 if pairs else 0.0)
    parts = [Estimate(what, _COPIES * 8.0 * floats, "use a larger step or a shorter duration", runs * steps * per_step)]
    rate = _fastest_rate(config)
    evaluations = 10 * rate * config.duration * runs  # a low estimate (17 measured)
    what = f"integrating dynamics as fast as {rate:.3g} 1/s (speeds/distance, turn rate, gain) for {config.duration:g}s"
    hint = "use slower speeds, turn rates or gains, or a shorter duration"
    parts.append(Estimate(what, 0.0, hint, evaluations * 50e-6 * agents))
    return parts


def _distributed(config: Any) -> list[Estimate]:
    steps = config.time.n_steps + 1
    cells, sensors = len(config.network.cells), len(config.network.positions)
    floats = steps * (24 * cells + 8 * sensors + 4 * (3 * cells + sensors))
    what = f"{steps:.3g} steps of {cells} cells and {sensors} sensors (time.duration / time.step)"
    seconds = steps * cells * 0.2e-3
    return [Estimate(what, _COPIES * 8.0 * floats, "use a larger time.step or a shorter time.duration", seconds)]


def _reference_problem(
    source: Path, key: str, solution: Path | None, problem: Path | None, task: int | None = None
) -> tuple[Any, list[Estimate]]:
    """The problem of a referenced solution (read from the file, or the problem file it would be solved from).

    ``task`` picks one task of a sweep's ``tasks/part-NNNNNN.nc`` (a plan replay's ``task:``).

    ``ConfigError`` names the scenario file and the key (``motion.solution``) before the referenced file's error.
    """
    from ..core.errors import ConfigError
    from ..ocp.problem import load_problem
    from ..ocp.sizes import problem_estimates
    from ..ocp.solution import Solution
    from .replay.reference import replay_method

    try:
        if solution is not None and solution.exists():
            return Solution.read_problem(solution, task), []
        if problem is not None and problem.exists():
            p = load_problem(problem)
            return p, problem_estimates(p, method=replay_method(p))  # solved as the replay will solve it
    except ConfigError as err:
        which = key if solution is not None and solution.exists() else key.replace("solution", "problem")
        raise ConfigError(f"{source}: {which}: {err}") from None
    return None, []


def _field_replay(config: Any, source: Path) -> list[Estimate]:
    from .replay.plan import resolve

    steps, N = _steps(config.duration, config.time_step), config.platforms.count
    floats = steps * (12 * N + 40)
    what = f"{steps:.3g} steps of {N} platforms (duration / time_step)"
    parts = [Estimate(what, _COPIES * 8.0 * floats, "use a larger time_step or a shorter duration",
                      steps * (3e-3 + 0.5e-3 * N))]  # fmt: skip
    motion = config.motion
    if getattr(motion, "kind", None) == "reference":
        paths = resolve(source, motion.solution), resolve(source, motion.problem)
        _, solve = _reference_problem(source, "motion.solution", *paths)
        parts += solve
    return parts


def _plan_replay(config: Any, source: Path) -> list[Estimate]:
    from .replay.plan import resolve

    paths = resolve(source, config.solution), resolve(source, config.problem)
    problem, parts = _reference_problem(source, "solution", *paths, config.task)
    if problem is None:
        return parts  # the run reports the missing file (exit 2) before computing anything
    mc = config.monte_carlo
    steps = _steps(problem.horizon.tf - problem.horizon.t0, mc.time_step)
    n, N = problem.n, problem.N
    # + Σ(t) re-integrated on the plan's nodes when the file keeps diag Σ only (at most as many as steps)
    floats = 3 * mc.runs * steps * n + 7 * steps * n * n + 8 * steps * N
    what = f"the Monte Carlo validation: {mc.runs} runs × {steps:.3g} steps of {n} states"
    hint = "use fewer monte_carlo.runs or a larger monte_carlo.time_step"
    return parts + [Estimate(what, 8.0 * floats, hint, mc.runs * steps * n * 0.5e-6)]


def _replan(config: Any, source: Path) -> list[Estimate]:
    """Flights, plans kept and re-solves: :func:`mobisense.ocp.replan_inputs.replan_estimates`, the API's budget."""
    from ..ocp.replan import PLAN_SAMPLES
    from ..ocp.replan_inputs import replan_estimates
    from .replay.replan import check_against_problem

    problem = check_against_problem(config, source)
    mc = config.monte_carlo
    hint = "use fewer monte_carlo.runs, a larger monte_carlo.time_step or a larger replan.every"
    return replan_estimates(problem, mc.runs, config.replan.every, mc.time_step, PLAN_SAMPLES, hint,
                            config.replan.length, config.replan.warm_start)  # fmt: skip


def scenario_estimates(kind: str, config: Any, source: Path) -> list[Estimate]:
    """Memory and time of simulating a validated scenario of ``kind`` (see ``formation.scenarios.SCENARIO_KINDS``).

    Raises
    ------
    ConfigError
        A file the scenario references cannot be read (the same error the run would raise).
    """
    if kind == "leader_follower":
        return _leader_follower(config)
    if kind == "distributed":
        return _distributed(config)
    if kind == "field_replay":
        return _field_replay(config, source)
    if kind == "plan_replay":
        return _plan_replay(config, source)
    if kind == "replan":
        return _replan(config, source)
    return []
