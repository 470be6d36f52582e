"""The structure of the package, read from its own source: one namespace, dependencies one way, no cycles.

Every import counts — module level, inside functions, under ``TYPE_CHECKING`` — because a lazy import is
still a dependency. The allowed direction between the subpackages is
``core ← ocp``, ``core ← estimation``, ``core, estimation, ocp ← formation``, and the command line on top.
"""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest

tomllib = pytest.importorskip("tomllib")  # Python >= 3.11

ROOT = Path(__file__).resolve().parents[1]
SUBPACKAGES = ("core", "ocp", "estimation", "formation")
#: subpackage -> the subpackages it may import
ALLOWED = {
    "core": set(),
    "ocp": {"core"},
    "estimation": {"core"},
    "formation": {"core", "estimation", "ocp"},
    "cli": {"core"},
    "": {"core"},  # the package's own __init__
}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(["mobisense", *parts])


def _modules() -> dict[str, Path]:
    files = [ROOT / "__init__.py", ROOT / "cli.py"]
    for package in SUBPACKAGES:
        files += sorted((ROOT / package).rglob("*.py"))
    return {_module_name(f): f for f in files}


MODULES = _modules()


def _package_of(path: Path) -> str:
    """The dotted package a file belongs to (``mobisense.ocp.direct`` for ``ocp/direct/solver.py``)."""
    name = _module_name(path)
    return name if path.name == "__init__.py" else name.rpartition(".")[0]


def _imports(path: Path) -> list[tuple[str, str]]:
    """(absolute module imported, name imported or '') for every import statement of a file."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against the file's package
                base = _package_of(path).split(".")
                base = base[: len(base) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            out += [(module, alias.name) for alias in node.names]
        elif isinstance(node, ast.Import):
            out += [(alias.name, "") for alias in node.names]
    return out


def _resolve(module: str, name: str) -> str | None:
    """The project module an import lands on (``from pkg import submodule`` lands on the submodule)."""
    for candidate in (f"{module}.{name}" if name else None, module):
        while candidate:
            if candidate in MODULES:
                return candidate
            candidate = candidate.rpartition(".")[0] if "." in candidate else None
    return None


def _graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {m: set() for m in MODULES}
    for name, path in MODULES.items():
        for module, imported in _imports(path):
            target = _resolve(module, imported)
            if target is not None and target != name and target != "mobisense":
                graph[name].add(target)
    return graph


def _subpackage(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def test_every_module_is_in_the_mobisense_namespace_and_installed():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    listed = set(config["tool"]["setuptools"]["packages"])
    packages = {_module_name(p.parent / "__init__.py") for p in ROOT.rglob("__init__.py") if p.parent != ROOT}
    packages = {p for p in packages if _subpackage(p) in SUBPACKAGES}
    assert packages | {"mobisense", "mobisense.problems"} == listed  # problems/: the shipped examples (data)


def test_no_import_cycles():
    graph = _graph()
    state: dict[str, int] = {}
    cycles = []

    def visit(node: str, stack: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycles.append(stack[stack.index(nxt) :] + [nxt])
            elif nxt not in state:
                visit(nxt, stack + [nxt])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    assert cycles == []


def test_dependencies_point_one_way():
    wrong = [
        f"{a} -> {b}"
        for a, targets in _graph().items()
        for b in targets
        if _subpackage(b) != _subpackage(a) and _subpackage(b) not in ALLOWED[_subpackage(a)]
    ]
    assert wrong == []


def test_estimation_never_imports_formation_or_ocp():
    offenders = [
        f"{a} -> {b}"
        for a, targets in _graph().items()
        if _subpackage(a) == "estimation"
        for b in targets
        if _subpackage(b) in ("formation", "ocp")
    ]
    assert offenders == []


def test_no_private_name_is_imported_from_another_module():
    private = [
        f"{name}: from {module} import {imported}"
        for name, path in MODULES.items()
        for module, imported in _imports(path)
        if module.startswith("mobisense") and imported.startswith("_") and not imported.startswith("__")
    ]
    assert private == []


@pytest.mark.parametrize("package", [m for m, p in MODULES.items() if p.name == "__init__.py"])
def test_public_names_resolve_and_do_not_shadow_submodules(package):
    module = importlib.import_module(package)
    folder = MODULES[package].parent
    submodules = {p.stem for p in folder.iterdir() if p.suffix == ".py" or (p / "__init__.py").exists()}
    for name in module.__all__:
        assert name not in submodules, f"{package}.{name} is both a public name and a submodule"
        getattr(module, name)


def test_modules_stay_small():
    sizes = {name: len(path.read_text(encoding="utf-8").splitlines()) for name, path in MODULES.items()}
    assert {name: n for name, n in sizes.items() if n > 500} == {}


def test_nothing_refers_to_material_outside_the_repository():
    pattern = re.compile(r"\.\./shared|" + "SP" + "EC §")  # built in pieces so this file does not match
    import os

    hits = []
    skipped = {".venv", ".git", "out", "site", "build", ".cache", "__pycache__", ".pytest_cache", ".ruff_cache"}
    tracked = []
    for folder, subfolders, names in os.walk(ROOT):  # pruned: generated folders are not the repository's text
        subfolders[:] = [s for s in subfolders if s not in skipped and not s.endswith(".egg-info")]
        tracked += [Path(folder) / n for n in names if Path(n).suffix in {".py", ".md", ".ipynb", ".yaml", ".toml"}]
    for path in tracked:
        if pattern.search(path.read_text(encoding="utf-8", errors="replace")):
            hits.append(str(path.relative_to(ROOT)))
    assert hits == []
