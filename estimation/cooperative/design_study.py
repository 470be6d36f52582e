"""The formation-design study behind ``mobisense steady-state``: the file, the design, its outputs.

Reads a formation file (:class:`FormationFile`), e.g.::

    formation: cross
    noise: {sigma_process: 0.1, sigma_measurement: 0.5, sigma_hessian: 1.0}
    bounds: {a: [0.2, 3.0], b: [0.2, 3.0]}
    equal_sides: false

and designs the steady-state shape (:func:`design_formation`): the bounded optimum of the cross's
(a, b) with its classification, or, with ``formation: custom`` and ``positions: [[x, y], …]`` (at most
:data:`~mobisense.estimation.cooperative.steady_state.MAX_POSITIONS` = 5000 platforms: the steady state of N
platforms factorises an N × N covariance, memory N², time N³), the steady state of that shape by the DARE (no
optimisation). The :class:`DesignStudy` it returns writes
``summary.json`` (``a, b, trace, P_diag, gain, on_bound, stationary_point`` …), ``trace_grid.nc``
(tr P∞ over the (a, b) box) and ``trace_contour.png``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator

from ...core.budget import Estimate
from ...core.config import InvalidValue, PositiveFloat, StrictModel, Vector2
from ...core.errors import brief
from .noise_config import NoiseConfig
from .steady_state import MAX_POSITIONS

__all__ = ["FormationFile", "ShapeBounds", "DesignStudy", "design_formation", "formation_estimates"]


class ShapeBounds(StrictModel):
    """Bounds ``[min, max]`` (L) of the half-distances a and b (docs/theory/steady_state.md §3, condition Cd4)."""

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

    kind: Literal["formation"] | None = Field(None, description="file kind (optional with 'bounds' or 'positions')")
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
            if len(self.positions) > MAX_POSITIONS:
                raise InvalidValue(
                    "positions", f"expected at most {MAX_POSITIONS} platforms (the steady state of N platforms "
                    f"needs N × N matrices and N³ operations), got {len(self.positions)}"
                )  # fmt: skip
            from .steady_state import MIN_ASPECT

            arr = np.asarray(self.positions, dtype=float)
            spread = np.linalg.svd(arr - arr.mean(axis=0), compute_uv=False) if len(arr) >= 2 else np.zeros(2)
            if len(arr) < 3 or not spread[1] >= MIN_ASPECT * spread[0] or spread[0] == 0:
                raise InvalidValue(
                    "positions", f"expected >= 3 platforms not all on or near one line (width at least {MIN_ASPECT:g} "
                    f"of the length), got {brief(self.positions)}"
                )  # fmt: skip
        if self.formation == "cross" and self.bounds is not None:
            from .steady_state import cross_information

            n = self.noise
            corners = [(a, b) for a in self.bounds.a for b in self.bounds.b]
            try:
                values = [cross_information(a, b, n.sigma_measurement, n.sigma_hessian) for a, b in corners]
            except OverflowError:
                values = [(float("inf"),) * 3]
            if not all(np.isfinite(c) and 0 < c < 1e300 for triple in values for c in triple):
                raise InvalidValue(
                    "bounds", "the information C'(DUD' + R)⁻¹C of the cross overflows or vanishes at these bounds "
                    "and noise levels (eq. steady_state.3: a⁴ σ3², a²/σ2²); choose bounds nearer the noise scales"
                )  # fmt: skip
        if not 11 <= self.contour_resolution <= 1001:
            raise InvalidValue("contour_resolution", f"expected 11 … 1001, got {self.contour_resolution}")
        return self


def formation_estimates(config: FormationFile) -> list[Estimate]:
    """Memory and time of designing ``config`` beyond the (a, b) grid, for :func:`~mobisense.core.budget.check_budget`.

    A custom shape of N platforms factorises the N × N covariance ``D U D' + R`` (a few N × N arrays, N³/3
    flops); the cross's closed form needs nothing of note. Computed from the validated sizes alone.
    """
    from .steady_state import steady_state_bytes, steady_state_seconds

    if config.formation != "custom" or config.positions is None:
        return []
    n = len(config.positions)
    what = f"the steady state of {n} platforms (positions: {n} × {n} covariance matrices)"
    return [Estimate(what, steady_state_bytes(n), "use fewer positions", steady_state_seconds(n))]


class DesignStudy:
    """The outcome of a formation design: ``summary`` (plain JSON), the tr P∞ grid and the contour figure.

    For ``formation: custom`` only ``summary`` is computed (the shape is given, nothing is designed).
    """

    def __init__(self, config: FormationFile, summary: dict[str, Any], design: Any = None, grid: Any = None):
        self.config = config
        self.summary = summary
        self.design = design
        self.grid = grid

    def to_xarray(self) -> Any:
        """Tr P∞(+) over the (a, b) box (``xarray.Dataset``; ``None`` for a custom shape)."""
        return self.grid

    def plot(self, folder: str | Path) -> list[Path]:
        """``trace_contour.png``: tr P∞ over (a, b) with the optimum (nothing for a custom shape)."""
        if self.grid is None:
            return []
        from ...core.files import write_figure

        path = Path(folder) / "trace_contour.png"
        write_figure(path, lambda: _contour_figure(self.grid, self.design, self.config))
        return [path]

    def save(self, folder: str | Path, figures: bool = True) -> list[Path]:
        """Write ``summary.json``, ``trace_grid.nc`` and (unless ``figures=False``) the contour plot."""
        from ...core.files import write_json, write_netcdf

        folder = Path(folder)
        write_json(folder / "summary.json", self.summary)
        written = [folder / "summary.json"]
        if self.grid is not None:
            write_netcdf(folder / "trace_grid.nc", self.grid)
            written.append(folder / "trace_grid.nc")
            if figures:
                written += self.plot(folder)
        return written

    def __repr__(self) -> str:
        s = self.summary
        if s["formation"] == "custom":
            return f"DesignStudy(custom shape of {len(s['positions'])} platforms, tr P = {s['trace']:.6g})"
        return f"DesignStudy({s['stationary_point']}: a = {s['a']:.6g}, b = {s['b']:.6g}, tr P = {s['trace']:.6g})"


def design_formation(config: FormationFile | str | Path) -> DesignStudy:
    """Design the steady-state formation described by ``config``.

    ``config`` is a :class:`FormationFile`, its YAML path, or a shipped example's name (``"formation_cross"``).
    """
    if not isinstance(config, FormationFile):
        from ...core.examples import resolve_input
        from ...core.kinds import load_as

        config = load_as(resolve_input(config), "formation")
    if config.formation == "custom":
        return DesignStudy(config, _custom_summary(config))
    summary, design = _cross_summary(config)
    return DesignStudy(config, summary, design, _trace_grid(config))


def _custom_summary(config: FormationFile) -> dict:
    from .steady_state import steady_state

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
    from .formation_design import design_cross_formation

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

    from .steady_state import cross_trace

    (a_min, a_max), (b_min, b_max) = _bounds(config)
    a = np.linspace(a_min, a_max, config.contour_resolution)
    b = np.linspace(b_min, b_max, config.contour_resolution)
    n = config.noise
    values = cross_trace(a[:, None], b[None, :], n.sigma_process, n.sigma_measurement, n.sigma_hessian)
    ds = xr.Dataset(
        {"trace": (("a", "b"), values, {"long_name": "trace of the steady-state error covariance P_inf(+) "
                                                     "of the cross formation", "units": "1"})},
        coords={"a": ("a", a, {"long_name": "half distance of platforms 1 and 2", "units": "1"}),
                "b": ("b", b, {"long_name": "half distance of platforms 3 and 4", "units": "1"})},
        attrs={"title": "mobisense: steady-state covariance of the cross formation over its shape (a, b)",
               "comment": "docs/theory/steady_state.md, eq. steady_state.5; lengths in the units of the noise "
                          "model (the formation file declares none), the trace in field units squared"},
    )  # fmt: skip
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
