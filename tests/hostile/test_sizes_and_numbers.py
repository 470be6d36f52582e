"""Hostile sizes and numbers, command by command: refused before any allocation (exit 2, one line, the key path
and how to proceed), or — when the input is valid but the numbers fail — exit 1 with a message, never a traceback,
a hang or an "optimum" that is not one.
"""

from __future__ import annotations

import copy
import json
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
import yaml
from hostile.harness import EITHER, GOOD, attack
from hostile.inputs import KINDS, small_problem
from reference_problems import PROBLEMS

FIELD_10X10 = PROBLEMS / "field_mapping_10x10.yaml"
ISLAND = PROBLEMS / "field_mapping_island.yaml"

pytestmark = pytest.mark.slow  # each case starts a Python process (~1 s)


@dataclass
class Case:
    """A command, how to change its valid input, extra arguments, the exit status and the words expected."""

    kind: str
    edit: Callable[[dict[str, Any]], Any]
    expect: int
    mentions: tuple[str, ...]
    args: tuple[str, ...] = ()
    limit: float = 90.0
    names_file: bool = True  # False for command-line errors, which argparse reports without the file


def _set(path: str, value: Any) -> Callable[[dict[str, Any]], None]:
    def edit(data: dict[str, Any]) -> None:
        target: Any = data
        parts = [int(p) if p.isdigit() else p for p in path.split(".")]
        for part in parts[:-1]:
            target = target[part]
        target[parts[-1]] = value

    return edit


def _both(*edits: Callable[[dict[str, Any]], None]) -> Callable[[dict[str, Any]], None]:
    def edit(data: dict[str, Any]) -> None:
        for e in edits:
            e(data)

    return edit


def _sensors(n: int) -> Callable[[dict[str, Any]], None]:
    def edit(data: dict[str, Any]) -> None:
        s = data["sensors"][0]
        data["sensors"] = [{**copy.deepcopy(s), "name": f"s{i}", "p0": [10.0 + i, 10.0]} for i in range(n)]

    return edit


def _states(n: int) -> Callable[[dict[str, Any]], None]:
    def edit(data: dict[str, Any]) -> None:
        eye = np.eye(n).tolist()
        data["process"] = {"A": (-0.5 * np.eye(n)).tolist(), "B": eye, "Q": eye, "Sigma0": (200 * np.eye(n)).tolist(),
                           "locations": [[float(i), 0.0] for i in range(n)]}  # fmt: skip
        data["cost"] = {"M": eye, "alpha": 0.004}

    return edit


def _none(data: dict[str, Any]) -> None:
    return None


def _island(data: dict[str, Any]) -> None:
    data.clear()
    data.update(yaml.safe_load(ISLAND.read_text()))


