"""Hostile input to gridded fields and to ``mobisense steady-state``: one line, exit status 2, nothing written.

Gridded fields (``field: {kind: gridded, path: …}``): files that are not netCDF-4, grids declared far larger
than the memory (refused from the declared sizes, before anything is read), parameters of the wrong type, and
a relative ``path`` resolved against the scenario's folder. Steady state of ``formation: custom``: too many
positions (refused before anything of size N² is allocated) and nearly collinear ones (the DARE on the 3 × 3
information form, a clear error if it still fails).
"""

from __future__ import annotations

import json
from pathlib import Path

import h5netcdf
import numpy as np
import pytest
import yaml

from mobisense import cli
from mobisense.core.budget import check_budget
from mobisense.core.config import ConfigError, StrictModel, parse_config
from mobisense.core.files import write_netcdf
from mobisense.estimation.cooperative.design_study import FormationFile
from mobisense.estimation.cooperative.noise_config import CooperativeNoise
from mobisense.estimation.cooperative.steady_state import steady_state
from mobisense.estimation.fields.gridded import GriddedField
from mobisense.estimation.fields.library import FieldSpec, QuadraticField, grid_dataset

ROOT = Path(__file__).resolve().parents[2]
NOISE = {"sigma_process": 0.1, "sigma_measurement": 0.5, "sigma_hessian": 1.0}


class _Holder(StrictModel):
    field: FieldSpec


def _grid(path: Path) -> Path:
    """A small valid gridded field (a quadratic on [-10, 10] × [-7, 7])."""
    quad = QuadraticField([[1.0, 0.0], [0.0, 0.5]], [0.1, 0.0], 4.0)
    write_netcdf(path, grid_dataset(quad, np.linspace(-10, 10, 41), np.linspace(-7, 7, 29)))
    return path


def _declared(path: Path, nx: int, ny: int) -> Path:
    """A small netCDF-4 file declaring ``z(y, x)`` of ny × nx with no chunk written (and coordinates x, y)."""
    with h5netcdf.File(path, "w") as f:
        f.dimensions = {"x": nx, "y": ny}
        for name, n in (("x", nx), ("y", ny)):
            f.create_variable(name, (name,), float, chunks=(min(n, 1_000_000),))
        f.create_variable("z", ("y", "x"), float, chunks=(min(ny, 1000), min(nx, 1000)))
    return path


def _replay(folder: Path, field: dict, name: str = "replay.yaml") -> Path:
    """A field replay (``problems/replay_two_charges.yaml``, 2 s) on ``field``, written in ``folder``."""
    data = yaml.safe_load((ROOT / "problems" / "replay_two_charges.yaml").read_text())
    data.update(field=field, duration=2.0)
    path = folder / name
    folder.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(data))
    return path


def _refused(capsys: pytest.CaptureFixture[str], argv: list[str], out: Path | None, *needles: str) -> str:
    """Run the CLI: exit 2, one line naming everything in ``needles``, no traceback, ``out`` not created."""
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err
    if out is not None:
        assert not out.exists()
    return err


# ------------------------------------------------------------------------------------------- gridded


@pytest.mark.parametrize("content", [b"hello\n", bytes(np.random.default_rng(3).integers(0, 256, 5000, np.uint8))])
def test_gridded_path_that_is_not_netcdf_is_exit_2(tmp_path: Path, capsys, content: bytes) -> None:
    (tmp_path / "junk.nc").write_bytes(content)
    scenario = _replay(tmp_path, {"kind": "gridded", "path": str(tmp_path / "junk.nc")})
    out = tmp_path / "out"
    err = _refused(capsys, ["replay", str(scenario), "--out", str(out), "--no-plot", "--quiet"], out,
                   "field.path:", "junk.nc", "netCDF-4")  # fmt: skip
    assert "internal error" not in err


def test_gridded_huge_declared_grid_is_refused_before_reading(tmp_path: Path, capsys) -> None:
    bomb = _declared(tmp_path / "bomb.nc", 100_000, 100_000)  # 80 GB declared, a few MB on disk
    scenario = _replay(tmp_path, {"kind": "gridded", "path": str(bomb)})
    out = tmp_path / "out"
    _refused(capsys, ["replay", str(scenario), "--out", str(out), "--no-plot", "--quiet"], out,
             "field.path:", "bomb.nc", "100,000 × 100,000", "25,000,000")  # fmt: skip
    # a single huge dimension: xarray would read its coordinate (8 GB) while opening the file
    wide = _declared(tmp_path / "wide.nc", 1_000_000_000, 4)
    with pytest.raises(ConfigError, match=r"field\.path: dimension 'x' of .*wide\.nc declares 1,000,000,000 values"):
        parse_config({"field": {"kind": "gridded", "path": str(wide)}}, _Holder, "f.yaml")


