"""The one reader of input files (core/reader.py) and the strict models (core/config.py), in process."""

from __future__ import annotations

import codecs
import time

import pytest
from pydantic import Field

from mobisense.core.config import ConfigError, FiniteFloat, PositiveFloat, StrictModel, format_location, parse_config
from mobisense.core.errors import brief
from mobisense.core.reader import MAX_DEPTH, MAX_NODES, parse_document, read_document


def parse(text: str):
    return parse_document(text, "f.yaml")


def refused(text: str) -> str:
    with pytest.raises(ConfigError) as err:
        parse(text)
    message = str(err.value)
    assert "\n" not in message and message.startswith("f.yaml:")
    return message


def test_yaml_12_core_scalars():
    data = parse("a: 1e-3\nb: yes\nc: 010\nd: 1:30\ne: true\nf: ~\ng: 0x1F\nh: .inf\ni: '1'\non: 3\nj: 2024-01-01\n")
    assert data == {"a": 0.001, "b": "yes", "c": 10, "d": "1:30", "e": True, "f": None, "g": 31,
                    "h": float("inf"), "i": "1", "on": 3, "j": "2024-01-01"}  # fmt: skip


def test_merge_keys_explicit_wins():
    assert parse("d: &d {x: 1, y: 2}\ne: {<<: *d, y: 3}\n")["e"] == {"x": 1, "y": 3}


def test_duplicate_key_names_its_path_and_lines():
    message = refused("cost:\n  alpha: 1\n  M: 2\n  alpha: 3\n")
    assert "cost.alpha: duplicate key (lines 2 and 4)" in message


def test_alias_bomb_is_refused_while_composing():
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x]"]
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 10)]
    t0 = time.perf_counter()
    message = refused("\n".join(lines) + "\nname: *a9\n")
    # 9^9 ≈ 3.9e8 nodes expanded; refused after ~MAX_NODES counted, in milliseconds (no object is built)
    assert f"more than {MAX_NODES} values" in message and time.perf_counter() - t0 < 1.0


def test_recursive_alias_and_deep_nesting():
    assert "recursive alias" in refused("a: &a [1, *a]\n")
    assert "nest" in refused("a: " + "[" * 50_000)
    assert f"nested more than {MAX_DEPTH}" in refused("a: " + "[" * 100 + "]" * 100)
    deep = "a: &a " + "[" * 40 + "1" + "]" * 40 + "\nb: " + "[" * 30 + "*a" + "]" * 30 + "\n"
    assert "aliases expanded" in refused(deep)


def test_numbers_out_of_range_and_tags():
    assert "out of range" in refused("a: " + "9" * 5000 + "\n")
    assert "out of range" in refused("a: 9223372036854775808\n")
    assert "floating-point range" in refused("a: 1e400\n")
    assert "unsupported tag" in refused("a: !!python/object/apply:os.system [ls]\n")
    assert "unsupported tag" in refused("a: !!binary aGVsbG8=\n")
    assert "expected a name as key" in refused("? [a, b]\n: 1\n")


def test_encodings(tmp_path):
    text = "name: café\n"
    for bom, encoding in ((codecs.BOM_UTF8, "utf-8"), (codecs.BOM_UTF16_LE, "utf-16-le"),
                          (codecs.BOM_UTF16_BE, "utf-16-be"), (codecs.BOM_UTF32_LE, "utf-32-le"),
                          (codecs.BOM_UTF32_BE, "utf-32-be")):  # fmt: skip
        path = tmp_path / f"{encoding}.yaml"
        path.write_bytes(bom + text.encode(encoding))
        assert read_document(path) == {"name": "café"}
    latin = tmp_path / "latin.yaml"
    latin.write_bytes("x: 1\nname: café\n".encode("latin-1"))
    with pytest.raises(ConfigError, match=r"line 2: not UTF-8 text \(byte 0xe9"):
        read_document(latin)
    nul = tmp_path / "nul.yaml"
    nul.write_bytes(b"a: 1\x00\n")
    with pytest.raises(ConfigError, match="binary data"):
        read_document(nul)


