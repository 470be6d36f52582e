"""The xarray-free netCDF writer writes the file xarray writes: same Dataset read back, same HDF5 layout.

Each case writes one :class:`DatasetContent` twice — through xarray (``write_netcdf(path,
content.to_xarray())``, the writer every other file uses) and through h5netcdf alone
(``write_netcdf(path, content)``) — and compares the two files read back with ``xarray.open_dataset``
(``assert_identical``: variables, dimensions, coordinates, dtypes, every attribute) and, below xarray, every
HDF5 dataset's shape, dtype, fill value, chunking and attributes (except the object references of the
dimension scales, which differ by address only, and ``_NCProperties``, which names the library that wrote the
file: h5netcdf, or mobisense's h5py writer :mod:`mobisense.core.netcdf4_layout`), and netCDF-C (netCDF4) reads
both files as the same variables, dimensions, values and attributes. ``history`` holds the clock time, so it is
fixed for the comparison.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import xarray as xr
import yaml

from mobisense.core import netcdf
from mobisense.core.files import write_netcdf
from mobisense.core.netcdf import open_dataset
from mobisense.core.netcdf_writer import DatasetContent, write_content

REFERENCES = ("DIMENSION_LIST", "REFERENCE_LIST")


def _layout(path: Path) -> dict[str, object]:
    """Every HDF5 object's shape, dtype, fill value and attributes (as text), the global attributes, and which
    library wrote the file (``provenance``: the key after ``version=2`` in ``_NCProperties``)."""
    out: dict[str, object] = {}
    with h5py.File(path) as f:
        out["/"] = {k: (repr(v), str(f.attrs.get_id(k).dtype)) for k, v in f.attrs.items() if k != "_NCProperties"}
        properties = f.attrs["_NCProperties"].decode("ascii").split(",")
        assert properties[0] == "version=2" and any(p.startswith("hdf5=") for p in properties), properties
        out["provenance"] = properties[1].split("=")[0]

        def visit(name: str, obj: h5py.Dataset) -> None:
            attrs = {k: (repr(v), str(obj.attrs.get_id(k).dtype)) for k, v in obj.attrs.items() if k not in REFERENCES}
            refs = {k: len(obj.attrs[k]) for k in REFERENCES if k in obj.attrs}
            out[name] = (obj.shape, str(obj.dtype), repr(obj.fillvalue), obj.chunks, attrs, refs)

        f.visititems(visit)
    return out


def _as_netcdf_c_reads_it(path: Path) -> dict[str, object]:
    """Dimensions, and each variable's dimensions, dtype, values and attributes, as netCDF-C reads the file."""
    import netCDF4

    with netCDF4.Dataset(path) as f:
        f.set_auto_mask(False)
        dims = {name: len(dim) for name, dim in f.dimensions.items()}
        variables = {
            name: (v.dimensions, str(v.dtype), v[...].tobytes(), {k: repr(v.getncattr(k)) for k in v.ncattrs()})
            for name, v in f.variables.items()
        }
        attrs = {k: repr(f.getncattr(k)) for k in f.ncattrs()}
    return {"dimensions": dims, "variables": variables, "attrs": attrs}


def assert_same_file(
    content: DatasetContent, folder: Path, monkeypatch: pytest.MonkeyPatch, fast: bool = True
) -> xr.Dataset:
    """Write ``content`` both ways; assert the files are the same; return the dataset read back.

    ``fast``: the content is of the kind the h5py writer covers (otherwise h5netcdf writes it)."""
    monkeypatch.setattr(netcdf, "_history", lambda: "2026-01-01T00:00:00Z: test (mobisense)")
    by_xarray, by_h5netcdf = folder / "xarray.nc", folder / "h5netcdf.nc"
    write_netcdf(by_xarray, content.to_xarray())
    write_netcdf(by_h5netcdf, content)
    with xr.open_dataset(by_xarray, engine="h5netcdf") as a, xr.open_dataset(by_h5netcdf, engine="h5netcdf") as b:
        xr.testing.assert_identical(a, b)
        for name in a.variables:
            assert a[name].dtype == b[name].dtype, name
            assert a[name].encoding.get("_FillValue", "none") is b[name].encoding.get("_FillValue", "none") or (
                np.isnan(a[name].encoding["_FillValue"]) and np.isnan(b[name].encoding["_FillValue"])
            ), name
        assert list(a.variables) == list(b.variables)
        loaded = b.load()
    expected, written = _layout(by_xarray), _layout(by_h5netcdf)
    assert expected.pop("provenance") == "h5netcdf"
    assert written.pop("provenance") == ("mobisense" if fast else "h5netcdf")
    assert expected == written
    assert _as_netcdf_c_reads_it(by_xarray) == _as_netcdf_c_reads_it(by_h5netcdf)
    return loaded