def test_gridded_grid_beyond_the_memory_budget_is_refused(tmp_path: Path, monkeypatch) -> None:
    import mobisense.core.budget as budget

    grid = _declared(tmp_path / "grid.nc", 3000, 3000)  # 9e6 points: below the cap, ~730 MiB with the process
    monkeypatch.setattr(budget, "default_memory_limit", lambda: 512 * 2**20)
    with pytest.raises(ConfigError, match=r"f\.yaml: field\.path: variable 'z' of .*grid\.nc .*needs about .* memory"):
        parse_config({"field": {"kind": "gridded", "path": str(grid)}}, _Holder, "f.yaml")


def test_gridded_parameter_types_are_reported_at_their_key(tmp_path: Path, capsys) -> None:
    grid = _grid(tmp_path / "ok.nc")
    scenario = _replay(tmp_path, {"kind": "gridded", "path": str(grid), "degree": "3"})
    _refused(capsys, ["validate", str(scenario)], None, "field.degree: expected 3 or 5, got '3' (a string)")
    cases = {
        "path": (5, "field.path: expected the name of a netCDF file (a string), got 5 (an integer)"),
        "select": ("abc", "field.select: expected a mapping of dimension names to integer indices"),
        "variable": ("nope", "field.variable: 'nope' not in"),
    }
    for key, (value, message) in cases.items():
        field = {"kind": "gridded", "path": str(grid), key: value}
        with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
            parse_config({"field": field}, _Holder, "f.yaml")
    with pytest.raises(ConfigError, match=r"field\.select\.time: not a dimension of variable 'z'"):
        parse_config({"field": {"kind": "gridded", "path": str(grid), "select": {"time": 0}}}, _Holder, "f.yaml")


def test_gridded_relative_path_is_relative_to_the_scenario_folder(tmp_path: Path, monkeypatch) -> None:
    folder = tmp_path / "scenarios"
    folder.mkdir()
    grid = _grid(folder / "grid.nc")
    scenario = _replay(folder, {"kind": "gridded", "path": "grid.nc"})
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)  # grid.nc is not in the working directory
    data = {"field": {"kind": "gridded", "path": "grid.nc"}}
    field = _Holder.model_validate(data, context={"source": str(scenario)}).field.build()
    assert isinstance(field, GriddedField) and field.path.resolve() == grid.resolve()
    # absolute paths are kept; without a source file, relative paths stay relative to the working directory
    absolute = _Holder.model_validate({"field": {"kind": "gridded", "path": str(grid)}}, context={"source": "x"})
    assert absolute.field.build().path == grid
    with pytest.raises(ConfigError, match=r"field\.path: file not found: grid\.nc"):
        parse_config(data, _Holder, "<dict>")


def test_cli_resolves_a_gridded_path_against_the_scenario_folder(tmp_path: Path, monkeypatch, capsys) -> None:
    folder = tmp_path / "scenarios"
    folder.mkdir()
    _grid(folder / "grid.nc")
    scenario = _replay(folder, {"kind": "gridded", "path": "grid.nc"})
    monkeypatch.chdir(tmp_path)
    assert cli.main(["validate", str(scenario.relative_to(tmp_path))]) == 0, capsys.readouterr().err


def test_a_replay_off_the_gridded_data_says_so(tmp_path: Path, capsys) -> None:
    # the spline extrapolates outside its grid: a run whose platforms leave the data is warned about, not trusted
    folder = tmp_path / "scenarios"
    folder.mkdir()
    _grid(folder / "grid.nc")
    inside = _replay(folder, {"kind": "gridded", "path": "grid.nc"}, "inside.yaml")
    assert cli.main(["replay", str(inside), "--out", str(tmp_path / "in"), "--no-plot"]) == 0
    summary = json.loads((tmp_path / "in" / "summary.json").read_text())
    assert summary["outside_field_data"] == 0.0 and "warning" not in summary
    capsys.readouterr()
    data = yaml.safe_load(inside.read_text())
    data["platforms"]["initial"]["center"] = [30.0, 0.0]  # 20 L east of the grid's x ≤ 10
    away = folder / "away.yaml"
    away.write_text(yaml.safe_dump(data))
    assert cli.main(["replay", str(away), "--out", str(tmp_path / "away"), "--no-plot"]) == 0
    summary = json.loads((tmp_path / "away" / "summary.json").read_text())
    assert summary["outside_field_data"] > 0.9
    assert summary["warning"].startswith("the platforms left the gridded field's data [-10, 10] × [-7, 7]")
    assert "mobisense: warning: the platforms left the gridded field's data" in capsys.readouterr().err