def test_files_that_are_not_files(tmp_path):
    with pytest.raises(ConfigError, match="is a directory"):
        read_document(tmp_path)
    with pytest.raises(ConfigError, match="file not found"):
        read_document(tmp_path / "missing.yaml")
    (tmp_path / "link.yaml").symlink_to(tmp_path / "nowhere")
    with pytest.raises(ConfigError, match="broken symbolic link"):
        read_document(tmp_path / "link.yaml")
    big = tmp_path / "big.yaml"
    big.write_bytes(b"#" * (9 * 2**20))
    with pytest.raises(ConfigError, match="MiB"):
        read_document(big)


def test_json_inputs(tmp_path):
    path = tmp_path / "summary.json"
    path.write_text('{"a": 1.5, "b": [1, 2]}')
    assert read_document(path) == {"a": 1.5, "b": [1, 2]}
    path.write_text('{"a": 1, "a": 2}')
    with pytest.raises(ConfigError, match="a: duplicate key"):
        read_document(path)
    path.write_text('{"a": NaN}')
    with pytest.raises(ConfigError, match="not a JSON number"):
        read_document(path)
    path.write_text("[" * 100_000)
    with pytest.raises(ConfigError, match="nested|invalid JSON"):
        read_document(path)
    # integers as in YAML (64 bits), with their key path; 5000 digits would make int() itself raise
    path.write_text('{"cost": {"alpha": [1, -99999999999999999999]}, "name": 1' + "0" * 5000 + "}")
    with pytest.raises(ConfigError, match=r"summary.json: (cost.alpha\[1\]|name): integer .* is out of range"):
        read_document(path)
    path.write_text('{"a": [9223372036854775807, -9223372036854775807]}')
    assert read_document(path) == {"a": [2**63 - 1, -(2**63 - 1)]}


def test_a_pipe_whose_writer_never_finishes_is_refused_in_bounded_time(tmp_path, monkeypatch):
    import os
    import threading

    import mobisense.core.input_text as input_text

    monkeypatch.setattr(input_text, "PIPE_TIMEOUT", 0.3)
    fifo = tmp_path / "f.yaml"
    os.mkfifo(fifo)
    opened = threading.Event()

    def idle_writer() -> None:  # opens the pipe, writes a little, then neither writes nor closes for 2 s
        with open(fifo, "w") as f:
            f.write("name: x\n")
            f.flush()
            opened.set()
            time.sleep(2.0)

    thread = threading.Thread(target=idle_writer, daemon=True)
    thread.start()
    # a first reader lets the writer's open() return, so the pipe has a writer when read_document opens it
    # (a pipe without a writer reads as empty, another case)
    keep = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    try:
        assert opened.wait(5.0)
        t0 = time.monotonic()
        with pytest.raises(ConfigError, match=r"f.yaml: no end of the data within 0.3 s"):
            read_document(fifo)
        assert time.monotonic() - t0 < 1.5  # not the writer's 2 s
    finally:
        os.close(keep)
    thread.join()


class Inner(StrictModel):
    alpha: PositiveFloat
    beta: FiniteFloat = 1.0


class Outer(StrictModel):
    cost: Inner
    count: int = Field(1, ge=1, le=10)
    flag: bool = False


def message(data) -> str:
    with pytest.raises(ConfigError) as err:
        parse_config(data, Outer, "f.yaml")
    return str(err.value)


def test_strict_scalars():
    assert "cost.alpha: expected a valid number (got True, a boolean)" in message({"cost": {"alpha": True}})
    assert "remove the quotes" in message({"cost": {"alpha": "0.1"}})
    assert "count: expected a valid integer" in message({"cost": {"alpha": 1.0}, "count": 2.0})
    assert "flag: expected a valid boolean" in message({"cost": {"alpha": 1.0}, "flag": "yes"})


def test_magnitudes():
    assert "magnitude" in message({"cost": {"alpha": 1e300}})
    assert "magnitude" in message({"cost": {"alpha": 1e-300}})
    assert parse_config({"cost": {"alpha": 1.0, "beta": 0.0}}, Outer).cost.beta == 0.0


