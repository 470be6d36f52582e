"""The pre-flight budget (sizes, limits, estimates against CasADi's counts) and output folders (checks, lock)."""

from __future__ import annotations

import json
import os

import pytest
import yaml
from reference_problems import PROBLEMS, hussein2008

from mobisense.core.budget import Estimate, check_budget, default_memory_limit, parse_duration, parse_size
from mobisense.core.config import ConfigError
from mobisense.core.output import LOCK_NAME, OutputFolder, default_output_folder, input_files


def test_sizes_and_durations():
    assert parse_size("4G") == 4 * 2**30 and parse_size("512M") == 512 * 2**20 and parse_size("2.5GiB") == 2.5 * 2**30
    assert parse_duration("90") == 90 and parse_duration("30m") == 1800 and parse_duration("2h") == 7200
    for bad in ("lots", "-1G", "10K", ""):
        with pytest.raises(ValueError):
            parse_size(bad)
    with pytest.raises(ValueError):
        parse_duration("0.1s")


def test_budget_refuses_with_what_and_how():
    check_budget([Estimate("small", 1e6)], limit=2**30)
    with pytest.raises(ConfigError, match=r"f\.yaml: too large: big needs about .* GiB .* 1 GiB allowed .*; shrink it"):
        check_budget([Estimate("big", 8 * 2**30, "shrink it")], limit=2**30, source="f.yaml")
    with pytest.raises(ConfigError, match=r"too long: slow would compute for at least 2 h, more than the 1 h"):
        check_budget([Estimate("slow", 0.0, "", 7200.0)], limit=2**30)
    assert 0 < default_memory_limit() <= os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2


def _check_size_against_the_built_nlp(data: dict, intervals: int) -> None:
    """Variables and constraints exact; CasADi's Jacobian and Hessian patterns at most the estimate, and within 1.5×."""
    from mobisense.ocp.direct.nlp_size import transcription_size
    from mobisense.ocp.direct.transcription import transcription_for
    from mobisense.ocp.model import Structure
    from mobisense.ocp.problem import Problem

    problem = Problem.from_dict(data)
    tr = transcription_for(problem)
    size = transcription_size(Structure.of(problem), 3, intervals, "radau")
    assert (size.variables, size.constraints) == (tr.nw, tr.ng)  # exact
    solver = tr._solver(False).function
    jacobian = solver.get_function("nlp_jac_g").sparsity_out(1).nnz()
    hessian = solver.get_function("nlp_hess_l").sparsity_out(0).nnz()
    assert jacobian <= size.jacobian_nnz <= 1.5 * jacobian
    assert hessian <= size.hessian_nnz <= 1.5 * hessian


def test_transcription_size_matches_the_built_nlp():
    # structural upper estimates: CasADi's patterns are at most these, and not far below (measured +12 … +17 %
    # for N = 1–3, Radau and Legendre)
    data = hussein2008(collocation={"intervals": 5})
    data["sensors"].append({**data["sensors"][0], "name": "s2", "p0": [-5.0, 3.0], "u_max": 2.0})
    _check_size_against_the_built_nlp(data, 5)


def test_transcription_size_counts_every_kind_of_path_constraint():
    # the path constraints were left out of the count: 50 sensors and 100 polygons of 64 vertices were taken for
    # the unconstrained NLP's 3e6 non-zeros, and the build ran out of a 4 GB address space after 107 s (red team);
    # the rows are exact, the non-zeros measured +3 % here
    data = hussein2008(collocation={"intervals": 4})
    s0 = data["sensors"][0]
    data["sensors"] = [{**s0, "name": f"s{i}", "p0": [20.0 + 3 * i, 20.0], "v0": [0.0, 0.0]} for i in range(3)]
    data["constraints"] = {"keep_out": [{"center": [-30.0, -30.0], "radius": 1.0},
                                        {"polygon": [[-20, -40], [-15, -40], [-15, -35], [-17, -33], [-20, -35]]}],
                           "min_separation": 0.5, "max_speed": 50.0,
                           "workspace": {"x": [-100, 100], "y": [-100, 100]}}  # fmt: skip
    _check_size_against_the_built_nlp(data, 4)


def test_a_constrained_problem_too_large_to_build_is_refused_before_anything_is_allocated(tmp_path, capsys):
    from mobisense import cli

    data = hussein2008(collocation={"intervals": 20})
    s0 = data["sensors"][0]
    data["sensors"] = [{**s0, "name": f"s{i}", "p0": [20.0 + 3 * i, 20.0], "v0": [0.0, 0.0]} for i in range(50)]
    square = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
    data["constraints"] = {"keep_out": [{"polygon": [[x - 60.0 + 3 * k, y - 60.0] for x, y in square]}
                                        for k in range(100)], "min_separation": 0.5}  # fmt: skip
    path = tmp_path / "p.yaml"
    path.write_text(yaml.safe_dump(data))
    out = tmp_path / "out"
    code = cli.main(["solve", str(path), "--out", str(out), "--no-plot", "--quiet", "--max-memory", "2G"])
    err = capsys.readouterr().err
    assert code == 2 and "too large: the direct-collocation NLP" in err and "6225 path-constraint rows per node" in err
    assert "fewer keep-out zones or polygon vertices" in err and not out.exists()