CASES: dict[str, Case] = {
    # ---------------------------------------------------------------- solve: sizes and the homotopy
    "solve K=100000 d=9": Case("solve", _none, 2, ("too large", "--intervals"),
                               ("--intervals", "100000", "--degree", "9")),
    # the island's solve (a disc, a separation, a workspace on the 5 × 5 field) takes 21.7 s; its bound was 1.84 s,
    # the unconstrained 5 × 5's, which takes 3.7 s; now 3 × that (CONSTRAINED_FACTOR)
    "solve the island in 4 s": Case("solve", _island, 2, ("too long", "shooting NLP"), ("--max-time", "4s")),
    "solve 1000 sensors": Case("solve", _sensors(1000), 2, ("too large", "N = 1000 sensors")),
    "solve 2000 sensors": Case("solve", _sensors(2000), 2, ("sensors", "at most 1000 items")),
    "solve 150 states": Case("solve", _states(150), 2, ("too large", "n = 150 states")),
    "solve --step 1e-13": Case("solve", _none, 2, ("solver.homotopy.step",), ("--step", "1e-13")),
    "solve adaptive --step 1e-13": Case("solve", _none, 2, ("solver.homotopy.step",),
                                        ("--homotopy", "adaptive", "--step", "1e-13")),
    "solve adaptive min_step 1e-13": Case("solve", _set("solver.homotopy", {"mode": "adaptive", "min_step": 1e-13}),
                                          2, ("solver.homotopy.min_step",)),
    "solve min_step > step": Case("solve", _set("solver.homotopy", {"mode": "adaptive", "step": 0.01,
                                                                     "min_step": 0.1}), 2, ("min_step <= step",)),
    "solve --intervals -5": Case("solve", _none, 2, ("solver.collocation.intervals",), ("--intervals", "-5")),
    "solve --max-memory 100M": Case("solve", _none, 2, ("too large", "100 MiB"),
                                    ("--intervals", "3000", "--max-memory", "100M")),
    "solve --max-memory junk": Case("solve", _none, 2, ("--max-memory",), ("--max-memory", "lots"), names_file=False),
    "solve --max-time 1s": Case("solve", _states(8), 2, ("too long", "--max-time"), ("--max-time", "1s")),
    # ---------------------------------------------------------------- solve: numbers
    "solve t0=-1e308 tf=1e308": Case("solve", _set("horizon", {"t0": -1e308, "tf": 1e308}), 2, ("horizon.t0",)),
    "solve tf - t0 = 1e-12 at t0 = 1e5": Case("solve", _set("horizon", {"t0": 1e5, "tf": 1e5 + 1e-9}), 2,
                                              ("horizon.tf", "resolution")),
    "solve tf - t0 = 1e-120": Case("solve", _set("horizon", {"t0": 0.0, "tf": 1e-120}), 2, ("horizon.tf",)),
    "solve horizon 1e-60 (control scale)": Case("solve", _set("horizon", {"t0": 0.0, "tf": 1e-60}), 2,
                                                ("horizon", "control scale")),
    "solve Sigma0 1e200": Case("solve", _set("process.Sigma0", [[1e200]]), 2, ("process.Sigma0",)),
    "solve A 1e300": Case("solve", _set("process.A", [[1e300]]), 2, ("process.A",)),
    "solve locations 1e200": Case("solve", _set("process.locations", [[1e200, 0.0]]), 2, ("process.locations",)),
    "solve p0 1e100 from -1e100": Case("solve", _both(_set("sensors.0.p0", [1e100, 1e100]),
                                                      _set("process.locations", [[-1e100, -1e100]])), 2,
                                       ("sensors", "length scale")),
    "solve max_iterations 10**18": Case("solve", _set("solver.max_iterations", 10**18), 2,
                                        ("solver.max_iterations",)),
    "solve M 1e-300": Case("solve", _set("cost.M", [[1e-300]]), 2, ("cost.M",)),
    "solve degree true": Case("solve", _set("solver.collocation.degree", True), 2,
                              ("solver.collocation.degree", "boolean")),
    "solve intervals 1.0": Case("solve", _set("solver.collocation.intervals", 20.0), 2,
                                ("solver.collocation.intervals", "integer")),
    "solve name ..": Case("solve", _set("name", ".."), 2, ("name",)),
    "solve name with a slash": Case("solve", _set("name", "../../etc/x"), 2, ("name",)),
    "solve sensor name 10 kB": Case("solve", _set("sensors.0.name", "s" * 10_000), 2, ("sensors[0].name",)),
    "solve unknown noise model": Case("solve", _set("sensors.0.noise", {"model": "cubic"}), 2,
                                      ("sensors[0].noise.model", "unknown noise model")),
    "solve noise without model": Case("solve", _set("sensors.0.noise", {"beta": 1.0}), 2, ("sensors[0].noise",)),
    "solve 3 Ipopt iterations (solver failure)": Case("solve", _set("solver.max_iterations", 3), 1,
                                                      ("Maximum_Iterations_Exceeded",)),
    # a horizon of 1e12: the indirect method's Kalman guess ran for minutes (DOP853, a fuzzer's); now it fails at
    # once (here: the adjoint's steps fall below the resolution of the times) and a 'both' solve reports the
    # indirect failure beside the direct solution, which it keeps
    "solve both tf = 1e12": Case("solve", _both(_set("solver.method", "both"), _set("horizon.tf", 10**12),
                                                _set("solver.collocation.intervals", 20)), 1,
                                 ("direct: converged at ε = 1", "; indirect: ")),
    "solve --multistart on indirect": Case("solve", _set("solver.method", "indirect"), 2, ("--multistart",),
                                           ("--multistart", "2")),
    "solve --workers without multistart": Case("solve", _none, 2, ("--multistart",), ("--workers", "2")),
    "solve --multistart -1": Case("solve", _none, 2, ("--multistart",), ("--multistart", "-1"), names_file=False),
    "solve --scheduler refused": Case("solve", _none, 2, ("--scheduler", "cannot connect"),
                                      ("--multistart", "2", "--scheduler", "tcp://127.0.0.1:1"), names_file=False),
    "solve --tls-ca-file missing": Case("solve", _none, 2, ("--tls-ca-file", "file not found"),
                                        ("--multistart", "2", "--scheduler", "tls://127.0.0.1:1",
                                         "--tls-ca-file", "nope.pem"), names_file=False),
    # ---------------------------------------------------------------- validate
    "validate 150 states (valid, not solved)": Case("validate", _states(150), 0, ("valid",), limit=120),
    "validate max_iterations 10**18": Case("validate", _set("solver.max_iterations", 10**18), 2,
                                           ("solver.max_iterations",)),
    # ---------------------------------------------------------------- steady-state
    "steady-state bounds [1e-300, 1e300]": Case("steady-state", _set("bounds", {"a": [1e-300, 1e300],
                                                                                "b": [0.2, 3.0]}), 2, ("bounds.a",)),
    "steady-state bounds reversed": Case("steady-state", _set("bounds.a", [3.0, 0.2]), 2, ("bounds.a",)),
    "steady-state contour_resolution 10**6": Case("steady-state", _set("contour_resolution", 10**6), 2,
                                                   ("contour_resolution",)),
    "steady-state equal_sides 'yes'": Case("steady-state", _set("equal_sides", "yes"), 2, ("equal_sides",)),
    "steady-state extreme noise ratio": Case("steady-state", _set("noise", {"sigma_process": 1e-90,
                                                                            "sigma_measurement": 1e90,
                                                                            "sigma_hessian": 1e90}), 1,
                                             ("not finite",)),
    "steady-state custom collinear": Case("steady-state", lambda d: {"formation": "custom", "noise": d["noise"],
                                                                     "positions": [[0, 0], [1, 0], [2, 0]]}, 2,
                                          ("positions",)),
    # ---------------------------------------------------------------- replay (field)
    "replay duration 1e9": Case("replay", _set("duration", 1e9), 2, ("time_step",)),
    "replay 1e6 steps (too long)": Case("replay", _both(_set("duration", 1e5), _set("time_step", 0.1)), 2,
                                        ("too long", "time_step")),
    "replay 1000 platforms": Case("replay", _set("platforms.count", 1000), 2, ("platforms.count",)),
    "replay seed -1": Case("replay", _set("seed", -1), 2, ("seed",)),
    "replay --seed -1": Case("replay", _none, 2, ("--seed",), ("--seed", "-1"), names_file=False),
    "replay unknown formation kind": Case("replay", _set("formation.kind", "hexagon"), 2, ("formation.kind",)),
    "replay motion reference, solution text": Case("replay", lambda d: _reference(d, "notes.txt"), 2,
                                                   ("notes.txt", "not a netCDF")),
    # ---------------------------------------------------------------- replay (re-planning)
    "replan 1e5 runs × 1e6 steps": Case("replan", _set("monte_carlo", {"runs": 100_000, "time_step": 1e-5}), 2,
                                        ("too large", "monte_carlo.runs")),
    "replan 1e4 runs re-planning every step": Case("replan", _both(_set("monte_carlo", {"runs": 10_000,
                                                                                         "time_step": 1e-3}),
                                                                   _set("replan.every", 1e-3)), 2,
                                                   ("too", "replan.every")),
    # 200 runs re-planning every 0.05 T: 4e4 re-solves of ≥ 11 ms each (measured), estimated at 0.4 ms each, passed
    # --max-time 30s and ran 13 minutes (red team); each re-solve's fixed cost is now counted
    "replan 4e4 re-solves in 30 s": Case("replan", _both(_set("monte_carlo", {"runs": 200, "time_step": 0.05}),
                                                         _set("replan.every", 0.05)), 2,
                                         ("too long", "re-solves", "replan.every"), ("--max-time", "30s")),
    # a field is re-planned by shooting since stop 34: a 10 × 10 field's window solves are counted (≥ 20 fine
    # iterations of its K = 100 grid each, on top of the full solve), 400 re-solves refused under 60 s
    "replan a 10 × 10 field every 0.05 T": Case("replan", _both(_set("problem", str(FIELD_10X10)),
                                                                _set("replan.every", 0.05)), 2,
                                                ("too long", "re-solves of the shooting NLP"), ("--max-time", "60s")),
    # red team: the island re-planned cold every 0.5 T was estimated at 23 s (each cold window's homotopy and the
    # constraints' cost uncounted), passed --max-time 30s and ran 286 s; now at least 113 s
    "replan the island cold every 0.5 T in 60 s": Case("replan", _both(_set("problem", str(ISLAND)), _set(
        "replan", {"every": 0.5, "horizon": "shrinking", "warm_start": "cold"})), 2,
        ("too long", "re-solves of the shooting NLP"), ("--max-time", "60s")),  # fmt: skip
    "replan every 1e-300": Case("replan", _set("replan.every", 1e-300), 2, ("replan.every",)),
    "replan receding without length": Case("replan", _set("replan.horizon", "receding"), 2, ("replan.length",)),
    "replan length 20 > horizon": Case("replan", _set("replan", {"every": 1.0, "horizon": "receding", "length": 20.0}),
                                2, ("replan.length", "within the horizon")),
    "replan warm start 'hot'": Case("replan", _set("replan.warm_start", "hot"), 2, ("replan.warm_start",)),
    "replan problem missing": Case("replan", _set("problem", "nope.yaml"), 2, ("nope.yaml", "file not found")),
    "replan problem is the scenario": Case("replan", _set("problem", "input.yaml"), 2, ("problem",)),
    "replan drift of length 3": Case("replan", _set("disturbance.drift", [0.1, 0.2, 0.3]), 2, ("disturbance.drift",)),
    "replan runs 0": Case("replan", _set("monte_carlo.runs", 0), 2, ("monte_carlo.runs",)),
    # ---------------------------------------------------------------- simulate leader-follower
    "leader-follower duration 1e6 step 1e-3": Case("simulate leader-follower",
                                                   _both(_set("duration", 1e6), _set("step", 1e-3)), 2,
                                                   ("too large", "step")),
    "leader-follower bearing 1.6": Case("simulate leader-follower", _set("reference.bearing", 1.6), 2,
                                        ("reference.bearing",)),
    "leader-follower pose of length 4": Case("simulate leader-follower", _set("leader.pose", [0, 0, 0, 0]), 2,
                                             ("leader.pose",)),
    "leader-follower step not a divisor": Case("simulate leader-follower", _set("step", 0.03), 2, ("step",)),
    "leader-follower rtol 1e-300": Case("simulate leader-follower", _set("integration.rtol", 1e-300), 2,
                                        ("integration.rtol",)),
    "leader-follower control 'control9'": Case("simulate leader-follower", _set("control", "control9"), 2,
                                               ("control",)),
    # ---------------------------------------------------------------- simulate distributed
    "distributed duration 1e7 step 1e-3": Case("simulate distributed",
                                               _set("time", {"step": 1e-3, "duration": 1e7}), 2, ("too large",)),
    "distributed cell naming sensor 99": Case("simulate distributed",
                                              lambda d: d["network"]["cells"][0].__setitem__(0, 99), 2,
                                              ("network.cells",)),
    "distributed positions 1e200": Case("simulate distributed", _set("network.positions.0", [1e200, 0.0]), 2,
                                        ("network.positions[0]",)),
    "distributed plot cell 99": Case("simulate distributed", _set("output.plot_cells", [99]), 2,
                                     ("output.plot_cells",)),
}  # fmt: skip


