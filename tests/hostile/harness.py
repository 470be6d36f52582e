"""Running ``mobisense`` as a hostile user would: a subprocess under a memory cap and a time limit, classified.

:func:`attack` runs one command line in a fresh folder and returns an :class:`Outcome` whose ``verdict`` is one
of the columns of the closing table of the issue — ``clean exit 2``, ``expected exit 1``, ``expected exit 0``
(or 130 for a signal) when the run behaved, else ``traceback`` (a Python traceback or an internal error),
``hang`` (the time limit), ``wrong result`` (another exit status, a message that does not name the key, more
than one line) or ``file left behind`` (an output folder, a lock or a temporary file after an exit 2, or a
temporary file after any run). Every outcome is recorded for the table printed at the end of the session.
"""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

#: address-space cap of each run (bytes): the interpreter with CasADi, dask and numpy maps ~0.5 GB
MEMORY_CAP = 4 * 2**30
#: wall-clock limit of each run (s) unless a case says otherwise; a run that exceeds it is a hang
TIME_LIMIT = 90.0
#: command -> verdict -> count, for the table (filled by every :func:`attack`)
RECORD: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
VERDICTS = ("clean exit 2", "expected exit 1", "expected exit 0/130", "traceback", "hang", "wrong result",
            "file left behind")  # fmt: skip
GOOD = VERDICTS[:3]
#: ``expect`` of a valid input that may be solved (0) or fail numerically (1, one line), never anything else
EITHER = -1


@dataclass
class Outcome:
    """What one hostile run did."""

    command: str
    code: int | None
    stdout: str
    stderr: str
    seconds: float
    verdict: str = ""
    problems: list[str] = field(default_factory=list)

    @property
    def lines(self) -> list[str]:
        """Non-empty stderr lines that are not warnings."""
        return [line for line in self.stderr.splitlines() if line.strip() and "warning:" not in line]


def _limits(memory: int) -> None:
    resource.setrlimit(resource.RLIMIT_AS, (memory, memory))
    os.setsid()  # own process group: a signal test can reach every worker, like Ctrl-C in a terminal


def start(args: list[str], cwd: Path, memory: int = MEMORY_CAP, env: dict[str, str] | None = None) -> subprocess.Popen:
    """Start ``mobisense ARGS`` in ``cwd`` under the memory cap (for the signal tests)."""
    environment = {**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})}
    environment.pop("MOBISENSE_TRACEBACK", None)
    return subprocess.Popen(
        [sys.executable, "-m", "mobisense.cli", *map(str, args)],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=environment,
        preexec_fn=lambda: _limits(memory),
    )


def finish(process: subprocess.Popen, limit: float) -> tuple[int | None, str, str, float]:
    """Wait for ``process`` at most ``limit`` seconds (then kill its process group): code, out, err, seconds."""
    t0 = time.monotonic()
    try:
        out, err = process.communicate(timeout=limit)
        code: int | None = process.returncode
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        out, err = process.communicate()
        code = None
    return code, out, err, time.monotonic() - t0


def temporaries(folder: Path) -> list[Path]:
    """Temporary and lock files left anywhere under ``folder``."""
    return [p for p in folder.rglob(".*") if p.name.endswith(".tmp") or p.name == ".mobisense.lock"]


def classify(
    outcome: Outcome,
    expect: int,
    mentions: tuple[str, ...],
    folder: Path,
    out: Path | None,
    one_line: bool = True,
    others: tuple[Path, ...] = (),
) -> Outcome:
    """Set ``outcome.verdict`` (and ``problems``) from the exit status, messages and files left."""
    problems = outcome.problems
    if outcome.code is None:
        outcome.verdict = "hang"
        return outcome
    if outcome.code == -signal.SIGINT:
        # Killed by SIGINT after reporting: CPython re-raises SIGINT at exit when a KeyboardInterrupt passed
        # through C code that ran Python (an import inside an extension), even though mobisense caught it. A
        # shell reports both as status 130, so the status a user sees is the documented one.
        outcome.code = 130
    text = outcome.stderr + outcome.stdout
    if "Traceback (most recent call last)" in text or "internal error" in text or outcome.code not in (0, 1, 2, 130):
        outcome.verdict = "traceback"
        problems.append(outcome.stderr[-800:])
        return outcome
    if expect == EITHER and outcome.code in (0, 1):
        expect = outcome.code  # a valid input whose numbers may defeat the solver: solved, or a clean failure
    if outcome.code != expect:
        problems.append(f"exit {outcome.code}, expected {expect}: {outcome.stderr[-400:]}")
    if expect in (1, 2) and one_line and len(outcome.lines) != 1:
        problems.append(f"expected one line on stderr, got {len(outcome.lines)}: {outcome.stderr[-400:]}")
    for word in mentions:
        if word not in text:
            problems.append(f"the message does not mention {word!r}: {outcome.stderr[-400:]}")
    if problems:
        outcome.verdict = "wrong result"
        return outcome
    left = [p for p in temporaries(folder) if p not in others]
    if expect == 2 and out is not None and out.exists():
        left.append(out)
    if expect == 2 and (folder / "out").exists():
        left.append(folder / "out")
    if left:
        outcome.verdict = "file left behind"
        problems.append(f"left behind: {[str(p) for p in left]}")
        return outcome
    outcome.verdict = {2: "clean exit 2", 1: "expected exit 1"}.get(expect, "expected exit 0/130")
    return outcome


def attack(
    command: str,
    args: list[str],
    folder: Path,
    expect: int,
    mentions: tuple[str, ...] = (),
    out: Path | None = None,
    limit: float = TIME_LIMIT,
    memory: int = MEMORY_CAP,
    one_line: bool = True,
    others: tuple[Path, ...] = (),
) -> Outcome:
    """Run ``mobisense ARGS`` in ``folder``, classify and record it under ``command``.

    ``others`` are files another (live) process holds, such as its lock: not left behind by this run.
    """
    code, stdout, stderr, seconds = finish(start(args, folder, memory), limit)
    outcome = Outcome(command, code, stdout, stderr, seconds)
    outcome = classify(outcome, expect, mentions, folder, out, one_line, others)
    RECORD[command][outcome.verdict] += 1
    return outcome


def table() -> str:
    """The closing table: cases per command and verdict."""
    header = "| command | cases | " + " | ".join(VERDICTS) + " |"
    rule = "|" + "---|" * (len(VERDICTS) + 2)
    rows = [header, rule]
    totals: dict[str, int] = defaultdict(int)
    for command in sorted(RECORD):
        counts = RECORD[command]
        n = sum(counts.values())
        totals["cases"] += n
        for v in VERDICTS:
            totals[v] += counts.get(v, 0)
        rows.append(f"| {command} | {n} | " + " | ".join(str(counts.get(v, 0)) for v in VERDICTS) + " |")
    rows.append(f"| all | {totals['cases']} | " + " | ".join(str(totals[v]) for v in VERDICTS) + " |")
    return "\n".join(rows)
