"""Every ``mobisense …`` command shown in README.md runs (outputs redirected to a temporary folder)."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from mobisense import cli

pytestmark = pytest.mark.slow  # every test here runs solvers or subprocesses for seconds

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text(encoding="utf-8")
BLOCKS = re.findall(r"```(?:sh|bash|console)\n(.*?)```", README, flags=re.S)
COMMANDS = [line.strip() for block in BLOCKS for line in block.splitlines() if line.strip().startswith("mobisense ")]


def test_readme_starts_with_the_two_commands():
    first_block = BLOCKS[0].splitlines()
    assert first_block[0].startswith("make demo") and first_block[1].startswith("make test")


#: folders the README copies the examples into (``examples --copy DIR``): paths in them go to the test's folder
WORDS = [shlex.split(command, comments=True) for command in COMMANDS]
COPIED = {words[i + 1] for words in WORDS for i, word in enumerate(words) if word == "--copy"}
#: options whose argument is an output the test redirects into its temporary folder
OUTPUTS = ("--out", "--copy")


@pytest.mark.parametrize("command", COMMANDS)
def test_readme_command_runs(command, tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    args = shlex.split(command, comments=True)[1:]
    if any(a.split("/")[0] in COPIED for a in args if "/" in a):
        assert cli.main(["examples", "--copy", str(tmp_path / next(iter(COPIED)))]) == 0
    args = [
        str(tmp_path / Path(a).name) if i > 0 and args[i - 1] in OUTPUTS
        else str(tmp_path / a) if "/" in a and a.split("/")[0] in COPIED
        else a
        for i, a in enumerate(args)
    ]  # fmt: skip
    try:
        status = cli.main(args)
    except SystemExit as exit_:  # --version and --help exit from argparse
        status = exit_.code
    assert status == 0, command


PYTHON_BLOCKS = re.findall(r"```python\n(.*?)```", README, flags=re.S)


@pytest.mark.parametrize("block", PYTHON_BLOCKS, ids=[f"python-{i}" for i in range(len(PYTHON_BLOCKS))])
def test_readme_python_runs(block, tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    code = block.replace('"out/', f'"{tmp_path}/')
    exec(compile(code, "README.md", "exec"), {})  # noqa: S102  (the README's own example)
