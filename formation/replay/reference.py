"""Optimised sensor trajectories as references to track (the OCP → control link, docs/theory/replay.md §1.1).

* :func:`load_checked` / :func:`load_or_solve` — a ``solution.nc`` written by ``mobisense solve`` if its
  problem hash matches the problem file's, or else (missing, unreadable, stale) the solution of that
  problem, solved here by :func:`mobisense.ocp.direct.solver.solve_direct` (so shipped scenarios run on a
  fresh clone and never replay a plan of another problem);
* :class:`ReferenceTrajectory` — positions and velocities of the solution as a C¹ cubic Hermite
  spline through its state grid (``p`` with slopes ``v``: exact at every collocation point), and the
  optimiser's own control ``u`` (linear between its collocation nodes) as the feed-forward;
* :class:`TrackingController` — ``f = u_ref + Kp (p_ref − r) + Kd (v_ref − r')``: with ``u_ref = p_ref''``
  the error obeys ``e'' + Kd e' + Kp e = 0``; the residual ``u_ref − p_ref''`` (collocation and
  interpolation error) is what keeps a replay started on the reference off it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..shape_control import FixedShapeController

if TYPE_CHECKING:
    from ...ocp.problem import Problem
    from ...ocp.solution import Solution

__all__ = ["load_checked", "load_or_solve", "reference_status", "replay_method", "ReferenceTrajectory",
           "TrackingController"]  # fmt: skip


def _read_solution(path: Path, task: int | None = None) -> tuple[Solution | None, str]:
    """The solution in ``path`` (None and why if it cannot be used).

    A field solution that keeps diag Σ only is marked (``stats["sigma_reintegrated"]``): :func:`_with_sigma`
    re-integrates its Σ(t) once it is known to be the one replayed.
    """
    from ...core.errors import ConfigError
    from ...ocp.solution import Solution

    try:
        solution = Solution.load(path, task=task)
    except ConfigError as err:  # one line naming the file, the variable and what was expected
        text = str(err)
        text = text[len(f"{path}: ") :] if text.startswith(f"{path}: ") else text
        return None, f"{path} is not a solution file written by mobisense solve ({text})"
    except Exception as err:  # noqa: BLE001  (any failure to read means: not a usable solution file)
        return None, f"{path} is not a solution file written by mobisense solve ({type(err).__name__}: {err})"
    if not solution.success:
        return None, f"{path} holds a failed solve ({solution.message})"
    if solution.Sigma is None and solution.method == "shooting":  # a field of more than 25 states: diag Σ only
        solution.stats["sigma_reintegrated"] = True
    elif solution.Sigma is None:  # the Monte Carlo validation compares against Σ(t)
        return None, f"{path}: Sigma: expected the full error covariance Σ(t), got a file written without it"
    return solution, ""


def _with_sigma(solution: Solution, path: Path) -> str:
    """Re-integrate the Σ(t) of a field plan whose file keeps diag Σ only; why it failed, or ``""``.

    The Monte Carlo validation compares against the whole Σ(t): the plan's, integrated as the plan check does
    (DOP853, rtol 1e-10; docs/theory/replay.md §1.3).
    """
    from ...ocp.field_plan_check import plan_covariances

    try:
        solution.Sigma = plan_covariances(solution)
    except RuntimeError as err:
        return f"{path}: Sigma: the file keeps diag Σ only and the plan's Σ(t) could not be re-integrated ({err})"
    return ""


def _check(
    solution_path: Path, problem_path: Path | None, task: int | None = None, rebuild: bool = True
) -> tuple[Solution | None, Problem | None, str]:
    """Solution (or None: solve first), the problem (if given) and what was found (see :func:`load_checked`)."""
    from ...core.config import ConfigError
    from ...ocp.problem import load_problem

    problem = None if problem_path is None else load_problem(problem_path)  # ConfigError (one line) if invalid
    if solution_path.is_dir() and (solution_path / "solution.nc").is_file():  # a solve's output folder
        solution_path = solution_path / "solution.nc"
    if not solution_path.is_file():
        from ...core.input_text import missing_file

        if problem is None or solution_path.exists():
            hint = " (give 'problem:' to solve it first)" if not solution_path.exists() else ""
            raise ConfigError(f"{solution_path}: {missing_file(solution_path)}{hint}")
        return None, problem, f"{solution_path} not found"
    solution, why = _read_solution(solution_path, task)
    current = None if problem is None else problem.digest()
    if solution is not None and current is not None and (stored := solution.problem.digest()) != current:
        why = f"{solution_path} is stale: it solves problem hash {stored}, {problem_path} has hash {current}"
        solution = None
    rebuilt = ""
    if solution is not None and solution.stats.get("sigma_reintegrated"):
        rebuilt = (
            f"; Σ(t) {'re-integrated' if rebuild else 'to be re-integrated'} from its plan (the file keeps diag Σ only)"
        )
        if rebuild and (why := _with_sigma(solution, solution_path)):
            solution = None
    if solution is None:
        if problem is None:
            raise ConfigError(f"{why}; give 'problem:' to solve it instead")
        return None, problem, why
    if problem is None:
        return solution, None, f"loaded {solution_path} (not checked against a problem file: give 'problem:'){rebuilt}"
    return solution, problem, f"loaded {solution_path} (problem hash {current} matches {problem_path}){rebuilt}"


def reference_status(
    solution_path: Path, problem_path: Path | None, task: int | None = None, tracking: Any = None, source: str = ""
) -> str:
    """What :func:`load_checked` would do, without solving (for ``mobisense validate``).

    With ``tracking`` (:class:`~mobisense.formation.replay.plan.TrackingGains`) its gains are also checked
    against the plan's horizon (``ConfigError`` naming ``source``), as the replay will.
    """
    solution, problem, note = _check(solution_path, problem_path, task, rebuild=False)  # validate: nothing computed
    planned = solution.problem if solution is not None else problem
    if tracking is not None and planned is not None:
        tracking.check_horizon(planned.horizon.tf - planned.horizon.t0, source)
    return note if solution is not None else f"{note}: the replay solves {problem_path} first"


def replay_method(problem: Problem) -> str:
    """The method a replay solves ``problem`` by when no usable solution is given.

    ``"shooting"`` for a field problem (direct collocation cannot hold its states), else ``"direct"``; the replay's
    budget (:mod:`mobisense.formation.sizes`) estimates the same solve.
    """
    return "shooting" if problem.solver.method == "shooting" else "direct"


def load_checked(solution_path: Path, problem_path: Path | None, task: int | None = None) -> tuple[Solution, str, bool]:
    """The solution of ``solution_path`` if it is up to date with ``problem_path``, else ``problem_path`` solved.

    ``task`` picks one task of a sweep's ``tasks/part-NNNNNN.nc`` (its sweep index; see
    :mod:`mobisense.ocp.task_files`).

    The solution's problem hash (:meth:`~mobisense.ocp.problem.Problem.digest`, which covers the solver
    options) must equal the problem file's; a missing, unreadable, failed or stale solution is replaced by
    the direct-collocation solution of the problem.

    Returns
    -------
    solution : Solution
    note : str
        What happened (printed by the command and stored in ``summary.json``).
    solved : bool
        Whether the problem was solved here (the caller writes the new ``solution.nc``).

    Raises
    ------
    ConfigError
        The solution cannot be used and there is no problem to solve, or the problem file is invalid.
    RuntimeError
        The solver did not reach ε = 1.
    """
    solution, problem, note = _check(solution_path, problem_path, task)
    if solution is not None:
        return solution, note, False
    assert problem is not None  # _check raises when there is neither
    if replay_method(problem) == "shooting":
        from ...ocp.field_solve import solve_shooting

        solution, how = solve_shooting(problem), "by shooting"
    else:
        from ...ocp.direct.solver import solve_direct

        solution, how = solve_direct(problem), "by direct collocation"
    if not solution.success:
        raise RuntimeError(f"solving {problem_path} failed: {solution.message}")
    return solution, f"{note}: solved {problem_path} {how}", True


def load_or_solve(solution_path: Path, problem_path: Path | None) -> tuple[Solution, str]:
    """:func:`load_checked` without the flag: the solution and what happened."""
    solution, note, _ = load_checked(solution_path, problem_path)
    return solution, note


class ReferenceTrajectory:
    """Reference positions, velocities and feed-forward accelerations of every sensor of a solution.

    Parameters
    ----------
    t : ndarray, shape (T,)
        State times of the solution (strictly increasing).
    p, v : ndarray, shape (T, N, 2)
        Positions (L) and velocities (L/T) there.
    t_u : ndarray, shape (Tu,)
        Control times.
    u : ndarray, shape (Tu, N, 2)
        Optimised controls (L/T²); held constant outside ``[t_u[0], t_u[-1]]``.
    """

    def __init__(self, t: np.ndarray, p: np.ndarray, v: np.ndarray, t_u: np.ndarray, u: np.ndarray) -> None:
        from scipy.interpolate import CubicHermiteSpline, interp1d

        t, p, v = np.asarray(t, float), np.asarray(p, float), np.asarray(v, float)
        if np.any(np.diff(t) <= 0):
            raise ValueError("t: expected strictly increasing state times")
        self.t0, self.tf = float(t[0]), float(t[-1])
        self.n_sensors = p.shape[1]
        self._position = CubicHermiteSpline(t, p, v, axis=0)
        self._velocity = self._position.derivative()
        u = np.asarray(u, float)
        self._control = interp1d(np.asarray(t_u, float), u, axis=0, bounds_error=False, fill_value=(u[0], u[-1]))

    @classmethod
    def from_solution(cls, solution: Solution) -> ReferenceTrajectory:
        """The reference of a :class:`~mobisense.ocp.solution.Solution`."""
        return cls(solution.t, solution.p, solution.v, solution.t_u, solution.u)

    def __call__(self, t: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``p_ref, v_ref, u_ref`` at time(s) ``t``, each of shape ``t.shape + (N, 2)``."""
        t = np.clip(t, self.t0, self.tf)
        return self._position(t), self._velocity(t), self._control(t)

    def acceleration(self, t: float | np.ndarray) -> np.ndarray:
        """``p_ref''(t)`` of the Hermite spline (piecewise linear), shape ``t.shape + (N, 2)``.

        ``u_ref − p_ref''`` is the residual that drives the tracking error (see the module notes).
        """
        return self._position.derivative(2)(np.clip(t, self.t0, self.tf))


@dataclass(frozen=True)
class TrackingController(FixedShapeController):
    """PD tracking with feed-forward of a reference trajectory: the shape controller's law applied to positions.

    Parameters
    ----------
    stiffness : float
        ``Kp`` (1/T²).
    damping : float
        ``Kd`` (1/T).
    """

    def __call__(  # type: ignore[override]
        self, position: np.ndarray, velocity: np.ndarray, reference: tuple[np.ndarray, np.ndarray, np.ndarray]
    ) -> np.ndarray:
        """Acceleration ``u_ref + Kp (p_ref − r) + Kd (v_ref − r')``, shape of ``position``."""
        p_ref, v_ref, u_ref = reference
        return super().__call__(position, velocity, p_ref, v_ref, u_ref)