# ------------------------------------------------------------------------------------------- steady state


def _formation(path: Path, positions: list) -> Path:
    path.write_text(yaml.safe_dump({"formation": "custom", "noise": NOISE, "positions": positions},
                                   default_flow_style=True))  # fmt: skip
    return path


def test_steady_state_too_many_positions_is_exit_2_before_allocating(tmp_path: Path, capsys) -> None:
    path = _formation(tmp_path / "many.yaml", [[i % 110, i // 110] for i in range(12_000)])
    out = tmp_path / "out"
    _refused(capsys, ["steady-state", str(path), "--out", str(out)], out,
             "many.yaml: positions: expected at most 5000 platforms", "got 12000")  # fmt: skip
    with pytest.raises(ValueError, match=r"positions: expected 3 … 5000 platforms"):
        steady_state(np.zeros((5001, 2)), CooperativeNoise.from_sigmas(0.1, 0.5, 1.0))


def test_steady_state_memory_is_estimated_from_the_number_of_positions() -> None:
    from mobisense.estimation.cooperative.design_study import formation_estimates
    from mobisense.estimation.cooperative.steady_state import MAX_POSITIONS

    rng = np.random.default_rng(0)
    config = FormationFile(formation="custom", noise=NOISE, positions=rng.normal(size=(MAX_POSITIONS, 2)).tolist())
    (estimate,) = formation_estimates(config)
    assert estimate.bytes >= 3 * 8.0 * MAX_POSITIONS**2 and "positions" in estimate.what
    with pytest.raises(ConfigError, match=r"f\.yaml: too large: the steady state of 5000 platforms \(positions"):
        check_budget(formation_estimates(config), limit=512 * 2**20, source="f.yaml")
    assert formation_estimates(FormationFile(noise=NOISE, bounds={"a": [0.2, 3.0], "b": [0.2, 3.0]})) == []


def test_steady_state_nearly_collinear_positions(tmp_path: Path, capsys) -> None:
    positions = [[i, (i % 7) * 0.01] for i in range(250)]
    path = _formation(tmp_path / "thin.yaml", positions)
    out = tmp_path / "out"
    assert cli.main(["steady-state", str(path), "--out", str(out)]) == 0, capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    noise = CooperativeNoise.from_sigmas(0.1, 0.5, 1.0)
    result = steady_state(np.array(positions, float), noise)
    assert summary["trace"] == pytest.approx(result.trace, rel=1e-12) and np.isfinite(result.trace)
    # a fixed point of one filter step (A = I): P(+) = ((P(+) + M)⁻¹ + C'(DUD' + R)⁻¹C)⁻¹
    from mobisense.estimation.cooperative.information_model import taylor_matrices

    C, D = taylor_matrices(result.positions)
    J = C.T @ np.linalg.solve(noise.total_measurement_covariance(D), C)
    step = np.linalg.inv(np.linalg.inv(result.posterior + noise.process) + J)
    scale = np.sqrt(np.outer(np.diag(result.posterior), np.diag(result.posterior)))  # as correlations: cond ~ 1e6
    assert np.abs((step - result.posterior) / scale).max() < 1e-6
    np.testing.assert_allclose(result.prior, result.posterior + noise.process, rtol=1e-12, atol=1e-15)


def test_steady_state_riccati_failure_is_one_line_exit_1(tmp_path: Path, capsys, monkeypatch) -> None:
    import control

    def failing(*args, **kwargs):
        raise control.ControlArgument("R must be a symmetric matrix")

    monkeypatch.setattr(control, "dare", failing)
    path = _formation(tmp_path / "pentagon.yaml", [[1, 0], [0.31, 0.95], [-0.81, 0.59], [-0.81, -0.59], [0.31, -0.95]])
    assert cli.main(["steady-state", str(path), "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and "internal error" not in err, err
    assert "pentagon.yaml" in err and "Riccati equation has no stabilising solution" in err