def test_misspelled_required_key_is_reported_as_such():
    # issue 13: not "cost.alpha: required key is missing (and 1 more problem)"
    assert message({"cost": {"alhpa": 1.0}}) == "f.yaml: cost.alhpa: unknown key; did you mean 'alpha'?"


def test_messages_never_print_a_whole_value():
    huge = list(range(10**6))
    text = message({"cost": {"alpha": huge}})
    assert len(text) < 200
    assert len(brief(huge)) <= 80 and len(brief("x" * 10**6)) <= 80
    long_key = message({"cost": {"alpha": 1.0}, "k" * 10**5: 1})
    assert len(long_key) < 400 and "100000 characters" in long_key


def test_union_tags_are_not_key_paths():
    from mobisense.formation.leader_follower.scenario import LeaderFollowerScenario

    loc = ("reference", "constant", "bearing")
    assert format_location(loc, LeaderFollowerScenario) == "reference.bearing"


def test_a_nul_escape_in_a_string_or_key_is_refused_where_it_is():
    """The reader refused NUL bytes in the file but not the escapes "\\0", "\\x00", "\\u0000" inside quoted
    strings: a leader-follower or distributed file named "a\\0b" validated, ran the whole simulation, then failed
    writing its results (HDF5 strings cannot hold NUL), exit 1 instead of 2. YAML and JSON alike."""
    for escape in ("\\0", "\\x00", "\\u0000"):
        message = refused(f'name: "a{escape}b"\nduration: 1\n')
        assert message == "f.yaml: name: a NUL character in 'a\u2400b'; expected text without it"
        message = refused(f'runs:\n  - {{"x{escape}": 1}}\n')
        assert message == "f.yaml: runs[0]: a NUL character in a key; expected a name without it"
    with pytest.raises(ConfigError, match=r"f.json: vary.names\[1\]: a NUL character"):
        parse_document('{"vary": {"names": ["a", "b\\u0000"]}}', "f.json", json_syntax=True)
    assert parse('name: "a\\tb"\n') == {"name": "a\tb"}  # other escapes are text as before


def test_a_union_names_every_alternative_and_a_mapping_is_said_to_be_one(tmp_path):
    # red team: "cost.M: expected a valid list (got the string 'median') (and 1 more problem)" hid the names
    # cost.M accepts; `problem: {a: 1}` said "expected a valid string" without what it got; --time-limit nan was
    # "expected less than or equal to 1000000000 (got nan)"
    from reference_problems import hussein2008

    from mobisense.core.input_text import missing_file
    from mobisense.ocp.problem import Problem

    data = hussein2008()
    data["cost"]["M"] = "median"
    with pytest.raises(ConfigError, match=r"^<dict>: cost\.M: expected a valid list, or 'mean', 'sum' or 'zero' "
                                          r"\(got the string 'median'\)$"):  # fmt: skip
        Problem.from_dict(data)
    data = hussein2008()
    data["sensors"].append({**data["sensors"][0], "name": "s2"})
    for sensor in data["sensors"]:
        sensor["measures"] = "area"
    with pytest.raises(ConfigError, match=r"sensors\[0\]\.measures: expected .*'point'.* \(and 1 more problem\)$"):
        Problem.from_dict(data)  # one problem per key path: the two sensors' branches count two, not four

    class Named(StrictModel):
        problem: str

    with pytest.raises(ConfigError, match=r"^f: problem: expected a valid string \(got a mapping\)$"):
        parse_config({"problem": {"a": 1}}, Named, "f")
    data = hussein2008()
    data["solver"]["time_limit"] = float("nan")
    with pytest.raises(ConfigError, match=r"solver\.time_limit: expected a finite number"):
        Problem.from_dict(data)
    # why a path is not a file to read, by kind
    (tmp_path / "folder").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "gone")
    assert missing_file(tmp_path / "nothing") == "file not found"
    assert missing_file(tmp_path / "folder").startswith("is a directory")
    assert missing_file(tmp_path / "link") == "broken symbolic link"
    assert missing_file("/dev/zero").startswith("is not a regular file")