def _reference(data: dict[str, Any], solution: str) -> None:
    data["motion"] = {"kind": "reference", "solution": solution}


@pytest.mark.parametrize("name", list(CASES))
def test_hostile_sizes_and_numbers(tmp_path, name):
    case = CASES[name]
    kind = KINDS[case.kind]
    (tmp_path / "notes.txt").write_text("this is not a netCDF file\n")
    data = kind.data()
    replaced = case.edit(data)
    path = kind.write(tmp_path, replaced if isinstance(replaced, dict) else data)
    out = tmp_path / "result"
    args = kind.command(path, out) + list(case.args)
    mentions = ("input.yaml", *case.mentions) if case.expect == 2 and case.names_file else case.mentions
    outcome = attack(kind.name, args, tmp_path, case.expect, mentions, out, limit=case.limit)
    assert outcome.verdict in GOOD, outcome.problems


def test_degenerate_scaling_is_solved_at_the_baseline(tmp_path):
    # M = 1e-90: the terminal weight is negligible, so the optimum is not to move; the NLP is scaled by the
    # coasting cost (no absolute floor), so the solver finds J = baseline (Ipopt tol 1e-9 → relative 1e-6 here)
    kind = KINDS["solve"]
    data = small_problem()
    data["cost"]["M"] = [[1e-90]]
    path = kind.write(tmp_path, data)
    out = tmp_path / "result"
    outcome = attack("solve", kind.command(path, out), tmp_path, 0, (), out)
    assert outcome.verdict in GOOD, outcome.problems
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "solved" and not summary["worse_than_baseline"]
    assert summary["cost"] == pytest.approx(summary["baseline"]["cost"], rel=1e-6)


