"""dump_mapping gives the text of the whole mapping emitted at once, character for character, with and without
remembered entries; on problem documents that is PyYAML's own safe_dump."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from mobisense.core import yaml_text
from mobisense.core.yaml_text import dump_mapping

# the whole mapping through the emitter dump_mapping uses (libyaml's when PyYAML has it — it differs from the
# pure-Python emitter on a few documents, e.g. an empty-string key: `'': x` against `? ''\n: x`)
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


def whole(doc) -> str:
    return yaml.dump(doc, Dumper=_DUMPER, sort_keys=False, allow_unicode=True)

# strings PyYAML quotes, folds, escapes or would read as another type
_STRINGS = [
    "", " ", "a", "yes", "No", "null", "~", "1.0", "0x1F", "1e3", "-", "- a", "a: b", "#c", "a #b", "'q'", '"q"',
    "line\nbreak", "tab\tin", "trailing ", " leading", "ü ß — ✓", "&anchor", "*alias", "!tag", "%d", "@x", "`x",
    "long " * 30, "x" * 100, "{a}", "[b]", "a,b", "?", ":", "\x07bell", "\ufeffbom", "2026-12-04", "12:30",
]  # fmt: skip


def _scalar(rng: np.random.Generator):
    kind = rng.integers(7)
    if kind == 0:
        return _STRINGS[rng.integers(len(_STRINGS))]
    if kind == 1:
        return int(rng.integers(-(10**6), 10**6)) * (10 ** int(rng.integers(0, 20)))
    if kind == 2:
        return float(rng.choice([0.0, -0.0, np.inf, -np.inf, np.nan, 1e300, 5e-324, 0.1, 1.0, 1e16]))
    if kind == 3:
        return float(rng.standard_normal() * 10.0 ** rng.integers(-12, 12))
    if kind == 4:
        return bool(rng.integers(2))
    if kind == 5:
        return None
    return "".join(chr(int(c)) for c in rng.integers(32, 0x2FF, rng.integers(0, 12)))


def _value(rng: np.random.Generator, depth: int):
    kind = rng.integers(4) if depth < 4 else 0
    if kind <= 1:
        return _scalar(rng)
    if kind == 2:
        return [_value(rng, depth + 1) for _ in range(rng.integers(0, 4))]
    return {_key(rng): _value(rng, depth + 1) for _ in range(rng.integers(0, 4))}


def _key(rng: np.random.Generator) -> str:
    return str(rng.choice(["name", "cost", "a", "b b", "yes", "1", "ü", "", "- k", "x" * 90]))


def test_random_documents_give_the_whole_text_also_when_entries_are_remembered():
    # 3000 documents of 1-6 entries drawn from a small pool of keys and values, so that most entries recur
    # (remembered text) and some differ by one value; each compared with the whole mapping emitted at once
    rng = np.random.default_rng(20261204)
    pool = [(_key(rng), _value(rng, 1)) for _ in range(60)]
    hits = 0
    for _ in range(3000):
        picks = rng.choice(len(pool), size=rng.integers(1, 7), replace=False)
        doc = {}
        for i in picks:
            key, value = pool[int(i)]
            doc[key] = value if rng.random() < 0.7 else _value(rng, 1)
        before = dict(yaml_text._entries)
        text = dump_mapping(doc)
        hits += sum((k, repr(v)) in before for k, v in doc.items())
        assert text == whole(doc), doc
    assert hits > 3000  # the remembered texts were used, not only freshly emitted ones


def test_problem_documents_of_a_sweep():
    from mobisense.ocp.problem import load_problem

    problem = load_problem("hussein2008")
    for alpha in (0.001, 0.0036, 0.02, 0.001):
        data = problem.normalised()
        data["cost"]["alpha"] = alpha
        data["sensors"][0]["p0"] = [alpha * 1000, -3.5]
        assert dump_mapping(data) == yaml.safe_dump(data, sort_keys=False, allow_unicode=True)


def test_shared_containers_and_other_values_are_emitted_whole():
    shared = [1, 2]
    doc = {"a": shared, "b": shared}  # PyYAML anchors the first and aliases the second
    assert "&id001" in dump_mapping(doc)
    assert dump_mapping(doc) == whole(doc)
    inner = {"x": 1}
    doc = {"a": {"p": inner, "q": inner}}
    assert dump_mapping(doc) == whole(doc)
    # non-string keys and other types are not plain data: the whole mapping goes to PyYAML, as before
    for doc in ({"a": {1: "x"}}, {1: "x"}, {}):
        assert dump_mapping(doc) == whole(doc)
    with pytest.raises(yaml.representer.RepresenterError):  # what safe_dump cannot write fails as before
        dump_mapping({"a": np.float64(0.5)})
    assert dump_mapping({"a": True}) != dump_mapping({"a": 1})  # the remembered texts keep True and 1 apart


def test_the_memory_is_bounded():
    for i in range(yaml_text.ENTRY_MEMO + 50):
        dump_mapping({"k": i})
    assert len(yaml_text._entries) <= yaml_text.ENTRY_MEMO
