"""``mobisense replay`` on field scenarios: outputs, shipped scenarios, validation (exit 2, key path)."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest
import xarray as xr
import yaml

from mobisense.cli import main

PROBLEMS = Path(__file__).resolve().parents[2] / "problems"


def shipped(name: str) -> dict:
    return yaml.safe_load((PROBLEMS / f"{name}.yaml").read_text())


def write(tmp_path: Path, data: dict, name: str = "scenario.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, allow_unicode=True))
    return path


def test_every_shipped_scenario_validates():
    from mobisense.core.config import load_config
    from mobisense.formation.replay.plan import OcpReplayScenario
    from mobisense.formation.replay.scenario import FieldReplayScenario

    for name in ("replay_two_charges", "replay_isotherm13"):
        load_config(PROBLEMS / f"{name}.yaml", FieldReplayScenario)
    load_config(PROBLEMS / "replay_hussein2008.yaml", OcpReplayScenario)


@pytest.mark.slow
def test_field_replay_writes_result_summary_figures_and_animation(tmp_path, capsys):
    data = shipped("replay_two_charges")
    data.update(duration=1.0)  # 10 samples: outputs and animation, not the dynamics, are tested here
    out = tmp_path / "out"
    assert main(["replay", str(write(tmp_path, data)), "--out", str(out), "--animate"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    for key in ("final_level_error", "mean_abs_theta_last_quarter", "rms_z_error", "rms_gradient_error",
                "shape_error_rms_last_half", "simulated_time_per_wall_second"):  # fmt: skip
        assert key in summary
    ds = xr.open_dataset(out / "result.nc", engine="h5netcdf")
    for name in ("z_true", "z_est", "grad_true", "grad_est", "r", "v", "a", "b", "theta"):
        assert name in ds
    assert ds.attrs["C"] == 4.0 and ds["r"].dims == ("time", "platform", "xy") and ds.sizes["time"] == 11
    ds.close()
    for name in ("paths.png", "z_estimate.png", "shape.png", "heading.png"):
        assert (out / name).stat().st_size > 0
    movies = [p for p in out.iterdir() if p.suffix in (".gif", ".mp4")]
    assert len(movies) == 1 and movies[0].stat().st_size > 0 and movies[0].name in summary["files"]
    assert not list(out.glob(".*"))  # no temporary files left
    assert "replay_two_charges" in capsys.readouterr().out


def test_quiet_replay_prints_nothing_but_writes_everything(tmp_path, capsys):
    data = shipped("replay_two_charges")
    data.update(duration=0.5)
    out = tmp_path / "out"
    assert main(["replay", str(write(tmp_path, data)), "--out", str(out), "--quiet", "--no-plot"]) == 0
    assert capsys.readouterr().out == ""  # as solve --quiet: no progress, no summary lines
    assert (out / "summary.json").is_file() and (out / "result.nc").is_file()


@pytest.mark.slow
def test_shape_from_a_steady_state_summary(tmp_path):
    formation = {"formation": "cross", "noise": {"sigma_process": 0.02, "sigma_measurement": 0.05,
                 "sigma_hessian": 0.02}, "bounds": {"a": [0.5, 3.0], "b": [0.5, 3.0]}}  # fmt: skip
    assert (
        main(
            [
                "steady-state",
                str(write(tmp_path, formation, "f.yaml")),
                "--out",
                str(tmp_path / "ss"),
                "--no-plot",
            ]
        )
        == 0
    )
    design = json.loads((tmp_path / "ss" / "summary.json").read_text())
    data = shipped("replay_isotherm13")
    data["formation"]["shape"] = {"summary": "ss/summary.json"}  # relative to the scenario file
    data.update(duration=0.5)
    assert main(["replay", str(write(tmp_path, data)), "--out", str(tmp_path / "out"), "--no-plot"]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["a0"] == pytest.approx(design["a"], rel=1e-15) and summary["b0"] == pytest.approx(
        design["b"], rel=1e-15
    )
    assert "steady-state summary" in summary["source"]


def _set(path: list, value):
    def apply(data):
        target = data
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value
        return data

    return apply


def _delete(path: list):
    def apply(data):
        target = data
        for key in path[:-1]:
            target = target[key]
        del target[path[-1]]
        return data

    return apply


BAD = [
    ("replay_isotherm13", _set(["motion", "levl"], 3.0), "motion.levl: unknown key; did you mean 'level'"),
    (
        "replay_isotherm13",
        _set(["formation", "kind"], "crosss"),
        "formation.kind: unknown formation 'crosss'",
    ),
    (
        "replay_isotherm13",
        _set(["formation", "gains", "stiffness"], -1.0),
        "formation.gains.stiffness: expected a number > 0",
    ),
    (
        "replay_isotherm13",
        _set(["platforms", "count"], 3),
        "formation.kind: the cross needs platforms.count = 4",
    ),
    (
        "replay_isotherm13",
        _set(["platforms", "initial", "velocity"], [0.0, 0.0]),
        "platforms.initial.velocity: expected a nonzero",
    ),
    (
        "replay_isotherm13",
        _set(["field", "kind"], "ocean_temp"),
        "field.kind: unknown field kind 'ocean_temp'",
    ),
    (
        "replay_isotherm13",
        _set(["formation", "shape"], {"summary": "missing.json"}),
        "missing.json: file not found",
    ),
    (
        "replay_isotherm13",
        _set(["formation", "shape"], {"a": 1.0}),
        "formation.shape.b: a fixed shape needs both",
    ),
    ("replay_isotherm13", _delete(["filter"]), "filter: required key is missing"),
    ("replay_isotherm13", _set(["time_step"], 100.0), "time_step: expected 1"),
    (
        "replay_two_charges",
        _set(["formation"], {"kind": "rigid", "offsets": [[-0.5, 0], [0.5, 0]]}),
        "collinear rigid",
    ),
    ("replay_two_charges", _set(["formation", "offsets"], [[0, 0]]), "formation.offsets: expected 2 offsets"),
    (
        "replay_two_charges",
        _set(["filter", "hessian"], "curvature"),
        "filter.hessian: curvature needs the four-platform cross",
    ),
    (
        "replay_two_charges",
        _set(["motion", "level"], -1.0),
        "motion.level: the reciprocal level function needs C > 0",
    ),
    ("replay_two_charges", _delete(["field"]), "expected a field replay (key 'field')"),
    # found by a mutation fuzzer: non-finite field numbers ran (exit 1, numpy warnings); a start faster than
    # max_speed crawled through the saturation for minutes; a list or mapping as a kind was an internal error
    ("replay_two_charges", _set(["field", "charges"], [[float("nan"), 0.0], [3.0, 0.0]]),
     "field.charges[0][0]: expected a finite number, got nan"),
    ("replay_two_charges", _set(["field", "strength"], float("inf")), "field.strength: expected a finite number"),
    # … and numbers of a magnitude no file may hold (softening² overflowed: internal error), booleans and strings
    # where the field's constructor takes numbers (np.asarray turned True into 1.0 and "3" into 3.0: accepted)
    ("replay_two_charges", _set(["field", "softening"], 1e200), "field.softening: expected a magnitude in [1e-100"),
    ("replay_two_charges", _set(["field", "charges"], [[True, 0.0], [3.0, 0.0]]),
     "field.charges[0][0]: expected a number, got True"),
    ("replay_two_charges", _set(["field", "charges"], [["-3", 0.0], [3.0, 0.0]]),
     "field.charges[0][0]: expected a number, got '-3'"),
    ("replay_isotherm13", _set(["platforms", "initial", "velocity"], [1e12, 0.0]),
     "platforms.initial.velocity: expected a speed at most max_speed"),
    ("replay_two_charges", _set(["formation", "kind"], ["rotating"]), "formation.kind: unknown formation ['rotating']"),
    ("replay_two_charges", _set(["motion", "kind"], {"a": 1}), "motion.kind: unknown motion {'a': 1}"),
    (  # a kind that is none of replay's, on a file without the keys of one: the kind is named, not the shape
        "replay_two_charges",
        lambda d: {"kind": 3, **{k: v for k, v in _delete(["field"])(d).items() if k != "kind"}},
        "kind: expected one of 'field_replay', 'plan_replay', 'replan', got 3",
    ),
]


@pytest.mark.parametrize("name,mutate,expected", BAD, ids=[e for _, _, e in BAD])
def test_invalid_scenarios_exit_2_with_the_key_path_and_write_nothing(
    tmp_path, capsys, name, mutate, expected
):
    path = write(tmp_path, mutate(copy.deepcopy(shipped(name))))
    out = tmp_path / "out"
    assert main(["replay", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert expected in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_animate_is_refused_for_a_replay_that_is_not_a_field_replay(tmp_path, capsys):
    # a plan replay has nothing to animate: the option is an error (exit 2, nothing written), not ignored
    out = tmp_path / "out"
    assert main(["replay", "replay_hussein2008", "--animate", "--out", str(out)]) == 2
    assert "--animate: only a field replay is animated, this is a plan_replay file" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("key", [["motion", "steering_gain"], ["formation", "gains", "shape_stiffness"]])
def test_a_loop_too_stiff_to_integrate_stops_with_exit_1(tmp_path, capsys, key):
    # gains of 1e12 (a fuzzer's) made one filter period take minutes: the integration of a period is bounded
    # (MAX_EVALUATIONS_PER_PERIOD, 500 times the most any shipped replay needs: ≈ 3 s) and the replay stops saying so
    from mobisense.formation.replay.simulation import MAX_EVALUATIONS_PER_PERIOD

    path = write(tmp_path, _set(key, 1e12)(shipped("replay_two_charges")))
    assert main(["replay", str(path), "--out", str(tmp_path / "out"), "--no-plot", "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert f"the closed loop is too stiff to integrate: more than {MAX_EVALUATIONS_PER_PERIOD} evaluations" in err
