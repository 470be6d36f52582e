"""Figure workers draw the files that drawing in process writes, report their errors, and leave nothing behind."""

from __future__ import annotations

import signal
import time

import pytest
import short_runs

from mobisense.core.errors import OutputError
from mobisense.ocp.figure_workers import FigureWorkers, figure_worker_count
from mobisense.ocp.plots import save_figures


@pytest.fixture(scope="module")
def solution():
    return short_runs.small_solution("direct")


def test_workers_write_the_bytes_drawing_in_process_writes(solution, tmp_path):
    expected = save_figures(solution, tmp_path / "here")
    with FigureWorkers(2) as workers:
        shares = workers.send(solution, tmp_path / "workers")
        written = workers.wait()
    assert len(shares) == 2 and all(shares)  # two drawing processes (the worker and its fork)
    assert [p.name for p in written] == [p.name for p in expected]  # same files, in the figures' order
    for here, there in zip(expected, written, strict=True):
        assert here.read_bytes() == there.read_bytes()  # same code, same Agg renderer: identical PNG files


def test_selected_figures_and_no_workers(solution, tmp_path):
    with FigureWorkers(0) as workers:  # one core: drawn in this process
        workers.send(solution, tmp_path / "inline", ["covariance"])
        assert [p.name for p in workers.wait()] == ["covariance.png"]
    with FigureWorkers(3) as workers:  # more processes allowed than figures: one each
        assert workers.send(solution, tmp_path / "some", ["paths", "controls"]) == [["paths.png"], ["controls.png"]]
        assert sorted(p.name for p in workers.wait()) == ["controls.png", "paths.png"]
    assert sorted(p.name for p in (tmp_path / "some").iterdir()) == ["controls.png", "paths.png"]


def test_a_worker_that_cannot_write_reports_the_file(solution, tmp_path):
    blocked = tmp_path / "not-a-folder"
    blocked.write_text("a file where the folder should be")
    with FigureWorkers(2) as workers, pytest.raises(OutputError, match="not-a-folder.*cannot be written"):
        workers.send(solution, blocked)
        workers.wait()


def test_a_worker_that_died_is_reported_with_its_exit_status(solution, tmp_path):
    with FigureWorkers(1) as workers:
        workers.process.send_signal(signal.SIGKILL)
        workers.process.wait()
        workers.send(solution, tmp_path)
        with pytest.raises(RuntimeError, match=r"a figure worker failed \(exit -9\)"):
            workers.wait()


def test_ending_the_workers_mid_drawing_leaves_no_temporary_files(solution, tmp_path):
    with FigureWorkers(2) as workers:
        time.sleep(1.5)  # the imports are done: the workers are drawing when they are ended
        workers.send(solution, tmp_path)
        time.sleep(0.2)
    assert workers.process is None  # ended and reaped (its drawing processes by it)
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")] == []


def test_worker_count():
    assert figure_worker_count(cpus=1) == 0 and figure_worker_count(cpus=2) == 2 and figure_worker_count(cpus=64) == 4
    assert figure_worker_count(1, cpus=8) == 1 and figure_worker_count(3, cpus=2) == 2
