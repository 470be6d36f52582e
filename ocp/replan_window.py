"""One re-plan: the window's problem, its terminal weight, its grid and its warm start (path_constraints.md §5).

At a re-plan instant ``t`` the problem is re-posed on the window ``[t, t_e]`` — ``t_e = t_f`` (shrinking
horizon) or ``min(t + L, t_f)`` (receding, length ``L``) — from the measured sensor states and the
filter's Σ, on ``max(1, round(K (t_e − t)/(t_f − t_0)))`` intervals (the problem's grid spacing). When
``t_e < t_f`` the terminal weight is the cost-to-go of Σ without further measurements (eq. path.7) and
fixed terminal sensor states are dropped (they belong to ``t_f``). :class:`Replanner` keeps one
transcription per interval count and starts each re-solve as ``warm_start`` says:

``shifted`` (default)
    the previous plan's primal–dual point moved onto the new grid (:mod:`mobisense.ocp.direct.warm_shift`);
``reused``
    the previous point index by index on a grid of the plan's interval count (the window's spacing then
    shrinks with it): the point is where the previous solution was in *its* time grid;
``cold``
    the coasting guess, no multipliers.

A measured state may violate a path constraint that the plan kept (a current pushed a sensor into a zone,
Euler's step overshot the speed limit by 1e-3): it is not bad input but the state to re-plan from. The window
then relaxes each violated constraint just enough to hold it (:func:`relax_constraints`) and reports by how
much; the next re-plan relaxes again from its own measured state, or not at all once the sensors are clear.

A field's window that stops at Ipopt's iteration or time limit (L-BFGS can stall beside an active constraint:
on the island re-plan, J was within 1e-5 of its end after 75 iterations and the solve ran on to its 500) is
still flown when its plan is feasible — every scaled row within Ipopt's ``constr_viol_tol`` — and no worse than
its start, the previous plan flown from the measured state: what the flight would fly otherwise
(:func:`unconverged_plan_flyable`, suboptimal MPC). The record says so (``ReplanRecord.flown_unconverged``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from .discretisation import discretise_process
from .problem import Problem
from .solve_outcome import StartKind

__all__ = [
    "WARM_STARTS",
    "RELAXATION",
    "cost_to_go_weight",
    "relax_constraints",
    "window_problem",
    "Replanner",
    "ReplanRecord",
    "FEASIBLE_ROW_VIOLATION",
    "unconverged_plan_flyable",
]

WarmStart = Literal["shifted", "reused", "cold"]
#: how a re-solve starts (see module docstring)
WARM_STARTS: tuple[str, ...] = ("shifted", "reused", "cold")


def cost_to_go_weight(A: np.ndarray, M: np.ndarray, K: np.ndarray, remaining: float) -> np.ndarray:
    """Λ(t_e) of eq. path.7: ``e^{Aᵀτ} M e^{Aτ} + ∫₀^τ e^{Aᵀs} K e^{As} ds`` with ``τ = remaining`` (T), (n, n).

    The integral is Van Loan's (:func:`~mobisense.ocp.discretisation.discretise_process` for ``Aᵀ`` and ``K``).
    """
    F, integral = discretise_process(np.asarray(A, float).T, np.asarray(K, float), remaining)  # F = e^{Aᵀτ}
    out = F @ M @ F.T + integral
    return 0.5 * (out + out.T)


#: a relaxed constraint clears the measured state by this fraction of its own size (radius, d_min, v_max, extent)
RELAXATION = 1e-3

#: the largest violation of a scaled row (O(1) by construction) of a plan still feasible: Ipopt's default
#: ``constr_viol_tol``, what it asks of a solution it calls optimal
FEASIBLE_ROW_VIOLATION = 1e-4
#: the Ipopt statuses of a solve that stopped on a budget, not on a failure of its own
BUDGET_STATUSES = ("Maximum_Iterations_Exceeded", "Maximum_WallTime_Exceeded", "Maximum_CpuTime_Exceeded")


def unconverged_plan_flyable(solution: Any) -> bool:
    """Whether a failed window solve's plan is fit to fly: it stopped on a budget, is feasible and improved its start.

    ``solution.stats["unconverged"]`` (a field's shooting solve, :func:`mobisense.ocp.field_solve.solve_shooting`)
    holds its Ipopt status and the J and largest scaled row violation of its start and end. Its start is the
    previous plan flown from the measured state; when that start broke a row by more than
    :data:`FEASIBLE_ROW_VIOLATION`, any feasible end is better than it.
    """
    record = solution.stats.get("unconverged") if not solution.success else None
    if not record or record["status"] not in BUDGET_STATUSES or not np.isfinite(record["cost"]):
        return False
    if solution.stats.get("start") != StartKind.WARM.value:  # a cold window started from its own homotopy: its
        return False  # start is not the plan the flight would fly instead, so "better than its start" says nothing
    if record["violation"] > FEASIBLE_ROW_VIOLATION:
        return False
    return record["start_violation"] > FEASIBLE_ROW_VIOLATION or record["cost"] <= record["start_cost"]


def relax_constraints(constraints: dict[str, Any], p: np.ndarray, v: np.ndarray) -> dict[str, float]:
    """Loosen the violated constraints, in place, just enough to hold the state; their violations (physical units).

    ``constraints`` is a normalised ``constraints`` dict, ``p`` and ``v`` the positions and velocities (N, 2).

    A disc's radius shrinks to the nearest sensor's distance, a polygon shrinks about its vertices' mean
    until every sensor is outside, ``min_separation`` drops to the closest pair's distance, ``max_speed``
    rises to the fastest sensor's speed and the workspace grows to hold every sensor, each with a clearance
    of :data:`RELAXATION` of its size. A zone shrunk below :data:`RELAXATION` of its size (a sensor on or next to
    its centre) is dropped from the window.
    """
    from .path_constraints import KeepOutPolygon, PathConstraints, margins, polygon_scale_outside

    violated = {
        k: float(x[0]) for k, x in margins(PathConstraints(**constraints), p[None], v[None]).items() if x[0] > 0
    }
    zones = constraints.get("keep_out") or []
    keep = [True] * len(zones)
    for k, zone in enumerate(zones):
        if f"keep_out[{k}]" not in violated:
            continue
        if "radius" in zone:
            nearest = float(np.min(np.linalg.norm(p - np.asarray(zone["center"], float), axis=1)))
            scale = nearest * (1 - RELAXATION) / zone["radius"]
            zone["radius"] *= scale
        else:
            V = np.asarray(zone["polygon"], float)
            scale = polygon_scale_outside(KeepOutPolygon(polygon=zone["polygon"]), p) * (1 - RELAXATION)
            zone["polygon"] = (V.mean(axis=0) + scale * (V - V.mean(axis=0))).tolist()
        keep[k] = scale > RELAXATION  # shrunk to nothing (a sensor on its centre): dropped
    if zones:
        constraints["keep_out"] = [zone for zone, kept in zip(zones, keep, strict=True) if kept]
    if "min_separation" in violated:
        i, j = np.triu_indices(len(p), 1)
        closest = float(np.min(np.linalg.norm(p[i] - p[j], axis=1)))
        relaxed = closest * (1 - RELAXATION)
        constraints["min_separation"] = relaxed if relaxed > RELAXATION * constraints["min_separation"] else None
    if "max_speed" in violated:
        constraints["max_speed"] = float(np.max(np.linalg.norm(v, axis=1))) * (1 + RELAXATION)
    if "workspace" in violated:
        w = constraints["workspace"]
        for axis, name in enumerate(("x", "y")):
            lo, hi = w[name]
            clear = RELAXATION * (hi - lo)
            w[name] = [min(lo, float(p[:, axis].min()) - clear), max(hi, float(p[:, axis].max()) + clear)]
    return violated


def window_problem(
    problem: Problem,
    t: float,
    t_end: float,
    p: np.ndarray,
    v: np.ndarray,
    Sigma: np.ndarray,
    intervals: int,
    strategy: str | None = "cold",
    relaxed: dict[str, float] | None = None,
) -> Problem:
    """``problem`` on ``[t, t_end]`` from positions ``p``, velocities ``v`` (N, 2), Σ (n, n), on ``intervals``.

    ``strategy``: the solve strategy if the warm start fails (None: the problem's). Constraints that the
    measured state violates are relaxed (:func:`relax_constraints`); ``relaxed`` receives their violations.
    """
    data = problem.normalised()
    data["horizon"]["t0"], data["horizon"]["tf"] = float(t), float(t_end)
    data["process"]["Sigma0"] = (0.5 * (Sigma + Sigma.T)).tolist()
    tf = problem.horizon.tf
    for i, sensor in enumerate(data["sensors"]):
        sensor["p0"], sensor["v0"] = p[i].tolist(), v[i].tolist()
        if t_end < tf:
            sensor["terminal"] = None
    if data.get("constraints"):
        violated = relax_constraints(data["constraints"], np.asarray(p, float), np.asarray(v, float))
        if relaxed is not None:
            relaxed.update(violated)
    if t_end < tf:
        m = problem.matrices()
        data["cost"]["M"] = cost_to_go_weight(m["A"], m["M"], m["K"], tf - t_end).tolist()
    if problem.solver.method == "shooting":  # a field: its own grid, the coarse one scaled alike (≥ 2 intervals)
        shooting = data["solver"]["shooting"]
        scale = intervals / shooting["intervals"]
        shooting["intervals"] = int(intervals)
        shooting["coarse_intervals"] = max(2, int(round(shooting["coarse_intervals"] * scale)))
        return Problem.from_dict(data, source="<re-plan>")
    if strategy is not None:
        data["solver"]["strategy"] = strategy
    data["solver"]["collocation"]["intervals"] = int(intervals)
    return Problem.from_dict(data, source="<re-plan>")


@dataclass
class ReplanRecord:
    """What one re-solve cost: instant (T), window end (T), intervals, Ipopt iterations, wall time (s), success.

    ``relaxed``: the constraints relaxed for it, group -> the measured state's violation (physical units).
    ``flown_unconverged``: it failed on a budget but its plan was flown (:func:`unconverged_plan_flyable`).
    """

    t: float
    t_end: float
    intervals: int
    iterations: int
    time_s: float
    success: bool
    relaxed: dict[str, float] = field(default_factory=dict)
    flown_unconverged: bool = False

    @property
    def flown(self) -> bool:
        """Whether the re-solve's plan replaced the previous one."""
        return self.success or self.flown_unconverged


@dataclass
class Replanner:
    """Re-solves ``problem`` on windows (see module docstring); one transcription per interval count.

    Parameters
    ----------
    problem : Problem
    length : float or None
        Receding-horizon length L (T); None: shrinking horizon.
    warm_start : {"shifted", "reused", "cold"}
    """

    problem: Problem
    length: float | None = None
    warm_start: WarmStart = "shifted"
    records: list[ReplanRecord] = field(default_factory=list)
    _transcriptions: dict[Any, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.warm_start not in WARM_STARTS:
            raise ValueError(f"warm_start: expected one of {WARM_STARTS}, got {self.warm_start!r}")

    @property
    def shooting(self) -> bool:
        """Whether the windows are solved by a field's shooting method (else by direct collocation)."""
        return self.problem.solver.method == "shooting"

    def window(self, t: float) -> tuple[float, int]:
        """Window end t_e (T) and interval count at re-plan instant ``t``."""
        h, solver = self.problem.horizon, self.problem.solver
        t_end = h.tf if self.length is None else min(t + self.length, h.tf)
        K = solver.shooting.intervals if self.shooting else solver.collocation.intervals
        if self.warm_start == "reused":
            return t_end, K
        fewest = 2 if self.shooting else 1
        return t_end, max(fewest, int(round(K * (t_end - t) / (h.tf - h.t0))))

    def transcription(self, sub: Problem) -> Any:
        """The (kept) transcription of a window problem."""
        from .direct.transcription import transcription_for
        from .model import Structure

        key = (Structure.of(sub), sub.solver.collocation.intervals)
        if key not in self._transcriptions:
            self._transcriptions[key] = transcription_for(sub)
        return self._transcriptions[key]

    def prepare(self, instants: np.ndarray) -> float:
        """Build the transcriptions of the windows at re-plan ``instants`` (T) before flying; wall time (s)."""
        start = time.perf_counter()
        if self.shooting:  # a shooting graph holds its window's Σ0: each re-solve builds its own (timed with it)
            return 0.0
        p, v, Sigma0 = self._initial_state()
        for t in instants:
            t_end, K = self.window(float(t))
            self.transcription(window_problem(self.problem, float(t), t_end, p, v, Sigma0, K))
        return time.perf_counter() - start

    def _initial_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The problem's own start: positions (N, 2), velocities (N, 2) and Σ0 (n, n)."""
        sensors = self.problem.sensors
        p, v = (np.array([getattr(s, key) for s in sensors], float) for key in ("p0", "v0"))
        return p, v, self.problem.matrices()["Sigma0"]

    def solved(self, sub: Problem, init: Any = None, transcription: Any = None) -> Any:
        """``sub`` solved by the problem's method: a field by shooting, else directly on its kept transcription."""
        if self.shooting:
            from .field_solve import solve_shooting

            return solve_shooting(sub, init=init)
        from .direct.solver import solve_direct

        return solve_direct(sub, transcription=transcription or self.transcription(sub), init=init)

    def first_plan(self) -> Any:
        """The plan over the first window (the problem's solve strategy)."""
        t0 = self.problem.horizon.t0
        t_end, K = self.window(t0)
        return self.solved(window_problem(self.problem, t0, t_end, *self._initial_state(), K, strategy=None))

    def solve(self, previous: Any, t: float, p: np.ndarray, v: np.ndarray, Sigma: np.ndarray) -> Any:
        """The plan re-solved at ``t`` from ``p``, ``v``, Σ, started from ``previous`` (None: cold)."""
        t_end, K = self.window(t)
        relaxed: dict[str, float] = {}
        sub = window_problem(self.problem, t, t_end, p, v, Sigma, K, relaxed=relaxed)
        # built before the flight by prepare(), not part of the re-solve time; a shooting graph holds its window's
        # Σ0 as a constant: built with each re-solve, and timed with it
        tr = None if self.shooting else self.transcription(sub)
        start = time.perf_counter()
        init = self._shooting_start(previous, t, t_end) if tr is None else self._direct_start(previous, sub, tr, t,
                                                                                                t_end)  # fmt: skip
        new = self.solved(sub, init, tr)
        elapsed = time.perf_counter() - start
        iterations = sum(step.iterations for step in new.homotopy)
        self.records.append(ReplanRecord(t, t_end, K, iterations, elapsed, new.success, relaxed,
                                         unconverged_plan_flyable(new)))  # fmt: skip
        return new

    def _direct_start(self, previous: Any, sub: Problem, tr: Any, t: float, t_end: float) -> Any:
        """The ``init`` of a direct window (:mod:`mobisense.ocp.direct.warm_shift` for ``shifted``)."""
        from .direct.warm_shift import shifted_point
        from .model import Structure

        if previous is None or self.warm_start == "cold" or Structure.of(previous.problem) != Structure.of(sub):
            return None  # a relaxation dropped a zone: the previous point has other rows (cold start)
        if self.warm_start == "reused":
            return previous
        P_new = tr.layout.pack(tr.layout.values(sub))  # cost_scale 1: solve_direct re-scales the point
        return shifted_point(previous, self.transcription(previous.problem), tr, P_new, (t, t_end))

    def _shooting_start(self, previous: Any, t: float, t_end: float) -> Any:
        """The ``init`` of a field's window (docs/theory/path_constraints.md §5.3).

        ``shifted`` starts the ε = 1 solve from the previous plan's controls at the same times (held at its last
        node past its end), ``reused`` from them node by node, ``cold`` runs the coarse ε-homotopy.
        """
        from dataclasses import replace

        if previous is None or self.warm_start == "cold":
            return None
        if self.warm_start == "reused":  # its k-th node's control at the window's k-th node
            return replace(previous, t_u=np.linspace(t, t_end, len(previous.t_u)))
        return previous
