"""Every netCDF file the commands write is CF-1.10: units that UDUNITS-2 parses, long names, global attributes.

Units are parsed with ``cf_units`` (the UDUNITS-2 library itself, bundled in its wheel): a unit string
that UDUNITS cannot read is a failure, and so is a length that is not convertible to metres (the old
"L", "T", "F" parse — as litre, tesla and farad — so parsing alone would not catch them). Where the CF
checker (``cfchecker``, which needs the system's libudunits2) is installed, it must report no error and
no warning; it knows CF up to 1.8, so it checks a copy labelled CF-1.8 (CF-1.9 and 1.10 add nothing these
files use: no geometries, no quantization, no time bounds).
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import short_runs
import xarray as xr

from mobisense.core.netcdf import LABEL_SUFFIX, cf_problems, open_dataset, prepare

cf_units = pytest.importorskip("cf_units")

TABLES = Path(__file__).resolve().parent / "cf_tables"


def _files(folder: Path) -> dict[str, Path]:
    """Run every writer into ``folder``; return name -> netCDF file."""
    solution = short_runs.small_solution()
    solution.save(folder / "solve")
    out = {"solution.nc": folder / "solve" / "solution.nc"}
    short_runs.field_solution(shooting={"full_sigma": False}).save(folder / "field")
    out["field solution.nc"] = folder / "field" / "solution.nc"
    runs = {
        "plan replay": short_runs.plan_replay(folder, solution),
        "field replay": short_runs.field_replay(folder, duration=1.0),
        "leader-follower": short_runs.leader_follower(folder, duration=0.2),
        "distributed": short_runs.distributed(folder, duration=3.0),
    }
    for name, result in runs.items():
        result.save(folder / name, figures=False)
        out[f"{name} result.nc"] = folder / name / "result.nc"
    short_runs.steady_state(folder).save(folder / "steady", figures=False)
    out["trace_grid.nc"] = folder / "steady" / "trace_grid.nc"
    return out


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> dict[str, Path]:
    return _files(tmp_path_factory.mktemp("cf"))


@pytest.mark.slow
def test_every_file_has_parsable_units_long_names_and_cf_attributes(written):
    for name, path in written.items():
        with xr.open_dataset(path, engine="h5netcdf") as ds:
            assert cf_problems(ds, cf_units.Unit) == [], name
            assert ds.attrs["Conventions"] == "CF-1.10" and "mobisense" in ds.attrs["history"], name


@pytest.mark.slow
def test_units_have_the_right_dimensions(written):
    metre, second = cf_units.Unit("m"), cf_units.Unit("s")
    with xr.open_dataset(written["solution.nc"], engine="h5netcdf") as ds:
        assert cf_units.Unit(ds["p"].attrs["units"]).is_convertible(metre)
        assert cf_units.Unit(ds["v"].attrs["units"]) == cf_units.Unit("m/s")
        assert cf_units.Unit(ds["u"].attrs["units"]) == cf_units.Unit("m/s^2")
        assert cf_units.Unit(ds["time"].attrs["units"]).is_convertible(second)
        assert "nlp_w" not in ds.coords and "nlp_w" in ds.data_vars  # data, not an index
    with xr.open_dataset(written["field replay result.nc"], engine="h5netcdf") as ds:
        assert cf_units.Unit(ds["r"].attrs["units"]).is_convertible(metre)
        assert cf_units.Unit(ds["time"].attrs["units"]).is_convertible(second)


@pytest.mark.slow
def test_declared_units_reach_the_file(tmp_path):
    solution = short_runs.small_solution(units={"length": "km", "time": "h"})
    solution.save(tmp_path)
    with xr.open_dataset(tmp_path / "solution.nc", engine="h5netcdf") as ds:
        assert cf_units.Unit(ds["v"].attrs["units"]) == cf_units.Unit("km/h")
        assert cf_units.Unit(ds["lam_v"].attrs["units"]) == cf_units.Unit("h/km")  # ∂J/∂v with J dimensionless


@pytest.mark.slow
def test_files_read_back_with_their_labels(written):
    ds = open_dataset(written["solution.nc"])
    assert list(ds["sensor"].values) == ["s1"] and not any(str(c).endswith(LABEL_SUFFIX) for c in ds.coords)
    assert ds.sel(sensor="s1", xy="x")["p"].shape == ds["time"].shape


def test_coordinates_get_no_fill_value_and_strings_become_labels():
    a = (("t", "name"), np.zeros((2, 2)), {"long_name": "a", "units": "m"})
    ds = xr.Dataset({"a": a}, coords={"t": ("t", [0.0, 1.0], {"long_name": "time", "units": "s"}), "name": ["p", "q"]})
    prepared, encoding = prepare(ds)
    assert encoding["t"]["_FillValue"] is None and "name" not in prepared.coords
    assert list(prepared[f"name{LABEL_SUFFIX}"].values) == ["p", "q"]
    assert {"Conventions", "title", "history", "source"} <= set(prepared.attrs)


def test_cf_problems_finds_what_is_missing():
    ds = xr.Dataset({"a": ("t", [1.0, 2.0], {"units": "L"})}, coords={"t": [1.0, 0.5]})
    problems = cf_problems(ds, cf_units.Unit)
    assert "a: no long_name" in problems and "t: no units" in problems
    assert "t: coordinate variable not strictly monotonic" not in problems  # decreasing is monotonic
    assert any("Conventions" in p for p in problems)
    bad = xr.Dataset({"a": ("t", [1.0], {"units": "metres per fortnight!", "long_name": "a"})})
    assert any("do not parse" in p for p in cf_problems(bad, cf_units.Unit))


def _cfchecks() -> str | None:
    try:
        import cfchecker.cfchecks  # noqa: F401  (needs the system's libudunits2)
    except Exception:  # noqa: BLE001
        return None
    return shutil.which("cfchecks") or str(Path(sys.executable).parent / "cfchecks")


@pytest.mark.slow
def test_the_cf_checker_finds_no_error_or_warning(written, tmp_path):
    checker = _cfchecks()
    if checker is None:
        pytest.skip("cfchecker needs the UDUNITS-2 C library (apt-get install libudunits2-0)")
    import h5py

    tables = ["-s", str(TABLES / "standard_names.xml"), "-a", str(TABLES / "area_types.xml"),
              "-r", str(TABLES / "region_names.xml")]  # fmt: skip
    for name, path in written.items():
        copy = tmp_path / f"{name.replace(' ', '_')}.nc"
        shutil.copy(path, copy)
        with h5py.File(copy, "a") as f:
            f.attrs["Conventions"] = "CF-1.8"
        report = subprocess.run([checker, "-v", "1.8", *tables, str(copy)], capture_output=True, text=True)
        assert "ERRORS detected: 0" in report.stdout and "WARNINGS given: 0" in report.stdout, (name, report.stdout)


@pytest.mark.slow
def test_index_coordinates_name_the_costates_only_where_the_file_has_them(written, tmp_path):
    with xr.open_dataset(written["solution.nc"], engine="h5netcdf") as ds:  # direct: Σ and its costate Λ
        assert "Lam" in ds and ds["row"].attrs["long_name"] == "row index of Σ and Λ (process state)"
    short_runs.field_solution().save(tmp_path)  # shooting: Σ (n ≤ 25 keeps it whole), no costates
    with xr.open_dataset(tmp_path / "solution.nc", engine="h5netcdf") as ds:
        assert "Lam" not in ds and "Sigma" in ds
        assert ds["row"].attrs["long_name"] == "row index of Σ (process state)"
        assert ds["col"].attrs["long_name"] == "column index of Σ (process state)"
