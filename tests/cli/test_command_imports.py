"""What each command imports: the whole-command times of benchmarks/bench_ocp_speed.py rest on these.

``solve`` writes ``solution.nc`` through h5py alone (:mod:`mobisense.core.netcdf4_layout`), so it imports
none of xarray, pandas, dask, distributed, pyarrow (about a second of imports), nor h5netcdf; ``validate`` needs neither
scipy nor CasADi; ``--help`` not even numpy or pydantic. Each command runs in a fresh interpreter and the
top-level packages in ``sys.modules`` at its end are compared.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
HUSSEIN = str(ROOT / "problems" / "hussein2008.yaml")
DATA_STACK = {"xarray", "pandas", "dask", "distributed", "pyarrow"}


def imported_by(*argv: str) -> set[str]:
    """Top-level packages loaded by ``mobisense ARGV`` run in a fresh interpreter (its exit status must be 0)."""
    code = (
        "import json, sys\n"
        "from mobisense.cli import main\n"
        f"status = main({list(argv)!r})\n"
        "print('\\n' + json.dumps([status, sorted({m.split('.')[0] for m in sys.modules})]))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    status, modules = json.loads(out.stdout.strip().splitlines()[-1])
    assert status == 0, out.stderr
    return set(modules)


def test_help_imports_neither_numpy_nor_pydantic():
    modules = imported_by("--help")
    assert not modules & {"numpy", "pydantic", "yaml", "casadi", "scipy", *DATA_STACK}


def test_validate_imports_neither_scipy_nor_casadi():
    modules = imported_by("validate", HUSSEIN)
    assert "pydantic" in modules  # the check is real: it validated the file
    assert not modules & {"scipy", "casadi", "h5py", "matplotlib", "rich", *DATA_STACK}


@pytest.mark.slow
def test_solve_imports_no_xarray_pandas_dask(tmp_path):
    modules = imported_by("solve", HUSSEIN, "--no-plot", "--quiet", "--intervals", "20", "--out", str(tmp_path))
    assert {"casadi", "h5py"} <= modules  # it solved and wrote solution.nc
    assert not modules & {"h5netcdf", *DATA_STACK}
    assert (tmp_path / "solution.nc").is_file() and (tmp_path / "summary.json").is_file()


@pytest.mark.slow
def test_solve_with_figures_imports_no_xarray_pandas_dask(tmp_path):
    # the figures are drawn by worker processes (mobisense.ocp.figure_workers): the command imports no matplotlib
    modules = imported_by("solve", HUSSEIN, "--quiet", "--intervals", "20", "--plot", "paths", "--out", str(tmp_path))
    assert not modules & {"matplotlib", *DATA_STACK}
    assert (tmp_path / "paths.png").is_file() and not (tmp_path / "covariance.png").exists()


def test_a_figure_worker_imports_matplotlib_and_no_data_stack():
    code = (
        "import json, runpy, sys\n"
        "sys.argv = ['figure_workers']\n"
        "try:\n"
        "    runpy.run_module('mobisense.ocp.figure_workers', run_name='__main__')\n"
        "except SystemExit as end:\n"
        "    assert end.code == 0, end.code\n"
        "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], input="", capture_output=True, text=True, cwd=ROOT, check=True)
    lines = out.stdout.strip().splitlines()
    assert len(lines) == 1  # no job (the command ended without a solution): no answer, nothing drawn
    modules = set(json.loads(lines[0]))
    assert "matplotlib" in modules and not modules & DATA_STACK
