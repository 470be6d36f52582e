"""``result.nc`` and ``summary.json`` of a field replay (:mod:`mobisense.formation.replay.simulation`).

Variables of the dataset (dimension ``time`` = the filter samples):

* ``z_true, z_est`` (time), ``grad_true, grad_est`` (time, xy) at the formation centre; ``z_std``,
  ``grad_std`` from the filter covariance; ``hess_true, hess_est`` (time, xy, xy2);
* ``r, v`` (time, platform, xy), ``center`` (time, xy), ``measurements`` (time, platform);
* ``a, b`` — half-distances ``½‖r2 − r1‖``, ``½‖r3 − r4‖`` (the shape variables of Zhang & Leonard (2010), §III-D; b is
  NaN for N < 4) — and their desired values ``a_desired, b_desired``; ``shape_error = ‖q − q^d‖``;
* ``theta`` — heading error of the centre w.r.t. the true level curve through it (docs/theory/level_curve.md,
  eq. level_curve.3), ``theta_est`` the one the controller saw from the estimate; ``lyapunov`` ``V(θ, z)`` on the true
  field (level-curve motion); ``reference, reference_error`` (reference motion);
* attributes: the level ``C`` (NaN for reference motion), units, scenario name, seed.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...core.units import UnitSystem
from ..level_curve import heading_error
from ..shape_control import shape_error
from .simulation import CenterLevelCurve, ReplayRecord, ReplaySystem

__all__ = ["replay_dataset", "replay_summary", "mean_abs_curvature", "units_of"]


def replay_dataset(record: ReplayRecord, system: ReplaySystem, seed: int) -> Any:
    """The replay as an ``xarray.Dataset`` (see the module docstring)."""
    import xarray as xr

    s, A = system.scenario, record.arrays()
    u = s.units
    N = system.n_platforms
    center, center_velocity = system.jacobi.to_jacobi(A["r"])[0], system.jacobi.to_jacobi(A["v"])[0]
    q = system.jacobi.to_jacobi(A["r"])[1]
    _, theta = heading_error(center_velocity, A["grad_true"])
    _, theta_est = heading_error(center_velocity, A["grad_est"])
    half = 0.5 * np.linalg.norm(A["r"][:, 1] - A["r"][:, 0], axis=-1)
    other = (
        0.5 * np.linalg.norm(A["r"][:, 2] - A["r"][:, 3], axis=-1) if N >= 4 else np.full(len(half), np.nan)
    )
    P = A["covariance"]
    us = units_of(s)
    F, FL, FL2, L = us.of(field=1), us.of(field=1, length=-1), us.of(field=1, length=-2), us.of(length=1)
    T, P2, X = ("time",), ("time", "platform", "xy"), ("time", "xy")
    data = {
        "z_true": (T, A["z_true"], {"long_name": "true field value at the formation centre", "units": F}),
        "z_est": (T, A["z_est"], {"long_name": "filter estimate of the field at the centre", "units": F}),
        "z_std": (T, np.sqrt(P[:, 0, 0]), {"long_name": "filter standard deviation of the field estimate",
                                           "units": F}),
        "grad_true": (X, A["grad_true"], {"long_name": "true field gradient at the centre", "units": FL}),
        "grad_est": (X, A["grad_est"], {"long_name": "filter estimate of the gradient at the centre", "units": FL}),
        "grad_std": (X, np.sqrt(np.stack([P[:, 1, 1], P[:, 2, 2]], -1)),
                     {"long_name": "filter standard deviation of each gradient component", "units": FL}),
        "hess_true": (X + ("xy2",), A["hess_true"], {"long_name": "true field Hessian at the centre", "units": FL2}),
        "hess_est": (X + ("xy2",), A["hess_est"], {"long_name": "Hessian estimate used by the filter", "units": FL2}),
        "r": (P2, A["r"], {"long_name": "platform position", "units": L}),
        "v": (P2, A["v"], {"long_name": "platform velocity", "units": us.of(length=1, time=-1)}),
        "center": (X, center, {"long_name": "formation centre (mean platform position)", "units": L}),
        "measurements": (("time", "platform"), A["measurements"],
                         {"long_name": "noisy field measurement of each platform", "units": F}),
        "a": (T, half, {"long_name": "half distance of platforms 1 and 2", "units": L}),
        "b": (T, other, {"long_name": "half distance of platforms 3 and 4 (NaN with fewer than 4)", "units": L}),
        "a_desired": (T, A["a_desired"], {"long_name": "desired half distance a", "units": L}),
        "b_desired": (T, A["b_desired"], {"long_name": "desired half distance b", "units": L}),
        "shape_error": (T, shape_error(q, A["q_desired"]),
                        {"long_name": "formation shape error |q - q_desired| (Jacobi vectors)", "units": L}),
        "theta": (T, theta, {"long_name": "heading error w.r.t. the true level curve", "units": "rad"}),
        "theta_est": (T, theta_est, {"long_name": "heading error seen by the controller", "units": "rad"}),
    }  # fmt: skip
    level = np.nan
    if isinstance(system.center, CenterLevelCurve):
        level = system.center.controller.level
        V = system.center.controller.lyapunov(theta, A["z_true"])
        data["lyapunov"] = (T, V, {"long_name": "Lyapunov function -log cos^2(theta/2) + h(z) on the true field",
                                   "units": "1"})  # fmt: skip
    if record.reference is not None:
        error = np.linalg.norm(center - record.reference, axis=-1)
        data["reference"] = (X, record.reference, {"long_name": "reference path of the centre", "units": L})
        data["reference_error"] = (T, error, {"long_name": "distance of the centre from its reference", "units": L})
    attrs = {
        "title": f"mobisense: field replay '{s.name}'",
        "C": level, "scenario": s.name, "seed": seed, "field": s.field.kind, "formation": s.formation.kind,
        "motion": s.motion.kind, "length_unit": u.length, "time_unit": u.time, "field_unit": u.field,
        "time_step": s.time_step,
    }  # fmt: skip
    coords = {
        "time": ("time", A["t"], {"long_name": "time of the filter samples", "units": us.of(time=1)}),
        "platform": ("platform", np.arange(1, N + 1), {"long_name": "platform number", "units": "1"}),
        "xy": ("xy", ["x", "y"], {"long_name": "planar component"}),
        "xy2": ("xy2", ["x", "y"], {"long_name": "planar component (second index of the Hessian)"}),
    }
    return xr.Dataset(data, coords=coords, attrs=attrs)


def units_of(scenario: Any) -> UnitSystem:
    """The :class:`~mobisense.core.units.UnitSystem` of a field-replay scenario (length, time, field)."""
    u = scenario.units
    return UnitSystem(u.length, u.time, {"field": u.field})


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.nanmean(np.asarray(x, float) ** 2)))


def replay_summary(ds: Any, record: ReplayRecord, system: ReplaySystem) -> dict[str, Any]:
    """Metrics of a replay: level error, heading, estimation errors, shape and tracking errors."""
    K = ds.sizes["time"]
    last_quarter, last_half = slice(K - max(1, K // 4), K), slice(K // 2, K)
    z_err = (ds["z_est"] - ds["z_true"]).values
    g_err = np.linalg.norm((ds["grad_est"] - ds["grad_true"]).values, axis=-1)
    e = np.concatenate([z_err[:, None], (ds["grad_est"] - ds["grad_true"]).values], axis=-1)
    P = np.asarray(record.covariance)
    nees = np.einsum("ki,ki->k", e, np.linalg.solve(P, e[..., None])[..., 0])
    wall = record.meta["wall_time_s"]
    s = system.scenario
    summary: dict[str, Any] = {
        "kind": "field",
        "scenario": s.name,
        "platforms": system.n_platforms,
        "duration": s.duration,
        "time_step": s.time_step,
        "steps": record.meta["steps"],
        "units": s.units.model_dump(),
        "derivatives": "true field" if system.true_derivatives else "filter estimates",
        "rms_z_error": _rms(z_err),
        "rms_gradient_error": _rms(g_err),
        "mean_nees": float(nees.mean()),
        "final_z_std": float(ds["z_std"].values[-1]),
        "shape_error_rms_last_half": _rms(ds["shape_error"].values[last_half]),
        "shape_error_final": float(ds["shape_error"].values[-1]),
        "a_final": float(ds["a"].values[-1]),
        "b_final": float(ds["b"].values[-1]),
        "a_range": [float(np.nanmin(ds["a"].values)), float(np.nanmax(ds["a"].values))],
        "mean_abs_theta_last_quarter": float(np.mean(np.abs(ds["theta"].values[last_quarter]))),
        "wall_time_s": wall,
        "simulated_time_per_wall_second": s.duration / wall if wall > 0 else None,
    }
    if np.isfinite(ds.attrs["C"]):
        level_error = np.abs(ds["z_true"].values - ds.attrs["C"])
        summary.update(
            level=ds.attrs["C"],
            final_level_error=float(level_error[-1]),
            max_level_error_last_half=float(level_error[last_half].max()),
            rms_level_error_last_half=_rms(level_error[last_half]),
            lyapunov_max_increase=float(np.max(np.diff(ds["lyapunov"].values), initial=0.0)),
        )
    if "reference_error" in ds:
        summary.update(
            reference_tracking_rms=_rms(ds["reference_error"].values),
            reference_tracking_max=float(ds["reference_error"].values.max()),
            reference_tracking_final=float(ds["reference_error"].values[-1]),
        )
    summary.update({k: v for k, v in record.meta.items() if k not in ("wall_time_s", "steps")})
    bounds = getattr(system.field, "bounds", None)  # a gridded field: its data cover only this rectangle
    if bounds is not None:
        (x0, x1), (y0, y1) = bounds
        r = np.asarray(record.r, float)
        outside = (r[..., 0] < x0) | (r[..., 0] > x1) | (r[..., 1] < y0) | (r[..., 1] > y1)
        summary["outside_field_data"] = float(outside.mean())
        if outside.any():
            first = float(np.asarray(record.t)[np.argmax(outside.any(axis=1))])
            summary["warning"] = (
                f"the platforms left the gridded field's data [{x0:g}, {x1:g}] × [{y0:g}, {y1:g}] in "
                f"{100 * outside.mean():.3g} % of their samples (first at t = {first:g}): the field's values there "
                "are the spline's extrapolation, not data"
            )
    return summary


def mean_abs_curvature(path: np.ndarray, step: float = 0.05, trim: int = 5) -> float:
    """Mean absolute curvature of a polyline, resampled at equal arclength (docs/theory/replay.md §2.6).

    Parameters
    ----------
    path : ndarray, shape (M, 2)
        Points of the curve (L), e.g. a formation centre's path or a contour's vertices.
    step : float
        Arclength between resampled points (L); curvature by central differences of the resampled curve.
    trim : int
        Resampled points dropped at each end (one-sided differences there).

    Returns
    -------
    float
        ``mean |κ|`` (1/L), ``κ = (x'y'' − y'x'') / |r'|³``.
    """
    path = np.asarray(path, dtype=float)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    su = np.arange(0.0, s[-1], step)
    p = np.stack([np.interp(su, s, path[:, i]) for i in range(2)], axis=-1)
    v = np.gradient(p, step, axis=0)
    a = np.gradient(v, step, axis=0)
    kappa = (v[:, 0] * a[:, 1] - v[:, 1] * a[:, 0]) / np.linalg.norm(v, axis=1) ** 3
    return float(np.mean(np.abs(kappa[trim:-trim])))

