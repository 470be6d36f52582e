"""Hostile input files against every command: each a subprocess under a memory cap and a time limit.

Every attack must end in exit status 2 with ONE line naming the file and, where the attack targets a key, its
key path; no traceback, nothing written, no temporary file; within the time limit and the memory cap.
"""

from __future__ import annotations

import codecs
import os
import random

import pytest
import yaml
from hostile.harness import GOOD, attack
from hostile.inputs import KINDS, Kind

pytestmark = pytest.mark.slow  # each case starts a Python process (~1 s)


def _bomb() -> str:
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x]"]
    for i in range(1, 10):
        refs = ", ".join([f"*a{i - 1}"] * 9)
        lines.append(f"a{i}: &a{i} [{refs}]")
    return "\n".join(lines) + "\nname: *a9\n"


def _typo_text(kind: Kind) -> str:
    return yaml.safe_dump(kind.misspelled(), sort_keys=False)


def _random_bytes() -> bytes:
    rng = random.Random(12)
    return bytes(rng.randrange(256) for _ in range(4096))


#: attack -> (content of the input file from the kind, expected exit status, what the message must mention)
ATTACKS = {
    "random bytes": (lambda k: _random_bytes(), 2, lambda k: ("input.yaml",)),
    "latin-1 text": (lambda k: "name: température 25°C\n".encode("latin-1"), 2, lambda k: ("not UTF-8",)),
    "NUL byte": (lambda k: b"name: a\x00b\n", 2, lambda k: ("binary data",)),
    "UTF-16 with BOM (decoded)": (lambda k: codecs.BOM_UTF16_LE + _typo_text(k).encode("utf-16-le"), 2,
                                  lambda k: (k.message,)),
    "UTF-32 with BOM (decoded)": (lambda k: codecs.BOM_UTF32_BE + _typo_text(k).encode("utf-32-be"), 2,
                                  lambda k: (k.message,)),
    "UTF-16 without BOM": (lambda k: _typo_text(k).encode("utf-16-le"), 2, lambda k: ("input.yaml",)),
    "CRLF line ends (decoded)": (lambda k: _typo_text(k).replace("\n", "\r\n"), 2, lambda k: (k.message,)),
    "50 000 nested [": (lambda k: "a: " + "[" * 50_000, 2, lambda k: ("nest",)),
    "alias bomb": (lambda k: _bomb(), 2, lambda k: ("alias",)),
    "recursive alias": (lambda k: "a: &a [1, *a]\n", 2, lambda k: ("recursive alias",)),
    "9 MiB file": (lambda k: "# " + "x" * (9 * 2**20) + "\n", 2, lambda k: ("MiB",)),
    "empty file": (lambda k: "", 2, lambda k: ("empty",)),
    "top-level list": (lambda k: "- a\n- b\n", 2, lambda k: ("expected a mapping",)),
    "tab indentation": (lambda k: "cost:\n\talpha: 1\n", 2, lambda k: ("invalid YAML",)),
    "duplicate key": (lambda k: yaml.safe_dump(k.data(), sort_keys=False) + f"{k.top}: null\n", 2,
                      lambda k: (f"{k.top}: duplicate key",)),
    "misspelled required key": (lambda k: k.misspelled(), 2, lambda k: (k.message,)),
    "boolean for a number": (lambda k: k.text_with("true"), 2, lambda k: (k.number_path, "boolean")),
    "numeric string": (lambda k: k.text_with("'0.5'"), 2, lambda k: (k.number_path, "remove the quotes")),
    "400-digit integer": (lambda k: k.text_with("1" + "0" * 400), 2, lambda k: (k.number_path, "out of range")),
    "1e400": (lambda k: k.text_with("1e400"), 2, lambda k: (k.number_path, "floating-point range")),
    ".nan": (lambda k: k.text_with(".nan"), 2, lambda k: (k.number_path, "finite")),
    "1e300": (lambda k: k.text_with("1.0e+300"), 2, lambda k: (k.number_path,)),
    "python tag": (lambda k: "a: !!python/object/apply:os.system ['echo hacked']\n", 2,
                   lambda k: ("unsupported tag",)),
    "10 MB key name": (lambda k: {**k.data(), "k" * 100_000: 1}, 2, lambda k: ("unknown key",)),
}  # fmt: skip


@pytest.mark.parametrize("attack_name", list(ATTACKS))
@pytest.mark.parametrize("kind_name", list(KINDS))
def test_hostile_file(tmp_path, kind_name, attack_name):
    kind = KINDS[kind_name]
    make, expect, mentions = ATTACKS[attack_name]
    path = kind.write(tmp_path, make(kind))
    out = tmp_path / "result"
    outcome = attack(kind.name, kind.command(path, out), tmp_path, expect, ("input.yaml", *mentions(kind)), out)
    assert outcome.verdict in GOOD, outcome.problems
    assert len(outcome.lines[0]) < 700, outcome.lines[0]  # a value is never printed whole


@pytest.mark.parametrize("kind_name", list(KINDS))
def test_input_is_a_directory_or_missing(tmp_path, kind_name):
    kind = KINDS[kind_name]
    kind.write(tmp_path)
    (tmp_path / "folder.yaml").mkdir()
    for name, words in (("folder.yaml", ("is a directory",)), ("missing.yaml", ("file not found",))):
        out = tmp_path / "result"
        outcome = attack(kind.name, kind.command(tmp_path / name, out), tmp_path, 2, (name, *words), out)
        assert outcome.verdict in GOOD, outcome.problems


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes on this system")
def test_a_pipe_without_writer_reads_as_empty(tmp_path):
    kind = KINDS["validate"]
    os.mkfifo(tmp_path / "pipe.yaml")
    outcome = attack(kind.name, kind.command(tmp_path / "pipe.yaml", None), tmp_path, 2, ("empty",), limit=30)
    assert outcome.verdict in GOOD, outcome.problems
