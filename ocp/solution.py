"""The result of a solve: trajectories, costates, cost split, homotopy record; saved as netCDF + JSON.

``solution.nc`` (xarray, h5netcdf) holds ``Sigma (time, row, col)``, ``p``/``v`` ``(time, sensor, xy)``,
``u (time_u, sensor, xy)``, costates ``Lam (time_costate, row, col)``, ``lam_p``/``lam_v``
``(time_costate, sensor, xy)`` when present, the homotopy path (``path_p``, ``path_Sigma`` per ε step),
and as attributes the normalised problem (YAML), the summary (JSON) and the solver options.
:meth:`Solution.load` reads it back.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ocp.files import to_jsonable, write_json, write_netcdf
from ocp.problem import Problem

__all__ = ["HomotopyStep", "Solution"]


@dataclass
class HomotopyStep:
    """One continuation step: ε, J_ε, Ipopt iterations and status, wall time (s)."""

    eps: float
    cost: float
    iterations: int
    status: str
    time_s: float
    success: bool = True


@dataclass
class Solution:
    """A solved (or partially solved) mobile-sensor Kalman problem.

    Arrays: ``t`` (T,) state times; ``Sigma`` (T, n, n); ``p``, ``v`` (T, N, 2); ``t_u`` (Tu,) control times;
    ``u`` (Tu, N, 2); optional costates on ``t_costate`` (Tc,): ``Lam`` (Tc, n, n), ``lam_p``, ``lam_v``
    (Tc, N, 2) — the PMP costates of J at ε = ``eps`` (Λ is the symmetric matrix costate of Σ).
    """

    problem: Problem
    method: str
    status: str
    message: str
    eps: float
    t: np.ndarray
    Sigma: np.ndarray
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

    @property
    def cost(self) -> float:
        """J at ε = 1: Tr[M Σ(tf)] + ∫ (α/2|u|² + Tr KΣ) dt."""
        return self.terminal_cost + self.running_cost

    @property
    def success(self) -> bool:
        """True when ε = 1 was reached and Ipopt converged."""
        return self.status == "solved"

    @property
    def min_sigma_eigenvalue(self) -> float:
        """Smallest eigenvalue of Σ(t) over the state grid (must be > 0)."""
        return float(np.linalg.eigvalsh(self.Sigma).min())

    def summary(self) -> dict[str, Any]:
        """The ``summary.json`` contract (see README)."""
        base = self.baseline.get("cost")
        out: dict[str, Any] = {
            "name": self.problem.name,
            "method": self.method,
            "status": self.status,
            "message": self.message,
            "eps_reached": self.eps,
            "cost": self.cost,
            "terminal_cost": self.terminal_cost,
            "running_cost": self.running_cost,
            "control_energy": self.control_energy,
            "solve_time_s": float(sum(step.time_s for step in self.homotopy)),
            "homotopy": [
                {"eps": s.eps, "cost": s.cost, "iterations": s.iterations, "status": s.status, "time_s": s.time_s}
                for s in self.homotopy
            ],
            "baseline": self.baseline,
            "improvement_percent": None if not base else 100.0 * (base - self.cost) / base,
            "min_sigma_eigenvalue": self.min_sigma_eigenvalue,
            "sigma_positive_definite": self.min_sigma_eigenvalue > 0,
            "problem_hash": self.problem.digest(),
            "solver": self.problem.solver.model_dump(mode="json"),
        }
        out.update(self.stats)
        return to_jsonable(out)

    # ------------------------------------------------------------------ persistence
    def to_dataset(self) -> Any:
        """Return the solution as an ``xarray.Dataset``."""
        import xarray as xr

        names = [s.name for s in self.problem.sensors]
        xy = ["x", "y"]
        n = self.problem.n
        data: dict[str, Any] = {
            "Sigma": (("time", "row", "col"), self.Sigma, {"long_name": "error covariance Σ(t)"}),
            "p": (("time", "sensor", "xy"), self.p, {"long_name": "sensor position", "units": "L"}),
            "v": (("time", "sensor", "xy"), self.v, {"long_name": "sensor velocity", "units": "L/T"}),
            "u": (("time_u", "sensor", "xy"), self.u, {"long_name": "sensor control", "units": "L/T^2"}),
        }
        coords: dict[str, Any] = {
            "time": self.t,
            "time_u": self.t_u,
            "sensor": names,
            "xy": xy,
            "row": np.arange(n),
            "col": np.arange(n),
        }
        if self.Lam is not None:
            coords["time_costate"] = self.t_costate
            data["Lam"] = (("time_costate", "row", "col"), self.Lam, {"long_name": "costate of Σ"})
            data["lam_p"] = (("time_costate", "sensor", "xy"), self.lam_p, {"long_name": "costate of p"})
            data["lam_v"] = (("time_costate", "sensor", "xy"), self.lam_v, {"long_name": "costate of v"})
        if self.path_eps is not None:
            coords["step"] = np.arange(len(self.path_eps))
            data["path_eps"] = (("step",), self.path_eps)
            data["path_p"] = (("step", "time", "sensor", "xy"), self.path_p)
            data["path_Sigma"] = (("step", "time", "row", "col"), self.path_Sigma)
        if self.nlp is not None:
            for key in ("w", "lam_w", "lam_g", "P"):
                dim = {"w": "nlp_w", "lam_w": "nlp_w", "lam_g": "nlp_g", "P": "nlp_p"}[key]
                data[f"nlp_{key}"] = ((dim,), np.asarray(self.nlp[key]), {"long_name": f"NLP {key} (warm starts)"})
        attrs = {
            "nlp_signature": "" if self.nlp is None else self.nlp["signature"],
            "problem_yaml": yaml.safe_dump(self.problem.normalised(), sort_keys=False),
            "solver_options_json": self.problem.solver.model_dump_json(),
            "summary_json": json.dumps(self.summary()),
            "homotopy_json": json.dumps(to_jsonable([asdict(s) for s in self.homotopy])),
            "baseline_json": json.dumps(to_jsonable(self.baseline)),
            "stats_json": json.dumps(to_jsonable(self.stats)),
            "method": self.method,
            "status": self.status,
            "message": self.message,
            "eps": self.eps,
            "terminal_cost": self.terminal_cost,
            "running_cost": self.running_cost,
            "control_energy": self.control_energy,
            "conventions": "Sigma/Lam full symmetric matrices; costates of J (minimisation, H = L + lam'f)",
        }
        return xr.Dataset(data, coords=coords, attrs=attrs)

    def save(self, folder: str | Path) -> None:
        """Write ``solution.nc`` and ``summary.json`` into ``folder`` (atomically)."""
        folder = Path(folder)
        write_netcdf(folder / "solution.nc", self.to_dataset())
        write_json(folder / "summary.json", self.summary())

    @classmethod
    def from_dataset(cls, ds: Any) -> Solution:
        """Rebuild a Solution from :meth:`to_dataset` output."""
        a = ds.attrs
        problem = Problem.from_dict(yaml.safe_load(a["problem_yaml"]), source="solution.nc:problem_yaml")
        has_costates = "Lam" in ds
        has_path = "path_eps" in ds
        return cls(
            problem=problem,
            method=str(a["method"]),
            status=str(a["status"]),
            message=str(a["message"]),
            eps=float(a["eps"]),
            t=ds["time"].values,
            Sigma=ds["Sigma"].values,
            p=ds["p"].values,
            v=ds["v"].values,
            t_u=ds["time_u"].values,
            u=ds["u"].values,
            terminal_cost=float(a["terminal_cost"]),
            running_cost=float(a["running_cost"]),
            control_energy=float(a["control_energy"]),
            homotopy=[HomotopyStep(**s) for s in json.loads(a["homotopy_json"])],
            t_costate=ds["time_costate"].values if has_costates else None,
            Lam=ds["Lam"].values if has_costates else None,
            lam_p=ds["lam_p"].values if has_costates else None,
            lam_v=ds["lam_v"].values if has_costates else None,
            path_eps=ds["path_eps"].values if has_path else None,
            path_p=ds["path_p"].values if has_path else None,
            path_Sigma=ds["path_Sigma"].values if has_path else None,
            baseline=json.loads(a["baseline_json"]),
            stats=json.loads(a["stats_json"]),
            nlp=None
            if "nlp_w" not in ds
            else {
                "w": ds["nlp_w"].values,
                "lam_w": ds["nlp_lam_w"].values,
                "lam_g": ds["nlp_lam_g"].values,
                "P": ds["nlp_P"].values,
                "signature": str(a["nlp_signature"]),
            },
        )

    @classmethod
    def load(cls, path: str | Path) -> Solution:
        """Load ``solution.nc`` (or a folder containing it)."""
        import xarray as xr

        path = Path(path)
        if path.is_dir():
            path = path / "solution.nc"
        with xr.open_dataset(path, engine="h5netcdf") as ds:
            return cls.from_dataset(ds.load())
