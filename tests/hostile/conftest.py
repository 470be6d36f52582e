"""Prints the closing table of the hostile-input suite (cases per command and verdict) after the session."""

from __future__ import annotations

import os

from hostile.harness import RECORD, table


def pytest_terminal_summary(terminalreporter, exitstatus, config):  # noqa: D103
    if not RECORD:
        return
    text = table()
    terminalreporter.write_sep("=", "hostile inputs: cases per command and verdict")
    terminalreporter.write_line(text)
    target = os.environ.get("MOBISENSE_HOSTILE_TABLE")
    if target:
        with open(target, "w", encoding="utf-8") as f:
            f.write(text + "\n")