def test_optimum_worse_than_baseline_is_flagged(tmp_path):
    # the flag compares the solved cost with the no-control baseline: here the baseline is halved by hand
    from mobisense.ocp.direct.solver import solve_direct
    from mobisense.ocp.problem import Problem

    solution = solve_direct(Problem.from_dict(small_problem()))
    solution.baseline = {"cost": solution.cost * 0.5}
    summary = solution.summary()
    assert summary["worse_than_baseline"] and "--multistart" in summary["warning"]


def test_replay_of_a_file_that_is_not_a_solution(tmp_path):
    kind = KINDS["replay"]
    garbage = {"notes.txt": b"plain text\n", "fake.nc": b"\x89HDF\r\n\x1a\n" + b"\x00" * 64,
               "problem.yaml": yaml.safe_dump(small_problem()).encode()}  # fmt: skip
    for name, content in garbage.items():
        (tmp_path / name).write_bytes(content)
        replay = {"name": "plan", "solution": name, "monte_carlo": {"runs": 10, "time_step": 0.1}}
        path = kind.write(tmp_path, replay)
        out = tmp_path / "result"
        outcome = attack("replay", kind.command(path, out), tmp_path, 2, (name, "not a"), out)
        assert outcome.verdict in GOOD, outcome.problems


def test_replay_monte_carlo_too_large(tmp_path):
    kind = KINDS["replay"]
    (tmp_path / "problem.yaml").write_text(yaml.safe_dump(small_problem()))
    replay = {"name": "plan", "solution": "missing.nc", "problem": "problem.yaml",
              "monte_carlo": {"runs": 1_000_000, "time_step": 1e-6}}  # fmt: skip
    path = kind.write(tmp_path, replay)
    out = tmp_path / "result"
    outcome = attack("replay", kind.command(path, out), tmp_path, 2, ("too large", "monte_carlo"), out)
    assert outcome.verdict in GOOD, outcome.problems


