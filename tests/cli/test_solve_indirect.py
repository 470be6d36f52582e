"""``mobisense solve --method indirect|both``: the summary.json contract and the saved comparison."""

from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr
from reference_problems import PROBLEMS

from mobisense import cli
from mobisense.ocp.solution import Solution

pytestmark = pytest.mark.slow  # every test here runs solvers or subprocesses for seconds


@pytest.fixture(scope="module")
def both_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("both") / "out"
    code = cli.main(["solve", str(PROBLEMS / "hussein2008.yaml"), "--method", "both", "--out", str(out), "--quiet"])
    return code, out


def test_both_writes_indirect_agreement_and_residuals(both_run):
    code, out = both_run
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["method"] == "both" and summary["status"] == "solved"
    indirect = summary["indirect"]
    for key in ("cost", "terminal_cost", "control_energy", "status", "time_s", "nodes", "homotopy"):
        assert key in indirect
    assert {"eps", "status", "nodes", "time_s"} <= set(indirect["homotopy"][-1])
    assert indirect["homotopy"][-1]["eps"] == 1.0 and indirect["status"] == "solved"
    agreement = summary["agreement"]
    assert set(agreement) >= {"cost_rel_diff", "max_state_diff", "max_control_diff", "max_costate_diff"}
    # the requirement; measured 6e-14 at Ipopt tol 1e-9
    assert agreement["cost_rel_diff"] < 1e-6
    assert summary["seeded"]["agreement"]["cost_rel_diff"] < 1e-6
    for method in ("direct", "indirect", "seeded"):
        residuals = summary["optimality"][method]
        assert set(residuals) >= {"dH_du", "transversality", "hamiltonian_variation"}
    # H is constant along the extremal up to the discretisation: measured 5e-8 (indirect), 1.5e-6 (direct)
    assert summary["optimality"]["indirect"]["hamiltonian_variation"] < 1e-6
    assert summary["optimality"]["direct"]["transversality"] < 1e-3  # multiplier estimate of Λ(tf): O(h^3)


def test_both_saves_the_indirect_trajectories(both_run):
    _, out = both_run
    with xr.open_dataset(out / "solution.nc", engine="h5netcdf") as ds:
        assert "indirect_Sigma" in ds and "indirect_lam_p" in ds
        Lam_tf = float(ds["indirect_Lam"].values[-1, 0, 0])
    assert Lam_tf == pytest.approx(20.0, rel=1e-10)  # transversality Λ(tf) = M
    loaded = Solution.load(out)  # a plain Solution can still read it
    assert loaded.method == "both"


def test_indirect_method_summary(tmp_path):
    out = tmp_path / "out"
    code = cli.main(
        ["solve", str(PROBLEMS / "hussein2008.yaml"), "--method", "indirect", "--out", str(out), "--quiet", "--no-plot"]
    )
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["method"] == "indirect" and summary["eps_reached"] == 1.0
    # polished by solve_bvp on an adaptive mesh: the K-converged optimum (10 digits given; measured 2e-12)
    assert summary["cost"] == pytest.approx(15.8477720354, rel=1e-10)
    # the polish's cost change estimates the K = 100 collocation error (order 2d − 1 = 5: measured 4.7e-11)
    assert summary["indirect"]["polish"]["cost_change"] < 1e-9
    assert len(summary["homotopy"]) == 20  # the paper's schedule, δ = 0.05
    loaded = Solution.load(out)
    np.testing.assert_allclose(loaded.Lam[-1], [[20.0]], rtol=1e-8)  # solve_bvp's bc_tol
    assert summary["optimality"]["indirect"]["dH_du"] < 1e-12  # u* = −λ_v/α is exact in the indirect method


def test_indirect_rejects_control_bounds_before_writing(tmp_path, capsys):
    out = tmp_path / "out"
    code = cli.main(["solve", str(PROBLEMS / "terminal_and_bound.yaml"), "--method", "indirect", "--out", str(out)])
    assert code == 2
    assert "sensors[0].u_max" in capsys.readouterr().err
    assert not out.exists()


def test_both_with_an_indirect_solve_that_fails_at_once_keeps_the_direct_solution(tmp_path, capsys):
    # Σ0 = 1e12: the ε = 0 BVP has a non-finite residual, so the indirect solution has no costates; writing
    # solution.nc failed on them (internal error, nothing written; found by a mutation fuzzer)
    import yaml

    data = yaml.safe_load((PROBLEMS / "hussein2008.yaml").read_text())
    data["process"]["Sigma0"] = [[1e12]]
    data["solver"].update(method="both", collocation={"scheme": "radau", "degree": 3, "intervals": 20})
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump(data))
    out = tmp_path / "out"
    assert cli.main(["solve", str(path), "--out", str(out), "--quiet", "--no-plot"]) == 1
    err = capsys.readouterr().err
    assert "indirect:" in err and "internal error" not in err
    loaded = Solution.load(out)  # the direct solution, readable
    assert np.isfinite(loaded.cost) and json.loads((out / "summary.json").read_text())["status"] == "failed"