def _synthetic() -> DatasetContent:
    """Float64/float32/int data, integer and string index coordinates (non-ASCII labels), auxiliary coords."""
    rng = np.random.default_rng(3)
    content = DatasetContent(attrs={"title": "synthetic", "eps": 0.5, "count": 3, "note": "Σ ≥ 0", "v": [1.0, 2.0]})
    content.add_coord("time", ("time",), np.linspace(0.0, 1.0, 5), {"long_name": "time", "units": "s"})
    content.add_coord("sensor", ("sensor",), ["Σ1", "s-two"], {"long_name": "sensor name", "units": "1"})
    content.add_coord("xy", ("xy",), ["x", "y"], {})  # a label without long_name gets a generic one
    content.add_coord("cell", ("cell",), np.arange(3), {"long_name": "cell", "units": "1"})
    content.add_coord("cell_x", ("cell",), [0.5, 1.5, 2.5], {"long_name": "x of the cell", "units": "m"})
    content.add_coord("time_other", ("time_other",), [0.0, 2.0], {"long_name": "another time", "units": "s"})
    content.add_coord("orphan", ("orphan_dim",), [1.0, 2.0], {"long_name": "on no variable", "units": "1"})
    content.add_variable("p", ("time", "sensor", "xy"), rng.normal(size=(5, 2, 2)), {"long_name": "p", "units": "m"})
    content.add_variable("f32", ("time", "cell"), rng.normal(size=(5, 3)).astype(np.float32), {"units": "1"})
    content.add_variable("count_per_cell", ("cell",), np.array([1, 2, 3]), {"long_name": "n", "units": "1"})
    content.add_variable("free", ("free_dim",), np.array([np.nan, 1.0]), {"long_name": "no coordinate", "units": "1"})
    content.add_variable("scalar", (), np.float64(2.5), {"long_name": "a scalar", "units": "1"})
    return content


def test_synthetic_content_is_written_as_xarray_writes_it(tmp_path, monkeypatch):
    ds = assert_same_file(_synthetic(), tmp_path, monkeypatch)
    assert ds.attrs["Conventions"] == "CF-1.10" and ds.attrs["title"] == "synthetic"
    assert "orphan" in ds.coords and "coordinates" not in ds.attrs  # read from the global "coordinates"
    with h5py.File(tmp_path / "h5netcdf.nc") as f:
        assert f.attrs["coordinates"] == "orphan"  # as xarray, a coordinate of no variable is named globally
    assert ds["p"].encoding["coordinates"] == "sensor_label xy_label"
    assert list(ds["sensor_label"].values) == ["Σ1", "s-two"]
    assert ds["xy_label"].attrs["long_name"] == "name of each xy"
    with pytest.raises(KeyError):
        ds["time"].encoding["_FillValue"]  # no fill value on coordinates (CF §2.5.1)


def test_labels_read_back_as_index_coordinates(tmp_path):
    write_netcdf(tmp_path / "a.nc", _synthetic())
    ds = open_dataset(tmp_path / "a.nc")
    assert list(ds["sensor"].values) == ["Σ1", "s-two"]
    np.testing.assert_array_equal(ds["p"].sel(sensor="Σ1").values, _synthetic().data_vars["p"][1][:, 0])


