"""A simulation result saved into a folder that holds an earlier one: no earlier figure left beside it."""

from __future__ import annotations

import json
from pathlib import Path

import xarray as xr

from mobisense.formation.simulation_result import SimulationResult


class _Drawn(SimulationResult):
    """A result whose figures are the names given (each a small file)."""

    def __init__(self, figures: list[str]) -> None:
        super().__init__(xr.Dataset({"x": ("time", [0.0, 1.0])}), {"kind": "test"})
        self.figures = figures

    def plot(self, folder: str | Path) -> list[Path]:
        for name in self.figures:
            (Path(folder) / name).write_bytes(b"png")
        return [Path(folder) / name for name in self.figures]


def test_a_new_result_removes_the_earlier_results_figures_and_nothing_else(tmp_path):
    _Drawn(["paths.png", "errors.png"]).save(tmp_path)
    (tmp_path / "notes.txt").write_text("the user's own file")
    _Drawn(["paths.png"]).save(tmp_path, figures=False)  # a re-run with --no-plot
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt", "result.nc", "summary.json"]
    _Drawn(["errors.png"]).save(tmp_path)
    assert json.loads((tmp_path / "summary.json").read_text())["files"] == ["result.nc", "summary.json", "errors.png"]
    # an earlier summary naming a path outside the folder, or not a figure, is not followed
    (tmp_path / "summary.json").write_text(json.dumps({"files": ["../outside.png", "notes.txt", 3]}))
    (tmp_path.parent / "outside.png").write_bytes(b"png")
    _Drawn([]).save(tmp_path)
    assert (tmp_path.parent / "outside.png").exists() and (tmp_path / "notes.txt").exists()