def test_replay_of_a_netcdf_that_is_not_a_solution(tmp_path):
    import xarray as xr

    kind = KINDS["replay"]
    xr.Dataset({"trace": (("a",), np.ones(3))}).to_netcdf(tmp_path / "grid.nc", engine="h5netcdf")
    replay = {"name": "plan", "solution": "grid.nc", "monte_carlo": {"runs": 10, "time_step": 0.1}}
    path = kind.write(tmp_path, replay)
    out = tmp_path / "result"
    outcome = attack("replay", kind.command(path, out), tmp_path, 2, ("grid.nc", "not a solution"), out)
    assert outcome.verdict in GOOD, outcome.problems



#: valid problems with extreme numbers (within the magnitude bounds): solved, or a clean numerical failure
EXTREMES = {
    "Sigma0 1e100": ("process.Sigma0", [[1e100]]),
    "A 1e50 (unstable)": ("process.A", [[1e50]]),
    "A -1e50 (stiff)": ("process.A", [[-1e50]]),
    "Q 1e100": ("process.Q", [[1e100]]),
    "M 1e100": ("cost.M", [[1e100]]),
    "alpha 1e-100": ("cost.alpha", 1e-100),
    "alpha 1e100": ("cost.alpha", 1e100),
    "tf 1e-12": ("horizon.tf", 1e-12),
    "tf 1e-30": ("horizon.tf", 1e-30),
    "tf 1e100": ("horizon.tf", 1e100),
    "noise 1e-100": ("sensors.0.noise", {"model": "quadratic_range", "beta": 1e-100, "gamma": 1e-100}),
    "noise 1e100": ("sensors.0.noise", {"model": "quadratic_range", "beta": 1e100, "gamma": 1e100}),
    "p0 1e50": ("sensors.0.p0", [1e50, 1e50]),
    "v0 1e50": ("sensors.0.v0", [1e50, 0.0]),
}


