"""Every figure a command writes has labelled axes and legend entries that can be seen.

The figures are written by the commands' own code (``save_figures``, ``SimulationResult.plot`` …) from
short runs of shipped examples, with :func:`mobisense.core.files.write_figure` replaced by a recorder
that checks each figure with :func:`figure_checks.figure_problems` (labels, colour-bar labels, legend
entries inside the axes and not hidden under other artists, measured in pixels) before saving it.
The checker itself is tested on a figure with exactly those defects, so it can fail.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pytest  # noqa: E402
import short_runs  # noqa: E402
from figure_checks import figure_problems  # noqa: E402


@pytest.fixture
def checked(monkeypatch):
    """Replace ``write_figure`` everywhere; return {file name: problems} of every figure written."""
    import mobisense.core.files as files

    original = files.write_figure
    found: dict[str, list[str]] = {}

    def write_checked(path, draw):  # noqa: ANN001, ANN202
        def draw_and_check():  # noqa: ANN202
            fig = draw()
            found[f"{Path(path).parent.name}/{Path(path).name}"] = figure_problems(fig)
            return fig

        original(path, draw_and_check)

    write_checked.recorder = True  # a module imported during an earlier test holds that test's recorder
    monkeypatch.setattr(files, "write_figure", write_checked)
    for name, module in list(sys.modules.items()):
        bound = getattr(module, "write_figure", None)
        if name.startswith("mobisense.") and (bound is original or getattr(bound, "recorder", False)):
            monkeypatch.setattr(module, "write_figure", write_checked)
    return found


def test_the_checker_finds_hidden_curves_markers_and_missing_labels():
    fig, ax = plt.subplots()
    t = np.linspace(0, 1, 50)
    ax.plot(t, t**2, lw=1, label="first")
    ax.plot(t, t**2 + 1e-9, lw=1, label="second, drawn over the first")
    ax.plot(0.5, 0.25, "s", ms=6, label="end")
    ax.plot(0.5, 0.25, "*", ms=14, label="star over the end")
    ax.plot([5.0], [5.0], "o", label="outside")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.legend()
    problems = figure_problems(fig)
    plt.close(fig)
    assert "axes 0 (untitled): no y label" in problems and "axes 0 (untitled): no x label" in problems
    assert any("'first' is hidden" in p for p in problems) and any("'end' is hidden" in p for p in problems)
    assert any("'outside' has no point" in p for p in problems)
    assert not any("'second" in p or "'star" in p for p in problems)


def _clean(found: dict[str, list[str]], expected: set[str]) -> None:
    assert expected <= set(found), f"figures not written: {expected - set(found)}"
    bad = {name: problems for name, problems in found.items() if problems}
    assert not bad, "\n".join(f"{n}: {p}" for n, ps in bad.items() for p in ps)


@pytest.mark.slow
def test_sweep_figures_a_line_for_one_key_a_heat_map_for_two(checked, tmp_path):
    from mobisense.ocp.batch.sweep_plots import plot_sweep, save_sweep_figures
    from mobisense.ocp.batch.sweep_runner import SweepResult

    one = pd.DataFrame({"cost.alpha": [0.001, 0.004, 0.016], "status": ["solved", "failed", "solved"],
                        "cost": [15.8, np.nan, 15.9]})  # fmt: skip
    two = pd.DataFrame({"cost.alpha": [0.001, 0.001, 0.004, 0.004],
                        "sensors[0].p0": [[10, 10], [10, -10], [10, 10], [10, -10]],
                        "status": ["solved"] * 4, "cost": [1.0, 2.0, 3.0, 4.0]})  # fmt: skip
    for vary, table, axes in ((["cost.alpha"], one, 1), (["cost.alpha", "sensors[0].p0"], two, 2)):
        fig = plot_sweep(table, vary)
        assert len(fig.axes) == axes  # a line; a heat map with its colour bar
        plt.close(fig)
        folder = tmp_path / f"{len(vary)}keys"
        save_sweep_figures(SweepResult(table, {"vary": vary, "mode": "grid"}, folder))
    _clean(checked, {"1keys/cost.png", "2keys/cost.png"})


@pytest.mark.slow
def test_solve_figures_direct_and_indirect(checked, tmp_path):
    from mobisense.ocp.plots import plot_covariance, save_figures

    direct = short_runs.small_solution()
    save_figures(direct, tmp_path / "direct")
    save_figures(short_runs.small_solution("indirect"), tmp_path / "indirect")
    names = ("paths.png", "covariance.png", "controls.png", "homotopy.png")
    _clean(checked, {f"direct/{n}" for n in names} | {f"indirect/{n}" for n in (*names, "continuation.png")})
    fig = plot_covariance(direct)
    assert len(fig.axes) == 1  # one process state: one panel, not the same curve twice
    assert any("no control" in t.get_text() for t in fig.axes[0].get_legend().get_texts())  # the baseline
    plt.close(fig)


@pytest.mark.slow
def test_field_figures(checked, tmp_path):
    from mobisense.ocp.plots import save_figures

    save_figures(short_runs.field_solution(), tmp_path / "field")
    _clean(checked, {f"field/{n}" for n in ("variance_maps.png", "trace.png", "controls.png", "homotopy.png")})


@pytest.mark.slow
def test_replay_figures(checked, tmp_path):
    field = short_runs.field_replay(tmp_path)
    field.plot(tmp_path / "field")
    short_runs.plan_replay(tmp_path, short_runs.small_solution()).plot(tmp_path / "plan")
    _clean(checked, {"field/paths.png", "field/z_estimate.png", "field/shape.png", "field/heading.png",
                     "plan/paths.png", "plan/covariance.png", "plan/nees.png"})  # fmt: skip


@pytest.mark.slow
def test_simulation_and_design_figures(checked, tmp_path):
    short_runs.leader_follower(tmp_path, "leader_follower_khepera", 0.5).plot(tmp_path / "ring")
    short_runs.leader_follower(tmp_path, "leader_follower_control3", 0.5).plot(tmp_path / "ramp")
    short_runs.distributed(tmp_path).plot(tmp_path / "distributed")
    short_runs.steady_state(tmp_path).plot(tmp_path / "design")
    _clean(checked, {"ring/paths.png", "ring/active_pairs.png", "ramp/references.png",
                     "ramp/formation_errors.png", "ramp/reference_point_errors.png", "ramp/deviation.png",
                     "distributed/paths.png", "distributed/estimates.png", "design/trace_contour.png"})  # fmt: skip


@pytest.mark.slow
def test_homotopy_figure_keeps_each_start_on_its_own_line(checked, tmp_path):
    """The steps of all starts used to be one line: a continuation stopped by its budget at ε = 0.4 was drawn
    joined to the cold solve at ε = 1, as if it had arrived there, and its stop marked as a failure."""
    from reference_problems import hussein2008

    import mobisense as ms
    from mobisense.ocp.plots import plot_homotopy, save_figures

    data = hussein2008(collocation={"intervals": 20}, homotopy={"step": 0.05}, strategy="homotopy")
    solution = ms.solve(ms.Problem.from_dict(data))
    record = solution.stats["strategy"]
    stopped = next(s for s in record["starts"] if s["start"] == "homotopy")
    assert stopped["status"] == "budget spent" and stopped["eps_reached"] < 1  # the case this test is about
    save_figures(solution, tmp_path / "budget", ["homotopy"])
    _clean(checked, {"budget/homotopy.png"})
    fig = plot_homotopy(solution)
    lines = {line.get_label(): np.asarray(line.get_xdata(), float) for line in fig.axes[0].get_lines()}
    assert set(lines["cold (kept): J_ε of its converged steps"]) == {1.0}
    # the default budget (1.5 × the cold solve's iterations) stops it at ε = 0.35 on this grid
    reached = stopped["eps_reached"]
    assert 0 < lines["homotopy: J_ε of its converged steps"].max() == pytest.approx(reached)
    assert reached < lines["homotopy: stopped, iteration budget spent"].max() < 1.0  # where it stopped, not ε = 1
    plt.close(fig)


def test_a_label_in_a_script_the_font_lacks_saves_without_a_warning(tmp_path):
    """A sweep over sensors[0].name: ["名前"] printed matplotlib's "Glyph … missing from font(s)" UserWarning
    (two lines per character) while cost.png was saved; the glyphs are drawn as boxes, silently."""
    import warnings

    from mobisense.core.files import write_figure

    def draw():  # noqa: ANN202
        fig, ax = plt.subplots()
        ax.plot([0, 1], [0, 1], label="名前")
        ax.legend()
        ax.set_xlabel("x")
        return fig

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        write_figure(tmp_path / "cjk.png", draw)
    assert (tmp_path / "cjk.png").stat().st_size > 0
    assert not [w for w in caught if "Glyph" in str(w.message)]
