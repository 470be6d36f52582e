"""Input files of every kind: recognised, validated, described; their schemas; the shipped examples."""

from __future__ import annotations

import json
import re

import pytest
import yaml
from reference_problems import PROBLEMS, hussein2008

from mobisense import cli
from mobisense.core.config import ConfigError
from mobisense.core.examples import EXAMPLES, copy_examples, resolve_input, shipped_examples
from mobisense.core.kinds import FILE_KINDS, detect_kind
from mobisense.core.schema import file_schema

#: the kind of every shipped example, told by its shape alone (none has a kind: key)
SHIPPED_KINDS = {
    "hussein2008": "problem", "coupled_two_sensor": "problem", "terminal_and_bound": "problem",
    "field_mapping_5x5": "problem", "field_mapping_10x10": "problem", "field_mapping_island": "problem",
    "sweep_hussein2008": "sweep", "formation_cross": "formation", "formation_cross_equal_sides": "formation",
    "formation_cross_interior": "formation", "replay_hussein2008": "plan_replay",
    "replay_two_charges": "field_replay", "replay_isotherm13": "field_replay",
    "leader_follower_control1": "leader_follower", "leader_follower_control2": "leader_follower",
    "leader_follower_control3": "leader_follower", "leader_follower_five_agents": "leader_follower",
    "leader_follower_khepera": "leader_follower", "distributed_advection_diffusion": "distributed",
    "hussein2008_paper": "problem", "replay_two_charges_fig3": "field_replay",
    "replay_isotherm13_adaptive": "field_replay", "replay_isotherm13_paper": "field_replay",
    "leader_follower_control3_paper": "leader_follower", "leader_follower_khepera2": "leader_follower",
    "leader_follower_khepera_switching": "leader_follower", "distributed_advection_diffusion_paper": "distributed",
    "distributed_advection_diffusion_paper_consistent": "distributed",
    "keep_out": "problem", "separation": "problem", "replan_drift": "replan",
}  # fmt: skip


def _data(name: str) -> dict:
    return yaml.safe_load((PROBLEMS / f"{name}.yaml").read_text(encoding="utf-8"))


def test_every_shipped_file_is_listed_once_and_ships_as_package_data():
    assert sorted(e.name for e in EXAMPLES) == sorted(p.stem for p in PROBLEMS.glob("*.yaml"))
    assert all(path.is_file() for path in shipped_examples().values())


@pytest.mark.parametrize("name", sorted(SHIPPED_KINDS))
def test_shipped_files_are_recognised_by_shape_and_by_kind_key(name):
    data = _data(name)
    assert detect_kind(data, name) == SHIPPED_KINDS[name]
    assert detect_kind({**data, "kind": SHIPPED_KINDS[name]}, name) == SHIPPED_KINDS[name]


def test_an_unknown_or_unclear_kind_is_one_line_with_the_choices():
    with pytest.raises(ConfigError, match=r"kind: unknown file kind 'swep'; did you mean 'sweep'\?"):
        detect_kind({"kind": "swep"}, "f.yaml")
    with pytest.raises(ConfigError, match=r"fits no kind; add 'kind: …' \(one of distributed, field_replay"):
        detect_kind({"name": "x"}, "f.yaml")


