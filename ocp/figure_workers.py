"""Figures drawn beside the solve: a worker process that imports matplotlib while the NLP is built and solved.

``mobisense solve`` spends ≈ 0.6 s importing matplotlib and the figure code and ≈ 0.12–0.3 s drawing and saving
each figure. Started before the solve, :class:`FigureWorkers` does the imports on a core the solver leaves
idle (Ipopt/MUMPS use one); once the solution is known the worker forks one drawing process per share of the
figures (the imports are done once, the forks share them) while the command writes ``solution.nc``. Each
figure is written atomically by the process that draws it, with the code of
:func:`mobisense.ocp.plots.save_figures` in one process, so the files are the same.

The worker is ``python -m mobisense.ocp.figure_workers``: it reads one pickled job (solution, folder, the
shares of figure names) from stdin and writes one JSON line on stdout (the files written, or the first error).
End of input without a job (the command failed or was interrupted) ends it quietly; SIGTERM and Ctrl-C end it
and its drawing processes, each removing its temporary files.
"""

from __future__ import annotations

import dataclasses
import json
import os
import pickle
import signal
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["FigureWorkers", "figure_worker_count"]

#: the most figures drawn at once (each drawing process is a fork of the worker; there are at most 5 figures)
MAX_WORKERS = 4


def figure_worker_count(figures: int | None = None, cpus: int | None = None) -> int:
    """Figures worth drawing at once: ``figures`` (default: all) on ``cpus`` cores (default: this machine's).

    The solver keeps one core busy and another imports matplotlib meanwhile; then the figures are drawn in
    parallel. On one core there is nothing to overlap: 0 (drawn in the command's process).
    """
    if cpus is None:
        cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    return 0 if cpus < 2 else min(cpus, MAX_WORKERS, figures or MAX_WORKERS)


class FigureWorkers:
    """A worker process started now that draws a solution's figures later, ``count`` at once.

    Use as a context manager: leaving it (normally, on an error or on Ctrl-C) ends the worker if it has not
    finished. With ``count = 0`` no process is started and :meth:`wait` draws in this process.
    """

    def __init__(self, count: int) -> None:
        self.count = count
        self.process: subprocess.Popen | None = None
        self._inline: tuple[Any, Path, list[str]] | None = None  # the job drawn here when there is no worker
        self._order: list[str] = []
        if count > 0:
            self.process = subprocess.Popen(
                [sys.executable, "-m", __name__],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                env={**os.environ, "MPLBACKEND": "Agg"},
            )

    def __enter__(self) -> FigureWorkers:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def send(self, solution: Any, folder: str | Path, names: Sequence[str] | None = None) -> list[list[str]]:
        """Hand the figures of ``solution`` to the worker; return the shares drawn at once (file names).

        ``names`` as in :func:`mobisense.ocp.plots.save_figures` (all figures by default). The figures are
        dealt in snake order (paths, covariance, controls, homotopy, continuation: 0 1 1 0 0 for two shares).
        Call :meth:`wait` for the files.
        """
        from .plots import figures_of

        figures = [n for n in figures_of(solution) if names is None or n.removesuffix(".png") in names]
        self._order = figures
        if self.process is None:
            self._inline = (solution, Path(folder), [n.removesuffix(".png") for n in figures])
            return [figures]
        shares: list[list[str]] = [[] for _ in range(self.count)]
        for i, name in enumerate(figures):  # snake order: the figures' costs even out
            turn, place = divmod(i, len(shares))
            shares[place if turn % 2 == 0 else len(shares) - 1 - place].append(name)
        shares = [share for share in shares if share]
        job = dataclasses.replace(solution, nlp=None)  # the NLP point (large) is not drawn
        payload = pickle.dumps((job, str(folder), [[n.removesuffix(".png") for n in s] for s in shares]))
        stdin, self.process.stdin = self.process.stdin, None  # closed here: communicate() only reads the answer
        try:
            assert stdin is not None
            stdin.write(payload)
            stdin.close()
        except BrokenPipeError:  # the worker died at start (its stderr says why): reported by wait()
            pass
        return shares

    def wait(self) -> list[Path]:
        """The files written (in the order of the figures); the error of any drawing process is raised here.

        Raises
        ------
        OutputError
            A figure could not be written (the message names the file).
        RuntimeError
            Drawing failed (the figure code's exception, named), or the worker died (its exit status).
        """
        if self.process is None:
            from .plots import save_figures

            if self._inline is None:
                return []
            solution, folder, names = self._inline
            return save_figures(solution, folder, names)
        out, err = self.process.communicate()
        reply = _reply(out, err, self.process.returncode)
        self.process = None
        if "error" in reply:
            from ..core.errors import OutputError

            raise (OutputError if reply.get("kind") == "OutputError" else RuntimeError)(reply["error"])
        written = [Path(p) for p in reply["written"]]
        return sorted(written, key=lambda p: self._order.index(p.name))  # every file is one of the figures sent

    def close(self) -> None:
        """End the worker if it still runs (SIGTERM: it ends its drawing processes, all remove temporaries)."""
        if self.process is None:
            return
        if self.process.poll() is None:
            self.process.terminate()
        try:
            self.process.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.communicate()
        self.process = None