@pytest.mark.parametrize("name", list(EXTREMES))
def test_extreme_valid_numbers_are_solved_or_fail_cleanly(tmp_path, name):
    key, value = EXTREMES[name]
    kind = KINDS["solve"]
    data = small_problem()
    _set(key, value)(data)
    path = kind.write(tmp_path, data)
    out = tmp_path / "result"
    outcome = attack("solve", kind.command(path, out), tmp_path, EITHER, (), out)
    assert outcome.verdict in GOOD, outcome.problems
    if outcome.code == 0:  # an optimum is a number, and never worse than not moving
        summary = json.loads((out / "summary.json").read_text())
        assert summary["status"] == "solved" and np.isfinite(summary["cost"]) and not summary["worse_than_baseline"]


#: valid scenarios with extreme numbers: simulated, a clean failure (exit 1), or refused as too long (exit 2)
SIMULATION_EXTREMES = {
    "leader speed 1e50": ("simulate leader-follower", "leader.speed", 1e50, 2),
    "leader gain 1e50": ("simulate leader-follower", "gain", 1e50, 2),
    "leader turn rate 1e50": ("simulate leader-follower", "leader.turn_rate", 1e50, 2),
    "follower 1e90 away": ("simulate leader-follower", "followers.0.pose", [1e90, 1e90, 0.0], 2),
    "reference distance 1e-90": ("simulate leader-follower", "reference.distance", 1e-90, 2),
    "leader speed 1e4": ("simulate leader-follower", "leader.speed", 1e4, EITHER),
    "diffusivity 1e50": ("simulate distributed", "field.diffusivity", 1e50, EITHER),
    "field amplitude 1e-100": ("simulate distributed", "field.amplitude", 1e-100, EITHER),
    "field velocity 1e50": ("simulate distributed", "field.velocity", [1e50, 0.0], EITHER),
    "snr 1e-100": ("simulate distributed", "noise.snr", 1e-100, EITHER),
    "wavenumber 1e50": ("simulate distributed", "field.wavenumber", 1e50, EITHER),
    "platform max speed 1e100": ("replay", "platforms.max_speed", 1e100, EITHER),
    "centre at 1e90": ("replay", "platforms.initial.center", [1e90, 1e90], EITHER),
    "process noise 1e-100": ("replay", "filter.noise.sigma_process", 1e-100, EITHER),
    "measurement noise 1e100": ("replay", "filter.noise.sigma_measurement", 1e100, EITHER),
    "level 1e90": ("replay", "motion.level", 1e90, EITHER),
    "angular speed 1e50": ("replay", "formation.angular_speed", 1e50, EITHER),
    "sigma_process 1e-100": ("steady-state", "noise.sigma_process", 1e-100, EITHER),
    "sigma_measurement 1e-100": ("steady-state", "noise.sigma_measurement", 1e-100, EITHER),
    "sigma_hessian 1e100": ("steady-state", "noise.sigma_hessian", 1e100, EITHER),
    "bounds [1e-90, 1e90]": ("steady-state", "bounds.a", [1e-90, 1e90], 2),
}


@pytest.mark.parametrize("name", list(SIMULATION_EXTREMES))
def test_extreme_valid_scenarios_run_fail_cleanly_or_are_refused(tmp_path, name):
    kind_name, key, value, expect = SIMULATION_EXTREMES[name]
    kind = KINDS[kind_name]
    data = kind.data()
    _set(key, value)(data)
    path = kind.write(tmp_path, data)
    out = tmp_path / "result"
    mentions = ("input.yaml", "too") if expect == 2 and kind_name != "steady-state" else ()
    outcome = attack(kind.name, kind.command(path, out), tmp_path, expect, mentions, out)
    assert outcome.verdict in GOOD, outcome.problems
