"""Design the steady-state formation shape: ``mobisense steady-state FORMATION.yaml --out DIR``.

Reads a formation file (:class:`FormationFile`), e.g.::

    formation: cross
    noise: {sigma_process: 0.1, sigma_measurement: 0.5, sigma_hessian: 1.0}
    bounds: {a: [0.2, 3.0], b: [0.2, 3.0]}
    equal_sides: false

and writes ``summary.json`` (``a, b, trace, P_diag, gain, on_bound, stationary_point`` …),
``trace_grid.nc`` (tr P∞ over the (a, b) box) and ``trace_contour.png``. With ``formation: custom`` and
``positions: [[x, y], …]`` it evaluates the steady state of that shape by the DARE (no optimisation).
The file is validated completely before anything is written; errors exit with status 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import model_validator

from estimation.noise_config import NoiseConfig
from ocp.config import InvalidValue, PositiveFloat, StrictModel, Vector2, load_config

__all__ = ["FormationFile", "ShapeBounds", "add_arguments", "run"]


class ShapeBounds(StrictModel):
    """Bounds ``[min, max]`` (L) of the half-distances a and b (SPEC §2.4, condition Cd4)."""

    a: list[PositiveFloat]
    b: list[PositiveFloat]

    @model_validator(mode="after")
    def _ordered(self) -> ShapeBounds:
        for name in ("a", "b"):
            pair = getattr(self, name)
            if len(pair) != 2 or pair[0] > pair[1]:
                raise InvalidValue(name, f"expected [min, max] with 0 < min <= max, got {pair}")
        return self


class FormationFile(StrictModel):
    """A formation-design file read by ``mobisense steady-state``."""

    formation: Literal["cross", "custom"] = "cross"
    noise: NoiseConfig
    bounds: ShapeBounds | None = None
    equal_sides: bool = False
    positions: list[Vector2] | None = None
    contour_resolution: int = 121

    @model_validator(mode="after")
    def _consistent(self) -> FormationFile:
        if self.formation == "cross":
            if self.bounds is None:
                raise InvalidValue("bounds", "required for formation: cross (e.g. {a: [0.2, 3.0], b: [0.2, 3.0]})")
            if self.positions is not None:
                raise InvalidValue("positions", "only used with formation: custom")
        else:
            if self.positions is None:
                raise InvalidValue("positions", "required for formation: custom (list of [x, y])")
            arr = np.asarray(self.positions, dtype=float)
            offsets = arr - arr.mean(axis=0)
            if len(arr) < 3 or np.linalg.matrix_rank(offsets, tol=1e-9 * max(1.0, np.abs(offsets).max())) < 2:
                raise InvalidValue("positions", f"expected >= 3 platforms not all on one line, got {self.positions}")
        if not 11 <= self.contour_resolution <= 1001:
            raise InvalidValue("contour_resolution", f"expected 11 … 1001, got {self.contour_resolution}")
        return self


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the ``steady-state`` arguments."""
    parser.add_argument("formation", type=Path, help="formation YAML file")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default out/<file name>)")
    parser.add_argument("--no-plot", action="store_true", help="skip the contour plot")


def run(args: argparse.Namespace) -> int:
    """Validate, design, write ``summary.json``, ``trace_grid.nc`` and ``trace_contour.png``."""
    config = load_config(args.formation, FormationFile)
    out = args.out if args.out is not None else Path("out") / args.formation.stem
    from ocp.files import write_json

    if config.formation == "custom":
        write_json(out / "summary.json", _custom_summary(config))
        return 0
    from ocp.files import write_figure, write_netcdf

    summary, design = _cross_summary(config)
    grid = _trace_grid(config)
    write_json(out / "summary.json", summary)
    write_netcdf(out / "trace_grid.nc", grid)
    if not args.no_plot:
        write_figure(out / "trace_contour.png", lambda: _contour_figure(grid, design, config))
    print(f"{summary['stationary_point']}: a = {summary['a']:.6g}, b = {summary['b']:.6g}, "
          f"tr P = {summary['trace']:.6g} -> {out}")  # fmt: skip
    return 0


