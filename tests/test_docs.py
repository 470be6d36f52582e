"""The theory pages the code cites exist: every ``docs/theory/PAGE.md §n`` and ``eq. PAGE.N`` resolves."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
THEORY = ROOT / "docs" / "theory"
CITATION = re.compile(r"docs/theory/([a-z_]+)\.md(?: §(\d+(?:\.\d+)?))?")
EQUATION = re.compile(r"\beq\. ((?:ocp|direct|indirect|cooperative|steady_state|hessian|formation_control|level_curve"
                      r"|leader_follower|distributed|replay|path|field)\.\d+)")  # fmt: skip


def _sources() -> list[Path]:
    folders = ("core", "ocp", "estimation", "formation", "tests", "notebooks", "problems", "benchmarks")
    files = [ROOT / "cli.py", ROOT / "__init__.py", ROOT / "README.md"]
    for folder in folders:
        files += [p for p in (ROOT / folder).rglob("*") if p.suffix in {".py", ".ipynb", ".yaml", ".md"}]
    return files


def _sections(page: Path) -> set[str]:
    return set(re.findall(r"^#{2,4} (\d+(?:\.\d+)*)\.? ", page.read_text(encoding="utf-8"), flags=re.M))


def test_every_cited_page_section_and_equation_exists():
    pages = {p.stem: p for p in THEORY.glob("*.md")}
    sections = {name: _sections(path) for name, path in pages.items()}
    tags = set(re.findall(r"\\tag\{([a-z_]+\.\d+)\}", "".join(p.read_text(encoding="utf-8") for p in pages.values())))
    missing = []
    for path in _sources():
        text = path.read_text(encoding="utf-8", errors="replace")
        for page, section in CITATION.findall(text):
            if page not in pages or (section and section not in sections[page]):
                missing.append(f"{path.relative_to(ROOT)}: docs/theory/{page}.md §{section}")
        missing += [f"{path.relative_to(ROOT)}: eq. {tag}" for tag in EQUATION.findall(text) if tag not in tags]
    assert missing == []