def test_what_the_writer_does_not_support_is_a_clear_error(tmp_path):
    flags = DatasetContent()
    flags.add_variable("flags", ("k",), [True, False], {})
    with pytest.raises(TypeError, match="data variable 'flags': values of type bool"):
        write_content(tmp_path / "a.nc", flags)
    sizes = DatasetContent()
    sizes.add_variable("a", ("k",), [1.0, 2.0], {})
    sizes.add_variable("b", ("k",), [1.0, 2.0, 3.0], {})
    with pytest.raises(ValueError, match="dimension 'k': sizes 2 and 3 conflict"):
        write_content(tmp_path / "b.nc", sizes)
    shape = DatasetContent()
    shape.add_variable("a", ("k",), np.zeros((2, 2)), {})
    with pytest.raises(ValueError, match="2-dimensional values for dimensions"):
        write_content(tmp_path / "c.nc", shape)


def test_writing_a_content_imports_neither_xarray_nor_pandas(tmp_path):
    code = (
        "import sys, numpy as np\n"
        "from mobisense.core.files import write_netcdf\n"
        "from mobisense.core.netcdf_writer import DatasetContent\n"
        "c = DatasetContent(attrs={'title': 't'})\n"
        "c.add_coord('sensor', ('sensor',), ['a'], {'long_name': 'name'})\n"
        "c.add_variable('p', ('sensor',), [1.0], {'long_name': 'p', 'units': 'm'})\n"
        f"write_netcdf({str(tmp_path / 'a.nc')!r}, c)\n"
        "print(sorted(m for m in ('xarray', 'pandas', 'dask', 'distributed', 'pyarrow') if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


@pytest.mark.slow
@pytest.mark.parametrize("method", ["direct", "indirect", "both"])
def test_a_solution_file_is_the_file_xarray_writes(method, tmp_path, monkeypatch):
    import short_runs

    solution = short_runs.small_solution(method)
    content = solution.to_content()
    ds = assert_same_file(content, tmp_path, monkeypatch)
    assert ("indirect_p" in ds) == (method == "both")
    # problem_yaml goes through libyaml's emitter (speed): the text of PyYAML's own safe_dump, character for character
    expected = yaml.safe_dump(solution.problem.normalised(), sort_keys=False, allow_unicode=True)
    assert content.attrs["problem_yaml"] == expected


@pytest.mark.slow
@pytest.mark.parametrize("full_sigma", [True, False])
def test_a_field_solution_file_is_the_file_xarray_writes(full_sigma, tmp_path, monkeypatch):
    import short_runs

    solution = short_runs.field_solution(shooting={"full_sigma": full_sigma})
    ds = assert_same_file(solution.to_content(), tmp_path, monkeypatch)
    assert ds["sigma_diag"].encoding["coordinates"] == "state_x state_y"
    assert ("Sigma" in ds) == full_sigma


def test_text_variables_and_a_stacked_sweep_file_are_written_as_xarray_writes_them(tmp_path, monkeypatch):
    # a sweep's part file: per-task problem hashes and JSON attributes (text along ``task``), stacked solutions
    from mobisense.ocp.task_files import stack_tasks

    one = _synthetic()
    other = _synthetic()
    other.attrs = {**other.attrs, "title": "another — ü"}
    stacked = stack_tasks([one, other], [4, 9], ["a1b2", "c3d4e5"])
    assert stacked.data_vars["task_attrs"][1].dtype.kind == "U"
    ds = assert_same_file(stacked, tmp_path, monkeypatch)
    assert list(ds["task_id"].values) == ["a1b2", "c3d4e5"]
    assert json.loads(str(ds["task_attrs"].values[1]))["title"] == "another — ü"


def test_a_size_0_dimension_is_left_to_h5netcdf_and_written_as_xarray_writes_it(tmp_path, monkeypatch):
    # h5netcdf makes a size-0 dimension unlimited (chunked, resizable); the h5py writer does not imitate that
    from mobisense.core import netcdf4_layout

    content = _synthetic()
    content.add_variable("no_zones", ("zone",), np.zeros(0), {"long_name": "no zone", "units": "m"})
    calls = []
    monkeypatch.setattr(netcdf4_layout, "write_netcdf4", lambda *a: calls.append(a))
    ds = assert_same_file(content, tmp_path, monkeypatch, fast=False)
    assert calls == [] and ds.sizes["zone"] == 0