def test_validate_says_what_each_file_is(capsys):
    files = [str(PROBLEMS / f"{name}.yaml") for name in sorted(SHIPPED_KINDS) if name != "sweep_hussein2008"]
    assert cli.main(["validate", *files]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == len(files)
    for name, line in zip(sorted(n for n in SHIPPED_KINDS if n != "sweep_hussein2008"), lines, strict=True):
        assert f"valid {SHIPPED_KINDS[name]} file" in line, line


@pytest.mark.slow
def test_validate_a_sweep_checks_every_task(capsys):
    assert cli.main(["validate", str(PROBLEMS / "sweep_hussein2008.yaml")]) == 0
    assert "parameter sweep (grid) of 6 tasks over cost.alpha (3 values) x sensors[0].p0 (2 values)" in (
        capsys.readouterr().out
    )


def test_validate_reports_every_invalid_file_and_exits_2(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump({**_data("formation_cross"), "bounds": {"a": [3.0, 0.2], "b": [0.2, 3.0]}}))
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text(yaml.safe_dump({**_data("hussein2008"), "kind": "sweep"}))
    assert cli.main(["validate", str(bad), str(PROBLEMS / "hussein2008.yaml"), str(wrong)]) == 2
    captured = capsys.readouterr()
    assert f"{bad}: bounds.a: expected [min, max]" in captured.err
    assert f"{wrong}: (top level)" in captured.err or f"{wrong}: " in captured.err
    assert "valid problem file" in captured.out


def test_a_problem_file_may_say_kind_problem_and_other_commands_refuse_it(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump({**hussein2008(), "kind": "problem"}))
    assert cli.main(["validate", str(path)]) == 0
    assert cli.main(["replay", str(path)]) == 2


#: each command that reads a file, and a shipped example of every kind it does not run
_COMMANDS = {
    ("solve",): "problem", ("sweep",): "sweep", ("steady-state",): "formation",
    ("simulate", "leader-follower"): "leader_follower", ("simulate", "distributed"): "distributed",
}  # fmt: skip
_ONE_OF_EACH = {kind: min(n for n, k in SHIPPED_KINDS.items() if k == kind) for kind in set(SHIPPED_KINDS.values())}


@pytest.mark.parametrize("command", sorted(_COMMANDS), ids=" ".join)
def test_a_command_given_a_file_of_another_kind_names_the_command_that_runs_it(command, tmp_path, capsys):
    # not the model's complaint about the keys the file lacks ("noise: required key is missing (and 6 more
    # problems)"), but what the file is and which command runs it; exit 2 and nothing written
    for kind, name in sorted(_ONE_OF_EACH.items()):
        if kind == _COMMANDS[command]:
            continue
        out = tmp_path / name
        assert cli.main([*command, name, "--out", str(out)]) == 2, (command, name)
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "Traceback" not in err
        said = "kind: a" if "kind" in _data(name) else "(top level): this looks like "  # replan_drift says its kind
        assert f"{name}.yaml: {said}" in err, err
        assert f"run it with '{FILE_KINDS[kind].command} " in err, err
        assert not out.exists()


def test_a_kind_key_of_another_kind_is_refused_with_its_command(tmp_path, capsys):
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump({**hussein2008(), "kind": "sweep"}))
    assert cli.main(["solve", str(path), "--out", str(tmp_path / "out")]) == 2
    assert f"{path}: kind: a parameter sweep file; run it with 'mobisense sweep {path}'" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_missing_file_named_like_a_shipped_example_points_to_it(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)  # problems/hussein2008.yaml run outside a clone, or a misspelled name
    for given, hint in (("problems/hussein2008.yaml", "hussein2008"), ("hussein2009", "hussein2008"),
                        ("replay_two_chrges.yaml", "replay_two_charges")):  # fmt: skip
        assert cli.main(["solve", given, "--out", "out"]) == 2
        assert f"{given}: file not found; did you mean the shipped example '{hint}'?" in capsys.readouterr().err
    assert cli.main(["solve", "nothing_like_it.yaml", "--out", "out"]) == 2
    assert capsys.readouterr().err.strip().endswith("nothing_like_it.yaml: file not found")
    assert not (tmp_path / "out").exists()