def _custom_summary(config: FormationFile) -> dict:
    from estimation.steady_state import steady_state

    noise = config.noise.to_noise()
    result = steady_state(np.asarray(config.positions, dtype=float), noise)
    return {
        "formation": "custom",
        "positions": result.positions,
        "trace": result.trace,
        "P_diag": np.diag(result.posterior),
        "posterior": result.posterior,
        "prior": result.prior,
        "gain": result.gain,
        "noise": config.noise.model_dump(),
        "method": "python-control dare (A = I)",
    }


def _bounds(config: FormationFile) -> tuple[tuple[float, float], tuple[float, float]]:
    """The (a, b) bounds; present for ``formation: cross`` (checked by :class:`FormationFile`)."""
    bounds = config.bounds if config.bounds is not None else ShapeBounds(a=[0.0, 0.0], b=[0.0, 0.0])
    return (bounds.a[0], bounds.a[1]), (bounds.b[0], bounds.b[1])


def _cross_summary(config: FormationFile) -> tuple[dict, object]:
    from estimation.formation_design import design_cross_formation

    n, bounds = config.noise, _bounds(config)
    design = design_cross_formation(n.sigma_process, n.sigma_measurement, n.sigma_hessian, bounds, config.equal_sides)
    steady = design.steady_state
    summary = {
        "formation": "cross",
        "a": design.x[0],
        "b": design.x[1],
        "trace": design.fun,
        "P_diag": np.diag(steady.posterior),
        "gain": steady.gain,
        "on_bound": {k: v is not None for k, v in design.on_bound.items()},
        "active_bounds": design.on_bound,
        "stationary_point": design.stationary_point,
        "message": design.message,
        "gradient": design.jac,
        "hessian_eigenvalues": design.hess_eigenvalues,
        "equal_sides": config.equal_sides,
        "bounds": {"a": bounds[0], "b": bounds[1]},
        "noise": n.model_dump(),
    }
    return summary, design


def _trace_grid(config: FormationFile) -> object:
    import xarray as xr

    from estimation.steady_state import cross_trace

    (a_min, a_max), (b_min, b_max) = _bounds(config)
    a = np.linspace(a_min, a_max, config.contour_resolution)
    b = np.linspace(b_min, b_max, config.contour_resolution)
    n = config.noise
    values = cross_trace(a[:, None], b[None, :], n.sigma_process, n.sigma_measurement, n.sigma_hessian)
    ds = xr.Dataset({"trace": (("a", "b"), values)}, coords={"a": a, "b": b})
    ds["trace"].attrs["long_name"] = "tr P_inf(+) of the cross formation (SPEC 2.4, eq. 30)"
    ds["a"].attrs["units"] = ds["b"].attrs["units"] = "length unit of the field"
    return ds


def _contour_figure(grid: object, design: object, config: FormationFile) -> object:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 5.2))
    a, b, trace = grid["a"].values, grid["b"].values, grid["trace"].values  # type: ignore[index]
    levels = np.quantile(trace, np.linspace(0, 1, 25))
    cs = ax.contourf(a, b, trace.T, levels=np.unique(levels), cmap="viridis")
    ax.contour(a, b, trace.T, levels=np.unique(levels), colors="k", linewidths=0.3)
    fig.colorbar(cs, ax=ax, label=r"tr $P_\infty(+)$ (field unit$^2$)")
    if config.equal_sides:
        ax.plot(a, a, "w--", lw=1, label="a = b constraint")
    x = design.x  # type: ignore[attr-defined]
    ax.plot(x[0], x[1], "r*", ms=14, mec="w", label=f"optimum ({design.stationary_point})")  # type: ignore[attr-defined]
    ax.set_xlabel("a: half-distance of platforms 1-2 (length unit)")
    ax.set_ylabel("b: half-distance of platforms 3-4 (length unit)")
    n = config.noise
    ax.set_title(
        f"Cross formation steady state, σ1={n.sigma_process:g}, σ2={n.sigma_measurement:g}, σ3={n.sigma_hessian:g}\n"
        f"a={x[0]:.4g}, b={x[1]:.4g}, tr P={design.fun:.4g}",  # type: ignore[attr-defined]
        fontsize=10,
    )
    ax.legend(loc="upper right", fontsize=8)
    return fig
