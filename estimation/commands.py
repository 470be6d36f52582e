"""The estimation command: ``mobisense steady-state FORMATION.yaml --out DIR``.

Writes ``summary.json`` (``a, b, trace, P_diag, gain, on_bound, stationary_point`` …), ``trace_grid.nc``
(tr P∞ over the (a, b) box) and ``trace_contour.png`` (see
:mod:`mobisense.estimation.cooperative.design_study`). The file is validated completely before anything
is written; errors exit with status 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..core.output import output_path

__all__ = ["SteadyStateCommand", "check_formation"]


class SteadyStateCommand:
    """Design the steady-state formation shape (cross formation, bounded) of a formation file."""

    @staticmethod
    def add_arguments(parser: argparse.ArgumentParser) -> None:
        """Add the ``steady-state`` arguments."""
        from ..core.budget import add_budget_argument

        parser.add_argument("formation", type=Path, help="formation YAML file, or a shipped example's name")
        parser.add_argument("--out", type=output_path, default=None, help="output folder (default out/<file name>)")
        parser.add_argument("--no-plot", action="store_true", help="skip the contour plot")
        add_budget_argument(parser)

    @staticmethod
    def run(args: argparse.Namespace) -> int:
        """Validate, design, write ``summary.json``, ``trace_grid.nc`` and ``trace_contour.png``."""
        import math

        from ..core.budget import Estimate, check_budget
        from ..core.errors import ComputationError, numerical_failures
        from ..core.examples import resolve_input
        from ..core.kinds import load_as
        from ..core.output import OutputFolder, default_output_folder, input_files
        from .cooperative.design_study import design_formation, formation_estimates

        args.formation = resolve_input(args.formation)
        source = str(args.formation)
        config = load_as(args.formation, "formation")  # ConfigError -> exit 2, nothing written
        grid = config.contour_resolution**2
        estimates = [Estimate("the tr P grid", 8.0 * 8 * grid, "a lower contour_resolution", 2e-6 * grid)]
        check_budget(estimates + formation_estimates(config), args.max_memory, source, args.max_time)
        folder = OutputFolder.check(args.out if args.out is not None else default_output_folder(args.formation),
                                    inputs=input_files(args.formation, config))
        with folder.lock():
            out = folder.path
            with numerical_failures(f"designing {source}"):
                study = design_formation(config)
            s = study.summary
            values = [s["trace"]] + ([s["a"], s["b"]] if s["formation"] == "cross" else [])
            if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values):
                raise ComputationError(
                    f"designing {source}: the steady state is not finite (tr P = {s['trace']}): the noise levels "
                    "or bounds make the Riccati equation degenerate"
                )
            folder.remove_previous(["trace_contour.png"])  # an earlier run's figure is not left beside new results
            study.save(out, figures=not args.no_plot)
        if s["formation"] == "cross":
            print(f"{s['stationary_point']}: a = {s['a']:.6g}, b = {s['b']:.6g}, tr P = {s['trace']:.6g} -> {out}")
        return 0


def check_formation(data: dict, path: Path, kind: str = "formation") -> str:
    """Validate a formation-design file's data; one line saying what it is (``ConfigError`` if invalid)."""
    from ..core.config import parse_config
    from .cooperative.design_study import FormationFile

    config = parse_config(data, FormationFile, source=str(path))
    n = config.noise
    noise = f"σ process {n.sigma_process:g}, σ measurement {n.sigma_measurement:g}, σ Hessian {n.sigma_hessian:g}"
    if config.formation == "custom":
        return f"steady-state formation design: custom shape of {len(config.positions or [])} platforms, {noise}"
    b = config.bounds
    box = "" if b is None else f"a in [{b.a[0]:g}, {b.a[1]:g}], b in [{b.b[0]:g}, {b.b[1]:g}]"
    sides = ", a = b imposed" if config.equal_sides else ""
    return f"steady-state formation design: cross formation, {box}{sides}, {noise}"