def test_a_near_miss_beside_the_file_comes_before_the_shipped_example(tmp_path, capsys, monkeypatch):
    """ex/husein2008.yaml beside the user's (maybe edited) ex/hussein2008.yaml pointed to the shipped example,
    whose bare name then ran the unedited original."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "ex").mkdir()
    (tmp_path / "ex" / "hussein2008.yaml").write_text(yaml.safe_dump(hussein2008()))
    assert cli.main(["validate", "ex/husein2008.yaml"]) == 2
    assert capsys.readouterr().err.strip() == "mobisense: error: ex/husein2008.yaml: file not found; did you mean " \
        "ex/hussein2008.yaml?"  # fmt: skip


def test_a_file_name_read_as_the_shipped_example_is_said(tmp_path, capsys, monkeypatch):
    """A bare name runs the shipped example as documented; a missing hussein2008.yaml was also read as it, without
    a word: now a note says which file is read."""
    monkeypatch.chdir(tmp_path)
    assert cli.main(["validate", "hussein2008"]) == 0
    assert capsys.readouterr().err == ""
    assert cli.main(["validate", "hussein2008.yaml"]) == 0
    note = capsys.readouterr().err.strip().splitlines()
    assert len(note) == 1 and note[0].startswith(f"mobisense: note: hussein2008.yaml is not in {tmp_path}: reading")
    assert note[0].endswith("problems/hussein2008.yaml")


def test_the_api_loaders_take_example_names_and_tell_scenario_kinds_by_shape():
    from mobisense import design_formation, load_scenario

    for name, kind in SHIPPED_KINDS.items():
        if kind in ("field_replay", "plan_replay", "replan", "leader_follower", "distributed"):
            assert load_scenario(name).kind == kind, name
            assert load_scenario(str(PROBLEMS / f"{name}.yaml")).kind == kind, name
    assert design_formation("formation_cross").summary["formation"] == "cross"
    with pytest.raises(ConfigError, match=r"hussein2008.yaml: \(top level\): this looks like an optimal-control "
                                          r"problem file; run it with 'mobisense solve "):  # fmt: skip
        load_scenario("hussein2008")


@pytest.mark.parametrize("kind", sorted(FILE_KINDS))
def test_schema_is_json_schema_that_accepts_the_shipped_files(kind, tmp_path):
    jsonschema = pytest.importorskip("jsonschema")
    schema = file_schema(kind)
    jsonschema.Draft202012Validator.check_schema(schema)
    for name in (n for n, k in SHIPPED_KINDS.items() if k == kind):
        jsonschema.validate(_data(name), schema)
    out = tmp_path / f"{kind}.schema.json"
    assert cli.main(["schema", kind, "--out", str(out)]) == 0
    assert json.loads(out.read_text()) == json.loads(json.dumps(schema))


def test_schema_rejects_a_misspelled_key_and_lists_registered_noise_models():
    jsonschema = pytest.importorskip("jsonschema")
    schema = file_schema("problem")
    data = hussein2008()
    data["cost"]["alhpa"] = data["cost"].pop("alpha")
    assert not jsonschema.Draft202012Validator(schema).is_valid(data)
    variants = schema["$defs"]["NoiseModel"]["oneOf"]
    assert {v["properties"]["model"]["const"] for v in variants} >= {"quadratic_range", "constant"}


def test_examples_lists_one_line_each_and_copies_them(tmp_path, capsys):
    assert cli.main(["examples"]) == 0
    out = capsys.readouterr().out
    for example in EXAMPLES:
        assert re.search(rf"^{example.name} +\S.*\[mobisense {example.command}\]$", out, flags=re.M)
    assert cli.main(["examples", "--copy", str(tmp_path / "ex")]) == 0
    assert sorted(p.name for p in (tmp_path / "ex").iterdir()) == sorted(f"{e.name}.yaml" for e in EXAMPLES)
    assert f"{len(EXAMPLES)} example files written to {tmp_path / 'ex'}/;" in capsys.readouterr().out
    (tmp_path / "ex" / "hussein2008.yaml").write_text("changed")
    with pytest.raises(FileExistsError, match=r"hussein2008.yaml exists with other content$"):
        copy_examples(tmp_path / "ex")
    assert cli.main(["examples", "--copy", str(tmp_path / "ex")]) == 2
    assert cli.main(["examples", "--copy", str(tmp_path / "ex"), "--force"]) == 0
    # only the changed file is written again
    assert f"1 example file written to {tmp_path / 'ex'}/ ({len(EXAMPLES) - 1} already there, unchanged)" in (
        capsys.readouterr().out
    )


def test_a_shipped_name_resolves_unless_a_file_of_that_name_exists(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert resolve_input("hussein2008") == shipped_examples()["hussein2008"]
    assert resolve_input("hussein2008.yaml") == shipped_examples()["hussein2008"]
    (tmp_path / "hussein2008.yaml").write_text("mine")
    assert str(resolve_input("hussein2008.yaml")) == "hussein2008.yaml"
    assert str(resolve_input("sub/hussein2008.yaml")) == "sub/hussein2008.yaml"  # a path is never replaced


def test_copied_examples_validate_where_they_are(tmp_path, capsys):
    written = copy_examples(tmp_path)
    files = [str(p) for p in written if p.stem not in ("sweep_hussein2008",)]
    assert cli.main(["validate", *files]) == 0


def test_a_missing_extra_is_one_line_saying_what_to_install(monkeypatch, capsys):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "dask" else real(name, *a))
    assert cli.main(["sweep", str(PROBLEMS / "sweep_hussein2008.yaml")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        'mobisense: error: mobisense sweep needs dask (not installed): pip install "mobisense[sweep]" '
        '(from a clone of the repository: pip install ".[sweep]")'
    )


def test_the_default_install_leaves_the_sweep_dependencies_to_the_extra():
    tomllib = pytest.importorskip("tomllib")
    project = tomllib.loads((PROBLEMS.parent / "pyproject.toml").read_text())["project"]
    names = {re.split(r"[<>=\[ ]", d)[0] for d in project["dependencies"]}
    assert not names & {"dask", "distributed", "pyarrow"}
    assert {re.split(r"[<>=\[ ]", d)[0] for d in project["optional-dependencies"]["sweep"]} == {"dask", "pyarrow"}
    assert project["license"] == "BSD-3-Clause" and (PROBLEMS.parent / "LICENSE").is_file()


def test_the_readme_describes_every_shipped_example_in_one_line():
    readme = (PROBLEMS.parent / "README.md").read_text(encoding="utf-8")
    for example in EXAMPLES:
        assert re.search(rf"^\| `{example.name}\.yaml` \| `{example.command}` \| \S", readme, flags=re.M), example.name


@pytest.mark.parametrize("command", [["solve", "hussein2008", "--out"], ["examples", "--copy"],
                                     ["schema", "problem", "--out"]], ids=lambda c: c[0])  # fmt: skip
def test_an_empty_output_path_is_refused_not_taken_as_the_current_folder(command, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cli.main([*command, ""]) == 2
    assert "expected a path, got ''" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_a_file_name_too_long_for_the_system_is_an_input_error(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    long = "x" * 300  # over the 255 bytes a name may have: the OS refuses it (ENAMETOOLONG), not a bug
    assert cli.main(["solve", long]) == 2
    assert cli.main(["solve", "hussein2008", "--no-plot", "--out", f"{long}/o"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.endswith("file name too long for this system") for line in err)
    assert list(tmp_path.iterdir()) == []


def test_a_replan_file_without_its_kind_key_is_a_replay(tmp_path):
    from mobisense import load_scenario

    data = _data("replan_drift")
    del data["kind"]
    path = PROBLEMS / "replan_drift.yaml"
    copy = tmp_path / "replan.yaml"
    copy.write_text(yaml.safe_dump({**data, "problem": str(path.parent / data["problem"])}))
    assert load_scenario(copy, kind="replay").kind == "replan" == load_scenario(copy).kind