def _reply(out: bytes, err: bytes, code: int | None) -> dict[str, Any]:
    lines = out.decode(errors="replace").strip().splitlines()
    try:
        return json.loads(lines[-1])
    except (IndexError, json.JSONDecodeError):
        detail = " ".join(err.decode(errors="replace").split())[-300:]
        return {"error": f"a figure worker failed (exit {code}): {detail or 'no message'}"}


def _terminated(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def _draw(solution: Any, folder: str, names: list[str]) -> dict[str, Any]:
    from .plots import save_figures

    try:
        return {"written": [str(p) for p in save_figures(solution, folder, names)]}
    except Exception as exc:  # noqa: BLE001  (sent to the command, which raises it)
        kind = type(exc).__name__
        return {"error": str(exc) if kind == "OutputError" else f"{kind}: {exc}", "kind": kind}


def _draw_shares(solution: Any, folder: str, shares: list[list[str]]) -> dict[str, Any]:
    """Draw the first share here and each other one in a fork of this process; merge the replies."""
    children: list[tuple[int, int]] = []
    try:
        for share in shares[1:] if hasattr(os, "fork") else []:
            read_end, write_end = os.pipe()
            pid = os.fork()
            if pid == 0:  # the drawing process: its reply through the pipe, then out without any clean-up
                os.close(read_end)
                try:
                    os.write(write_end, json.dumps(_draw(solution, folder, share)).encode())
                    os._exit(0)
                except BaseException:  # noqa: BLE001  (KeyboardInterrupt: its temporaries are removed)
                    os._exit(130)
            os.close(write_end)
            children.append((pid, read_end))
        here = shares if not children else shares[:1]
        replies = [_draw(solution, folder, [n for share in here for n in share])]
        while children:
            pid, read_end = children[0]
            with os.fdopen(read_end, "rb") as pipe:
                data = pipe.read()
            _, status = os.waitpid(pid, 0)
            children.pop(0)
            code = os.waitstatus_to_exitcode(status)
            replies.append(json.loads(data) if data else {"error": f"a figure process ended with status {code}"})
    finally:
        for pid, read_end in children:  # interrupted: end the drawing processes, wait for their clean-up
            os.kill(pid, signal.SIGTERM)
            os.waitpid(pid, 0)
            os.close(read_end)
    errors = [r for r in replies if "error" in r]
    return errors[0] if errors else {"written": [p for r in replies for p in r["written"]]}


def main() -> int:
    """The worker: import, read the job, draw, answer."""
    signal.signal(signal.SIGTERM, _terminated)  # raise, so that atomic writes remove their temporaries
    try:
        import matplotlib.pyplot  # noqa: F401  (the import this process exists to do early)

        from . import plots  # noqa: F401

        data = sys.stdin.buffer.read()
        if not data:  # the command ended without a solution
            return 0
        solution, folder, shares = pickle.loads(data)  # noqa: S301  (written by the command's process)
        reply = _draw_shares(solution, folder, shares)
        print(json.dumps(reply), flush=True)
        return 1 if "error" in reply else 0
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
