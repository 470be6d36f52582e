"""The result of a solve: trajectories, costates, cost split, homotopy record; saved as netCDF + JSON.

``solution.nc`` (xarray, h5netcdf) holds ``Sigma (time, row, col)``, ``p``/``v`` ``(time, sensor, xy)``,
``u (time_u, sensor, xy)``, costates ``Lam (time_costate, row, col)``, ``lam_p``/``lam_v``
``(time_costate, sensor, xy)`` when present, the homotopy path (``path_p``, ``path_Sigma`` per ε step),
and as attributes the normalised problem (YAML), the summary (JSON) and the solver options.
:meth:`Solution.load` reads it back.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..core.errors import ConfigError, brief
from ..core.files import to_jsonable, write_json, write_netcdf
from ..core.netcdf_writer import DatasetContent
from .problem import Problem
from .solution_file import brief_error, open_solution_file, read_solution_problem
from .solution_warnings import solution_warnings
from .solve_outcome import SolveStatus, StartKind
from .state_layout import StateLayout

__all__ = ["SolveStatus", "StartKind", "HomotopyStep", "TrajectorySample", "Solution"]


@dataclass
class TrajectorySample:
    """A solution evaluated at chosen times: ``t`` (T,), ``Sigma`` (T, n, n), ``p``, ``v``, ``u`` (T, N, 2)."""

    t: np.ndarray
    Sigma: np.ndarray
    p: np.ndarray
    v: np.ndarray
    u: np.ndarray


@dataclass
class HomotopyStep:
    """One solve of a start: ε, J_ε, Ipopt iterations and status, wall time (s), which start it belongs to."""

    eps: float
    cost: float
    iterations: int
    status: str
    time_s: float
    success: bool = True
    start: str = ""


@dataclass
class Solution:
    """A solved (or partially solved) mobile-sensor Kalman problem.

    Arrays: ``t`` (T,) state times; ``Sigma`` (T, n, n) (None if loaded from a file written without it, a field
    solution of more than 25 states: then ``sigma_diag`` (T, n) holds its diagonal, see :meth:`variances`);
    ``p``, ``v`` (T, N, 2); ``t_u`` (Tu,) control times;
    ``u`` (Tu, N, 2); optional costates on ``t_costate`` (Tc,): ``Lam`` (Tc, n, n), ``lam_p``, ``lam_v``
    (Tc, N, 2) — the PMP costates of J at ε = ``eps`` (Λ is the symmetric matrix costate of Σ).
    """

    problem: Problem
    method: str
    status: SolveStatus
    message: str
    eps: float
    t: np.ndarray
    Sigma: np.ndarray | None
    p: np.ndarray
    v: np.ndarray
    t_u: np.ndarray
    u: np.ndarray
    terminal_cost: float
    running_cost: float
    control_energy: float
    homotopy: list[HomotopyStep] = field(default_factory=list)
    t_costate: np.ndarray | None = None
    Lam: np.ndarray | None = None
    lam_p: np.ndarray | None = None
    lam_v: np.ndarray | None = None
    path_eps: np.ndarray | None = None
    path_p: np.ndarray | None = None
    path_Sigma: np.ndarray | None = None
    baseline: dict[str, float] = field(default_factory=dict)
    stats: dict[str, Any] = field(default_factory=dict)
    #: the converged NLP point (scaled w, lam_w, lam_g, parameters P, layout signature) for warm starts
    nlp: dict[str, Any] | None = None
    #: (scheme, degree, intervals) when the states are collocation polynomials on a uniform grid
    collocation: tuple[str, int, int] | None = None
    #: diag Σ(t), shape (T, n), read from a file that holds no full Σ (``Sigma`` is None then)
    sigma_diag: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.status = SolveStatus(self.status)

    # ------------------------------------------------------------------ building
    @classmethod
    def from_states(
        cls,
        problem: Problem,
        method: str,
        status: SolveStatus | str,
        message: str,
        eps: float,
        t: np.ndarray,
        x: np.ndarray,
        t_u: np.ndarray,
        u: np.ndarray,
        costs: tuple[float, float, float],
        t_costate: np.ndarray | None = None,
        lam: np.ndarray | None = None,
        path_eps: np.ndarray | None = None,
        path_x: np.ndarray | None = None,
        **extra: Any,
    ) -> Solution:
        """The one way to build a Solution from state vectors (direct and indirect methods alike).

        Parameters
        ----------
        problem : Problem
        method : str
            ``"direct"``, ``"indirect"``, …
        status : SolveStatus or str
        message : str
        eps : float
            The ε of the states (1 when solved).
        t : ndarray, shape (T,)
            State times (T).
        x : ndarray, shape (T, nx)
            States in the layout of :class:`~mobisense.ocp.state_layout.StateLayout`.
        t_u : ndarray, shape (Tu,)
            Control times.
        u : ndarray, shape (Tu, 2N)
            Controls (L/T²).
        costs : tuple of float
            ``(terminal_cost, running_cost, control_energy)`` of J at ε = 1.
        t_costate : ndarray, shape (Tc,), optional
        lam : ndarray, shape (Tc, nx), optional
            Costates of J (split into Λ, λ_p, λ_v with :meth:`StateLayout.split_costate`).
        path_eps : ndarray, shape (S,), optional
            The ε of each accepted homotopy step.
        path_x : ndarray, shape (S, T, nx), optional
            The states of each accepted homotopy step on ``t``.
        **extra
            Any other field (``homotopy``, ``baseline``, ``stats``, ``nlp``, ``collocation``).
        """
        layout = StateLayout(problem.n, problem.N)
        Sigma, p, v = layout.split(x)
        solution = cls(
            problem=problem,
            method=method,
            status=SolveStatus(status),
            message=message,
            eps=eps,
            t=np.asarray(t, float),
            Sigma=Sigma,
            p=p,
            v=v,
            t_u=np.asarray(t_u, float),
            u=np.asarray(u, float).reshape(len(t_u), problem.N, 2),
            terminal_cost=costs[0],
            running_cost=costs[1],
            control_energy=costs[2],
            **extra,
        )
        if lam is not None:
            solution.t_costate = np.asarray(t_costate, float)
            solution.Lam, solution.lam_p, solution.lam_v = layout.split_costate(lam)
        if path_x is not None:
            solution.path_eps = np.asarray(path_eps, float)
            solution.path_Sigma, solution.path_p, _ = layout.split(path_x)
        return solution

    @property
    def layout(self) -> StateLayout:
        """The state layout of this solution's problem."""
        return StateLayout(self.problem.n, self.problem.N)

    def states(self) -> np.ndarray:
        """States x (T, nx) on :attr:`t`."""
        return self.layout.join(self.Sigma, self.p, self.v)

    def costates(self) -> np.ndarray:
        """Costates λ (Tc, nx) on :attr:`t_costate` (``ValueError`` if the solution has none)."""
        if self.Lam is None:
            raise ValueError("this solution carries no costates")
        return self.layout.join_costate(self.Lam, self.lam_p, self.lam_v)

    @property
    def cost(self) -> float:
        """J at ε = 1: Tr[M Σ(tf)] + ∫ (α/2|u|² + Tr KΣ) dt."""
        return self.terminal_cost + self.running_cost

    @property
    def success(self) -> bool:
        """True when ε = 1 was reached and Ipopt converged."""
        return self.status is SolveStatus.SOLVED

    @property
    def min_sigma_eigenvalue(self) -> float:
        """Smallest eigenvalue of Σ(t) over the state grid (must be > 0); from ``stats`` when Σ was not kept."""
        if self.Sigma is None:
            return float(self.stats["min_sigma_eigenvalue"])
        return float(np.linalg.eigvalsh(self.Sigma).min())

    def variances(self) -> np.ndarray:
        """The error variances diag Σ(t) on the state times ``t``, shape (T, n) (units: state²).

        From ``Sigma``, or from ``sigma_diag`` when the solution was loaded from a file that keeps only the
        diagonal (a field solution of more than 25 states, ``solver.shooting.full_sigma``).
        """
        if self.Sigma is not None:
            return np.diagonal(self.Sigma, axis1=1, axis2=2)
        if self.sigma_diag is None:
            raise ValueError("this solution holds neither Σ(t) nor its diagonal")
        return self.sigma_diag

    def non_finite(self) -> str | None:
        """What is NaN or infinite in the solution (cost, Σ, p, v, u), or ``None`` if everything is finite."""
        for name in ("terminal_cost", "running_cost", "control_energy"):
            if not np.isfinite(getattr(self, name)):
                return f"the {name.replace('_', ' ')} is {getattr(self, name)}"
        for name in ("Sigma", "p", "v", "u"):
            if getattr(self, name) is None:  # Σ of a file that keeps its diagonal only
                continue
            values = np.asarray(getattr(self, name))
            if not np.all(np.isfinite(values)):
                return f"{name} has {int(np.size(values) - np.isfinite(values).sum())} NaN or infinite values"
        return None

    def reject_non_finite(self) -> None:
        """Mark a solve that produced NaN/inf as failed (an "optimum" that is not a number is not one)."""
        problem = self.non_finite()
        if problem is not None and self.success:
            self.status = SolveStatus.FAILED
            self.message = f"non-finite solution at ε = {self.eps:g}: {problem}"

    @property
    def worse_than_baseline(self) -> bool:
        """True when a converged solve costs more than not moving (u ≡ 0), a feasible plan: a poor local optimum."""
        base = self.baseline.get("cost")
        return bool(
            self.success
            and base is not None
            and np.isfinite(base)
            and self.cost > base * (1 + 1e-6)
            and self.baseline_feasible
        )

    @functools.cached_property
    def baseline_violations(self) -> list[str]:
        """The constraints the no-control baseline violates (:meth:`Problem.coasting_violations`), computed once."""
        return self.problem.coasting_violations()

    @property
    def baseline_feasible(self) -> bool:
        """Whether the no-control baseline satisfies the problem's constraints (else no improvement is quoted)."""
        return not self.baseline_violations

    @property
    def improvement_percent(self) -> float | None:
        """``100 (J_baseline − J) / J_baseline``; None without a baseline, when it is infeasible or the solve failed.

        J is the optimiser's, or the plan check's (the controls flown exactly) when the grid does not resolve the
        plan (:data:`~mobisense.ocp.solution_warnings.PLAN_TOLERANCE`): a grid error of 0.17 % was quoted as an
        improvement over coasting by a plan that coasts (random-problem audit).
        """
        from .solution_warnings import unresolved_plan_cost

        base = self.baseline.get("cost")
        if not base or not self.baseline_feasible or not self.success:
            return None
        flown = unresolved_plan_cost(self)
        return 100.0 * (base - (self.cost if flown is None else flown)) / base

    def summary(self) -> dict[str, Any]:
        """The ``summary.json`` contract (see README)."""
        smallest = self.min_sigma_eigenvalue  # an eigenvalue problem per state time: computed once
        out: dict[str, Any] = {
            "name": self.problem.name,
            "method": self.method,
            "status": self.status.value,
            "message": self.message,
            "eps_reached": self.eps,
            "cost": self.cost,
            "terminal_cost": self.terminal_cost,
            "running_cost": self.running_cost,
            "control_energy": self.control_energy,
            "solve_time_s": float(sum(step.time_s for step in self.homotopy)),
            "homotopy": [
                {
                    "eps": s.eps,
                    "cost": s.cost,
                    "iterations": s.iterations,
                    "status": s.status,
                    "time_s": s.time_s,
                    "start": s.start,
                }
                for s in self.homotopy
            ],
            "baseline": self.baseline,
            "baseline_feasible": self.baseline_feasible,
            "baseline_violations": self.baseline_violations,
            "improvement_percent": self.improvement_percent,
            "min_sigma_eigenvalue": smallest,
            "sigma_positive_definite": smallest > 0,
            "problem_hash": self.problem.digest(),
            "solver": self.problem.solver.model_dump(mode="json"),
            "worse_than_baseline": self.worse_than_baseline,
        }
        warnings = solution_warnings(self, smallest)
        if warnings:
            out["warning"] = "; and ".join(warnings)
        out.update(self.stats)
        return to_jsonable(out)

    # ------------------------------------------------------------------ persistence
    def to_content(self) -> DatasetContent:
        """What ``solution.nc`` holds, as numpy arrays (see :mod:`mobisense.ocp.solution_dataset`; no xarray)."""
        from .solution_dataset import solution_content

        return solution_content(self)

    def to_dataset(self) -> Any:
        """Return the solution as an ``xarray.Dataset`` (see :mod:`mobisense.ocp.solution_dataset`)."""
        return self.to_content().to_xarray()

    def to_xarray(self) -> Any:
        """The solution as an ``xarray.Dataset`` (what :meth:`save` writes as ``solution.nc``)."""
        return self.to_dataset()

    def sample(self, t: float | np.ndarray) -> TrajectorySample:
        """Evaluate the solution at any times in [t0, tf].

        For a direct solution the states are the collocation polynomials through each interval's d + 1
        nodes and the controls the Lagrange polynomials through its d collocation nodes (exactly the
        functions the NLP optimised); for a field's shooting solution the piecewise-linear controls and the
        positions and velocities they give (eq. field.7, exact) with Σ by PCHIP between the nodes, or NaN when
        the solution holds no Σ (a field of more than 25 states keeps its diagonal only); for a solution on
        BVP nodes, cubic splines through the nodes.

        Parameters
        ----------
        t : float or ndarray, shape (T,)
            Times (T) in [t0, tf]: ``TypeError`` for values that are not numbers, ``ValueError`` for another
            shape, NaN or a time outside.

        Returns
        -------
        TrajectorySample
            ``t`` (T,), ``Sigma`` (T, n, n), ``p`` and ``v`` (T, N, 2), ``u`` (T, N, 2).
        """
        given = np.asarray(t)
        if given.dtype.kind not in "iuf":
            raise TypeError(f"t: expected a time or a 1-D array of times (numbers), got {brief(t)}")
        times = np.atleast_1d(given.astype(float))
        if times.ndim != 1:
            raise ValueError(f"t: expected a time or a 1-D array of times, got an array of shape {times.shape}")
        if not np.all(np.isfinite(times)):
            raise ValueError(f"t: expected finite times, got {brief(times[~np.isfinite(times)][0])}")
        t0, tf = float(self.t[0]), float(self.t[-1])
        tol = 1e-12 * abs(tf - t0) + 8 * np.finfo(float).eps * max(abs(t0), abs(tf))
        if times.size and (times.min() < t0 - tol or times.max() > tf + tol):
            raise ValueError(f"t: expected times in [{t0:g}, {tf:g}], got [{times.min():g}, {times.max():g}]")
        times = np.clip(times, t0, tf)
        if self.method == "shooting":
            return self._sample_shooting(times)
        x = self.states()
        if self.collocation is not None:
            x_t, u_t = self._sample_collocation(times, x)
        else:
            from scipy.interpolate import CubicSpline

            x_t = CubicSpline(self.t, x, axis=0)(times)
            u_t = CubicSpline(self.t_u, self.u.reshape(len(self.t_u), -1), axis=0)(times)
        Sigma, p, v = self.layout.split(x_t)
        return TrajectorySample(times, Sigma, p, v, u_t.reshape(len(times), self.problem.N, 2))

    def _sample_shooting(self, times: np.ndarray) -> TrajectorySample:
        """The shooting's own functions: u linear on each interval, p and v integrated exactly (eq. field.7)."""
        from scipy.interpolate import PchipInterpolator

        from .field import flown_states

        t = self.t
        p, v, u = flown_states(t, self.p, self.v, self.u, times)
        n = self.problem.n
        if self.Sigma is None or np.ndim(self.Sigma) != 3:
            Sigma = np.full((len(times), n, n), np.nan)
        else:
            Sigma = PchipInterpolator(t, self.Sigma, axis=0)(times)
        return TrajectorySample(times, Sigma, p, v, u)

    def _sample_collocation(self, times: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        from .collocation import collocation_scheme

        scheme, degree, K = self.collocation  # type: ignore[misc]
        colloc = collocation_scheme(scheme, degree)
        t0, tf = float(self.t[0]), float(self.t[-1])
        node_times = t0 + (tf - t0) / K * (np.arange(K)[:, None] + colloc.tau[None, :])  # (K, d+1)
        tol = 1e-9 * abs(tf - t0) / K + 8 * np.finfo(float).eps * max(abs(t0), abs(tf))
        index = np.clip(np.searchsorted(self.t, node_times - tol), 0, len(self.t) - 1)
        return colloc.evaluate(times, t0, tf, x[index], self.u.reshape(K, degree, -1))

    def __repr__(self) -> str:
        base = self.baseline.get("cost")
        improvement = self.improvement_percent
        if improvement is not None:
            change = f" (J is {improvement:.1f} % lower)"
        else:
            change = " (infeasible: it violates the terminal constraints)"
        lines = [
            f"Solution of {self.problem.name!r} by the {self.method} method: {self.status.value} (ε = {self.eps:g})",
            f"  J = {self.cost:.10g} = terminal {self.terminal_cost:.6g} + running {self.running_cost:.6g}"
            f" (control energy {self.control_energy:.6g})",
        ]
        if base:
            lines.append(f"  no-control baseline J = {base:.10g}{change}")
        lines += [
            f"  n = {self.problem.n} process states, N = {self.problem.N} sensors, "
            f"t ∈ [{self.t[0]:g}, {self.t[-1]:g}]: {len(self.t)} state times, {len(self.t_u)} control times",
            f"  costates: {'on ' + str(len(self.t_costate)) + ' times' if self.t_costate is not None else 'none'}; "
            f"{len(self.homotopy)} Ipopt solve{'s' if len(self.homotopy) != 1 else ''} (ε steps of every start), "
            f"{sum(s.iterations for s in self.homotopy)} iterations, {sum(s.time_s for s in self.homotopy):.3g} s",
            f"  {self.message}",
        ]
        return "\n".join(lines)

    def save(self, folder: str | Path) -> None:
        """Write ``solution.nc`` and ``summary.json`` into ``folder`` (atomically)."""
        folder = Path(folder)
        write_netcdf(folder / "solution.nc", self.to_content())  # without importing xarray
        write_json(folder / "summary.json", self.summary())

    @classmethod
    def from_dataset(cls, ds: Any, source: str = "solution.nc") -> Solution:
        """Rebuild a Solution from :meth:`to_dataset` output (or a ``solution.nc`` read back).

        ``ConfigError`` naming ``source`` and the variable or attribute when the dataset is not a solution of
        the problem it stores: dimensions (checked before any value is read), times (finite, strictly
        increasing, within the horizon), values (a solved solution's are finite); see
        :func:`~mobisense.ocp.solution_dataset.check_layout` and :func:`~mobisense.ocp.solution_dataset.check_values`.
        """
        from .solution_dataset import check_layout, check_times, check_values, solution_fields, stored_problem

        problem = stored_problem(ds, source)
        check_layout(ds, problem, source)
        check_times(ds, problem, source)  # before the arrays on those times are read
        fields = solution_fields(ds, source, problem)
        check_values(fields, source)
        try:
            fields["homotopy"] = [HomotopyStep(**step) for step in fields["homotopy"]]
        except TypeError:
            raise ConfigError(
                f"{source}: homotopy_json: expected a list of steps {{eps, cost, iterations, status, time_s, "
                f"success, start}}, got {brief(fields['homotopy'])}"
            ) from None
        return cls(**fields)

    @classmethod
    def load(cls, path: str | Path, task: int | None = None) -> Solution:
        """Load ``solution.nc`` (or a folder containing it); ``ConfigError`` (one line) if it is not one.

        A sweep's ``tasks/part-NNNNNN.nc`` holds several tasks: ``task`` is the sweep index of the one to load
        (the ``index`` column of ``results.parquet``, whose ``solution_file`` column names the file). The arrays
        the file declares must fit the memory budget and have the shapes of a solution of its stored problem
        before any is read (:func:`~mobisense.ocp.solution_file.open_solution_file`, :meth:`from_dataset`).
        """
        with open_solution_file(path, task) as (ds, where):
            try:
                return cls.from_dataset(ds, str(where))
            except ConfigError:
                raise
            except (
                KeyError, ValueError, TypeError, IndexError, AttributeError, OSError, MemoryError, RuntimeError
            ) as exc:  # fmt: skip
                raise ConfigError(f"{where}: not a solution written by mobisense solve ({brief_error(exc)})") from None

    @staticmethod
    def read_problem(path: str | Path, task: int | None = None) -> Problem:
        """The problem stored in a ``solution.nc`` without loading its arrays (``ConfigError`` if unreadable).

        ``task`` picks one task of a sweep's ``tasks/part-NNNNNN.nc`` (its sweep index), as in :meth:`load`.
        """
        return read_solution_problem(path, task)