def test_output_folder_checks(tmp_path):
    (tmp_path / "file").write_text("x")
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    for path, words in ((tmp_path / "file", "not a folder"), (tmp_path / "file" / "x", "which is a file"),
                        (tmp_path / "dangling", "symbolic link"), (tmp_path / "dangling" / "x", "dangling"),
                        ("/proc/self/x", "virtual file system")):  # fmt: skip
        with pytest.raises(ConfigError, match=words):
            OutputFolder.check(path)
    assert not (tmp_path / "new").exists()
    OutputFolder.check(tmp_path / "new" / "deeper")  # creates nothing
    assert not (tmp_path / "new").exists()


def test_lock_is_exclusive_cleans_temporaries_and_leaves_nothing_on_invalid_input(tmp_path):
    out = tmp_path / "a" / "b"
    with OutputFolder.check(out).lock():
        assert (out / LOCK_NAME).read_text().strip() == str(os.getpid())
        with pytest.raises(ConfigError, match=f"in use by another mobisense run \\(pid {os.getpid()}\\)"):
            with OutputFolder.check(out).lock():
                pass
        (out / "result.nc").write_text("written")
    assert not (out / LOCK_NAME).exists()
    (out / ".summary.json.abcd1234.tmp").write_text("half")
    (out / ".keep.tmp").write_text("not ours")
    with OutputFolder.check(out).lock():
        assert not (out / ".summary.json.abcd1234.tmp").exists() and (out / ".keep.tmp").exists()
    fresh = tmp_path / "fresh" / "out"
    with pytest.raises(ConfigError):
        with OutputFolder.check(fresh).lock():
            raise ConfigError("found late")
    assert not (tmp_path / "fresh").exists()
    # a run that ends without writing (a simulation that diverged: exit 1) leaves no folder it created …
    with OutputFolder.check(fresh).lock():
        pass
    assert not (tmp_path / "fresh").exists()
    # … and a folder that was there before stays, empty or not
    fresh.mkdir(parents=True)
    with OutputFolder.check(fresh).lock():
        pass
    assert fresh.is_dir()


def test_default_output_folder_is_sanitised():
    assert str(default_output_folder("problems/hussein2008.yaml")) == "out/hussein2008"
    assert str(default_output_folder("..yaml")) == "out/output"
    assert str(default_output_folder("a b/../c;rm -rf.yaml")) == "out/c_rm_-rf"


def test_an_output_folder_holding_an_input_under_an_output_name_is_refused_before_anything_runs(tmp_path, capsys):
    # red team: `solve summary.json --out .` replaced the problem file by the summary; a plan replay of
    # kosol/solution.nc with --out kosol replaced the user's solution (and its summary) by another problem's
    from mobisense import cli

    data = yaml.safe_load((PROBLEMS / "hussein2008.yaml").read_text())
    problem = tmp_path / "summary.json"
    problem.write_text(json.dumps(data))
    before = problem.read_bytes()
    assert cli.main(["solve", str(problem), "--out", str(tmp_path), "--no-plot"]) == 2
    err = capsys.readouterr().err
    assert "holds the input" in err and "summary.json" in err and len(err.strip().splitlines()) == 1
    assert problem.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["summary.json"]

    kept = tmp_path / "kosol"
    small = {**data, "solver": {**data["solver"], "collocation": {"intervals": 10}}}
    (tmp_path / "small.yaml").write_text(yaml.safe_dump(small))
    assert cli.main(["solve", str(tmp_path / "small.yaml"), "--out", str(kept), "--no-plot", "--quiet"]) == 0
    capsys.readouterr()
    before = {p.name: p.read_bytes() for p in kept.iterdir()}
    (tmp_path / "h.yaml").write_text(yaml.safe_dump(data))  # another problem: the replay would solve it again
    scenario = tmp_path / "pr.yaml"
    scenario.write_text(yaml.safe_dump({"name": "pr", "solution": "kosol/solution.nc", "problem": "h.yaml",
                                        "monte_carlo": {"runs": 2}}))  # fmt: skip
    assert cli.main(["replay", str(scenario), "--out", str(kept), "--no-plot"]) == 2
    err = capsys.readouterr().err
    assert "holds the input" in err and "solution.nc" in err and len(err.strip().splitlines()) == 1
    assert {p.name: p.read_bytes() for p in kept.iterdir()} == before
    # an input beside the outputs under a name no command writes is no clash: problems/x.yaml --out problems/
    assert OutputFolder.check(tmp_path, inputs=input_files(tmp_path / "small.yaml")).path == tmp_path
