"""``mobisense replay`` on a ``kind: replan`` file: outputs, and bad input (exit 2 with the key path)."""

from __future__ import annotations

import json

import pytest
import yaml
from reference_problems import PROBLEMS

from mobisense import cli


def _files(tmp_path, **replan):
    data = yaml.safe_load((PROBLEMS / "hussein2008.yaml").read_text())
    data["solver"]["collocation"]["intervals"] = 20
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(data))
    scenario = {
        "kind": "replan",
        "problem": "p.yaml",
        "replan": {"every": 2.5, "horizon": "shrinking", **replan},
        "disturbance": {"drift": [0.3, -0.2], "force_noise_std": 0.05, "seed": 1},
        "monte_carlo": {"runs": 2, "time_step": 0.02},
    }
    path = tmp_path / "replan.yaml"
    path.write_text(yaml.safe_dump(scenario))
    return path


@pytest.mark.slow
def test_replan_file_writes_summary_result_and_figure(tmp_path) -> None:
    out = tmp_path / "out"
    assert cli.main(["replay", str(_files(tmp_path)), "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    for name in ("closed_loop", "open_loop", "no_control"):
        assert set(s[name]) == {"cost_mean", "cost_std", "cost_stderr"}
    assert s["replan_every_s"] == 2.5 and s["replan_solve_time_s"]["max"] > 0
    assert {"result.nc", "replan.png"} <= set(s["files"])


def test_receding_horizon_is_rejected_with_the_key_path(tmp_path, capsys) -> None:
    out = tmp_path / "out"
    assert cli.main(["replay", str(_files(tmp_path, horizon="receding")), "--out", str(out)]) == 2
    assert "replan.horizon" in capsys.readouterr().err and not out.exists()
