"""``mobisense simulate leader-follower``: shipped scenarios end to end, invalid files, a singular run."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml

from mobisense.cli import main
from mobisense.core.config import load_config
from mobisense.core.netcdf import open_dataset
from mobisense.formation.leader_follower.scenario import LeaderFollowerScenario

PROBLEMS = Path(__file__).resolve().parents[2] / "problems"
SHIPPED = sorted(PROBLEMS.glob("leader_follower_*.yaml"))


def _write(tmp_path: Path, source: str, edit) -> Path:
    data = yaml.safe_load((PROBLEMS / source).read_text())
    edit(data)
    path = tmp_path / "scenario.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_shipped_scenarios_validate(path: Path) -> None:
    scenario = load_config(path, LeaderFollowerScenario)
    assert scenario.runs and scenario.followers


def test_shipped_required_scenarios_exist() -> None:
    names = {p.stem for p in SHIPPED}
    assert names >= {f"leader_follower_{n}" for n in ("control1", "control2", "control3", "five_agents")}


@pytest.mark.slow
def test_control1_vs_control2_end_to_end(tmp_path: Path) -> None:
    out = tmp_path / "out"
    scenario = PROBLEMS / "leader_follower_control2.yaml"
    assert main(["simulate", "leader-follower", str(scenario), "--out", str(out)]) == 0
    files = {p.name for p in out.iterdir()}
    assert files >= {"result.nc", "summary.json", "paths.png", "formation_errors.png", "reference_point_errors.png"}
    ds = open_dataset(out / "result.nc")  # the run labels back as the index of "run"
    for name in ("x", "y", "phi"):
        assert ds[name].dims == ("run", "agent", "time") and ds[name].shape == (2, 2, 1001)
    for name in ("d", "beta", "xe", "ye", "d0", "beta0", "deviation"):
        assert ds[name].dims == ("run", "follower", "time")
    assert list(ds["run"].values) == ["control1", "control2"]
    t = ds["time"].values
    xe = ds["xe"].sel(run="control1", follower=2).values
    # eq. 13 through the CLI: rtol = 1e-10 in the file, positions ≲ 20 m → 10·rtol·20 m (see controls tests)
    assert np.max(np.abs(xe - xe[0] * np.exp(-t))) < 2e-8
    # xe, ye are the world-frame offset of eq. leader_follower.3 (they were labelled along/across the heading)
    run = ds.sel(run="control2")
    x, y, phi = (run[k].values for k in ("x", "y", "phi"))
    d0, b0 = run["d0"].values[0], run["beta0"].values[0]
    assert np.ptp(phi[1]) > 0.1  # the follower turns: the two frames differ
    # the same formula on the stored states: round-off of positions ≲ 20 m
    np.testing.assert_allclose(run["xe"].values[0], x[1] + d0 * np.cos(phi[1] + b0) - x[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(run["ye"].values[0], y[1] + d0 * np.sin(phi[1] + b0) - y[0], rtol=0, atol=1e-12)
    assert "world x" in ds["xe"].attrs["long_name"] and "world y" in ds["ye"].attrs["long_name"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["runs"]["control2"]["followers"]["2"]["bearing_error_monotone"] is True
    assert summary["runs"]["control1"]["followers"]["2"]["bearing_error_monotone"] is False
    assert set(summary["files"]) == files


@pytest.mark.slow
def test_ring_sensing_end_to_end(tmp_path: Path) -> None:
    """The Khepera scenario, shortened: active pairs recorded, estimates feed the control, seed reproducible."""

    def shorten(data: dict) -> None:
        data["duration"] = 6.0
        data["runs"] = data["runs"][:2]

    scenario = _write(tmp_path, "leader_follower_khepera.yaml", shorten)
    outs = [tmp_path / name for name in ("a", "b", "c")]
    for out, seed, plot in zip(outs, ("3", "3", "4"), ([], ["--no-plot"], ["--no-plot"]), strict=True):
        assert main(["simulate", "leader-follower", str(scenario), "--out", str(out), "--seed", seed, *plot]) == 0
    assert (outs[0] / "active_pairs.png").exists()
    a, b, c = (open_dataset(out / "result.nc") for out in outs)
    for ds in (a, b):
        del ds.attrs["history"]  # when and by which command line it was written
    assert a["active"].dims == ("run", "follower", "time", "pair") and a.sizes["pair"] == 6
    assert int(a["active"].sum()) > 0 and int((a["selected_pair"] > 0).sum()) > 0
    xr.testing.assert_identical(a, b)  # same seed, same result
    assert not np.allclose(a["x"].values, c["x"].values)  # another seed, other noise
    # the estimate tracks the truth: RMS error a few mm for 2 mm range noise
    assert float(np.sqrt((a["position_error"] ** 2).mean())) < 0.02
    summary = json.loads((outs[0] / "summary.json").read_text())
    entry = summary["runs"]["beta0_0_closest"]["followers"]["2"]
    assert entry["fraction_with_active_pair"] > 0.9 and entry["rms_position_error"] < 0.02


@pytest.mark.slow
def test_no_plot_writes_no_figures(tmp_path: Path) -> None:
    out = tmp_path / "out"
    path = PROBLEMS / "leader_follower_control1.yaml"
    assert main(["simulate", "leader-follower", str(path), "--out", str(out), "--no-plot"]) == 0
    assert {p.name for p in out.iterdir()} == {"result.nc", "summary.json"}


@pytest.mark.parametrize(
    ("source", "edit", "message"),
    [
        (
            "leader_follower_control1.yaml",
            lambda d: d["reference"].update(bearing=1.6),
            "reference.bearing: expected |bearing| < pi/2",
        ),
        ("leader_follower_control1.yaml", lambda d: d.update(gian=2.0), "gian: unknown key; did you mean 'gain'?"),
        ("leader_follower_control1.yaml", lambda d: d.update(step=0.03), "step: expected a divisor of duration"),
        ("leader_follower_control1.yaml", lambda d: d.update(control="control4"), "control: expected one of"),
        ("leader_follower_control1.yaml", lambda d: d["followers"][0].update(pose=[0, 0]), "followers[0].pose"),
        (
            "leader_follower_five_agents.yaml",
            lambda d: d.update(control="control3"),
            "runs[0].control: control3 needs the rates of d0 and beta0",
        ),
        (
            "leader_follower_five_agents.yaml",
            lambda d: d["runs"][1]["reference"].update(distance_from_run="later"),
            "runs[1].reference.distance_from_run: expected the name of an earlier run",
        ),
        (
            "leader_follower_control3.yaml",
            lambda d: d.update(duration=40.0),
            "reference: d0(t) reaches",  # eq. 55 drives d0 through 0 near t = 21 s
        ),
        (
            "leader_follower_khepera.yaml",
            lambda d: d["sensing"].update(pairs=[[1, 9]]),
            "sensing.pairs[0]: expected two different sensor numbers in 1..8",
        ),
    ],
)
def test_invalid_scenarios_exit_2_without_output(tmp_path: Path, capsys, source, edit, message) -> None:
    scenario = _write(tmp_path, source, edit)
    out = tmp_path / "out"
    assert main(["simulate", "leader-follower", str(scenario), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and str(scenario) in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not out.exists()


def test_singular_run_exits_1_without_output(tmp_path: Path, capsys) -> None:
    """Control 2 with the leader abeam of the follower (β = π/2): outside Theorem 2's domain."""

    def abeam(data: dict) -> None:
        data["followers"][0]["pose"] = [0.0, -1.0, 0.0]
        data["runs"] = [{"name": "control2", "control": "control2"}]

    scenario = _write(tmp_path, "leader_follower_control2.yaml", abeam)
    out = tmp_path / "out"
    assert main(["simulate", "leader-follower", str(scenario), "--out", str(out)]) == 1
    assert "singular" in capsys.readouterr().err
    assert not out.exists()


def test_dynamics_too_fast_for_the_step_exit_1_without_output(tmp_path: Path, capsys) -> None:
    """A reference distance oscillating at 1e12 rad/s (a fuzzer's): the integration is bounded per output step
    (MAX_EVALUATIONS_PER_STEP, ≈ 50 times the most a shipped scenario needs) and the run stops saying why,
    in ≈ 2 s instead of ≈ 100 s."""
    from mobisense.formation.leader_follower.simulation import MAX_EVALUATIONS_PER_STEP

    def fast(data: dict) -> None:
        data["reference"]["distance_rate_frequency"] = 1e12

    scenario = _write(tmp_path, "leader_follower_control3.yaml", fast)
    out = tmp_path / "out"
    assert main(["simulate", "leader-follower", str(scenario), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert f"({MAX_EVALUATIONS_PER_STEP} per output step; stopped at t = " in err and "too fast" in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not out.exists()
