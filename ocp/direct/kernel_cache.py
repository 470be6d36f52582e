"""Compiled collocation kernels, cached on disk (docs/theory/direct.md §1.7).

The interval kernels (:mod:`mobisense.ocp.direct.kernels`) are SX functions; CasADi can evaluate them in its
virtual machine or as generated C. :func:`load_compiled` generates the C code of a set of functions once,
compiles it into a shared library with the system C compiler and keeps the library in the cache folder,
under a name derived from a key that identifies the functions: the problem structure, scheme and layout,
the source of the modules that define the equations, the CasADi version, the compiler and its flags, and
the functions' sizes. On a later run with the same key the library is loaded without generating anything.

The cache folder is ``$MOBISENSE_CACHE`` if set, else ``$XDG_CACHE_HOME/mobisense``, else
``~/.cache/mobisense``; nothing is written anywhere else (the generated C file is written there too and
removed after compiling). The C compiler is ``$CC`` if set, else the first of ``cc``, ``gcc``, ``clang`` on
the ``PATH``. Without a compiler, with an unwritable cache folder or when compiling fails, the functions
are returned unchanged (virtual machine) and the reason is reported: the result is the same, only slower.
A library whose functions do not have the expected inputs and outputs (a stale or damaged file) is rebuilt.

With ``background=True`` (``solver.codegen: auto``) a miss does not wait for the compiler — generating and
compiling the kernels of n = 4, N = 2 takes 12–45 s, far more than the solve: the functions are saved
(CasADi serialisation, milliseconds) and a detached process (``python -m mobisense.ocp.direct.kernel_cache``)
generates and compiles them into the cache, while this process evaluates them in the virtual machine
(the same numbers, ≈ 2× slower evaluations); the next process with the same key loads the library. A
marker file keeps concurrent processes from compiling the same key twice (stale after 10 minutes).

A library's modification time is its last use (touched when loaded); after every build, all but the
:data:`CACHE_MAX_LIBRARIES` most recently used are removed (:func:`prune`), so editing the equations or solving
many structures does not fill the disk.
"""

from __future__ import annotations

import hashlib
import inspect
import json
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Iterable
from pathlib import Path

import casadi as ca

__all__ = [
    "CACHE_ENV",
    "COMPILE_FLAGS",
    "cache_folder",
    "c_compiler",
    "source_digest",
    "load_compiled",
    "compile_library",
    "prune",
    "CACHE_MAX_LIBRARIES",
]

#: environment variable naming the cache folder
CACHE_ENV = "MOBISENSE_CACHE"
#: compiler flags (``-O1``: measured fastest to build at equal run time; ``-O2`` compiles 8x longer)
COMPILE_FLAGS: tuple[str, ...] = ("-O1", "-fPIC", "-shared")
#: a background compile marker older than this (s) is taken as the trace of a killed compile
STALE_MARKER_S = 600.0
#: background compiles allowed at once per cache folder: a miss beyond it runs in the virtual machine and
#: leaves its compile to a later run (a test suite or sweep meeting many structures would otherwise start a
#: C compiler for each, all at once)
MAX_BACKGROUND_COMPILES = 1
#: libraries kept in the cache folder: beyond this many, the least recently used (loaded or built) are removed
#: after a build (a library is 0.1–2 MB; every version of the equations and every structure adds one)
CACHE_MAX_LIBRARIES = 200


def cache_folder() -> Path:
    """The folder of compiled kernels (see module docstring)."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base).expanduser() / "mobisense"


def c_compiler() -> str | None:
    """Path of the C compiler (``$CC``, else cc, gcc, clang), or None when there is none."""
    names = [os.environ["CC"]] if os.environ.get("CC") else ["cc", "gcc", "clang"]
    for name in names:
        path = shutil.which(name)
        if path:
            return path
    return None


def source_digest(objects: list[object]) -> str | None:
    """SHA-256 of the source files defining ``objects`` (modules or classes), or None if one has no file.

    Part of every cache key: editing the equations (or a registered noise model) changes the key. Code
    without a readable source file (defined interactively) cannot be fingerprinted, so it is never cached.
    """
    digest = hashlib.sha256()
    for obj in objects:
        try:
            digest.update(Path(inspect.getsourcefile(obj) or "").read_bytes())  # type: ignore[arg-type]
        except (TypeError, OSError):
            return None
    return digest.hexdigest()


def _matches(loaded: ca.Function, reference: ca.Function) -> bool:
    """Same inputs and outputs (sparsity patterns) as the SX function it replaces."""
    if loaded.n_in() != reference.n_in() or loaded.n_out() != reference.n_out():
        return False
    return all(loaded.sparsity_in(i) == reference.sparsity_in(i) for i in range(reference.n_in())) and all(
        loaded.sparsity_out(i) == reference.sparsity_out(i) for i in range(reference.n_out())
    )


def _load(library: Path, functions: dict[str, ca.Function]) -> dict[str, ca.Function] | None:
    """The library's functions if it exists and provides every function with the right signature."""
    if not library.exists():
        return None
    try:
        loaded = {name: ca.external(name, str(library)) for name in functions}
    except RuntimeError:
        return None
    return loaded if all(_matches(loaded[name], f) for name, f in functions.items()) else None


def load_compiled(
    functions: dict[str, ca.Function], key: str, folder: Path | None = None, background: bool = False
) -> tuple[dict[str, ca.Function], str]:
    """Compiled versions of ``functions`` from the cache (built on a miss), or the functions themselves.

    Parameters
    ----------
    functions : dict
        Name -> SX function (the name becomes the C symbol).
    key : str
        What identifies the functions (see module docstring); the compiler and flags are added here.
    folder : Path, optional
        Cache folder (default :func:`cache_folder`).
    background : bool
        On a miss, compile in a detached process and return the functions themselves (see module docstring).

    Returns
    -------
    functions : dict
        Name -> ``casadi.external`` function, or the input functions when compiling is not possible.
    how : str
        ``"compiled (cached)"``, ``"compiled"`` or ``"virtual machine (<reason>)"``.
    """
    compiler = c_compiler()
    if compiler is None:
        return functions, "virtual machine (no C compiler found)"
    folder = Path(folder) if folder is not None else cache_folder()
    full_key = "|".join([key, compiler, *COMPILE_FLAGS, ca.__version__])
    digest = hashlib.sha256(full_key.encode()).hexdigest()[:20]
    library = folder / f"kernels_{digest}.so"
    loaded = _load(library, functions)
    if loaded is not None:
        _touch(library)  # its modification time is its last use: the least recently used go first (_prune)
        return loaded, "compiled (cached)"
    if background:
        return functions, _start_background(functions, folder, digest, full_key, compiler)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        source = _write_source(functions.values(), library)
    except OSError as err:
        return functions, f"virtual machine (cache folder {folder} not writable: {err.strerror})"
    failure = _compile(source, library, full_key, compiler)
    if failure is not None:
        return functions, f"virtual machine ({failure})"
    loaded = _load(library, functions)
    if loaded is None:
        return functions, "virtual machine (the compiled library could not be loaded)"
    return loaded, "compiled"


def _write_source(functions: Iterable[ca.Function], library: Path) -> Path:
    """Generate the C of ``functions`` beside ``library`` (a temporary file of this process); its path."""
    generator = ca.CodeGenerator(f"{library.stem}.c", {"with_header": False})
    for f in functions:
        generator.add(f)
    source = library.with_name(f".{library.stem}.{os.getpid()}.c")
    source.write_text(generator.dump(), encoding="utf-8")
    return source


def _compile(source: Path, library: Path, full_key: str, compiler: str) -> str | None:
    """Compile ``source`` into ``library`` (atomically) and record its key; None, or why it failed."""
    target = library.with_name(f".{library.stem}.{os.getpid()}.so")
    try:
        run = subprocess.run(
            [compiler, *COMPILE_FLAGS, str(source), "-o", str(target), "-lm"], capture_output=True, text=True
        )
        if run.returncode != 0:
            return "compiling failed: " + (run.stderr.strip().splitlines() or ["no message"])[0]
        os.replace(target, library)  # atomic: a concurrent run sees the old library or the new one, never half
        library.with_suffix(".json").write_text(json.dumps({"key": full_key}, indent=1), encoding="utf-8")
        prune(library.parent)
    except OSError as err:
        return f"cache folder {library.parent} not writable: {err.strerror}"
    finally:
        for path in (source, target):
            path.unlink(missing_ok=True)
    return None


def _start_background(
    functions: dict[str, ca.Function], folder: Path, digest: str, full_key: str, compiler: str
) -> str:
    """Save ``functions`` and start a detached compile of them (unless one runs); say so."""
    marker = folder / f".kernels_{digest}.building"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        if marker.exists() and time.time() - marker.stat().st_mtime < STALE_MARKER_S:
            return "virtual machine (kernels being compiled by another process)"
        if _compiles_running(folder) >= MAX_BACKGROUND_COMPILES:  # one compiler at a time on the machine
            return "virtual machine (another background compile is running; these kernels wait for a later run)"
        marker.write_text(str(os.getpid()), encoding="utf-8")
        saved = []
        for name, f in functions.items():
            path = folder / f".kernels_{digest}.{os.getpid()}.{name}.casadi"
            f.save(str(path))
            saved.append(str(path))
    except (OSError, RuntimeError) as err:
        return f"virtual machine (cache folder {folder} not writable: {err})"
    args = [sys.executable, "-m", __name__, str(folder / f"kernels_{digest}.so"), full_key, compiler, *saved]
    _detach(args)
    return "virtual machine (compiling in the background for the next run)"


def _detach(args: list[str]) -> None:
    """Start ``args`` in a new session, not as a child of this process (no zombie, no ResourceWarning).

    A shell starts it in the background and exits at once; the compile is then adopted by init. Without a
    POSIX shell, a plain detached child.
    """
    quiet = {"stdin": subprocess.DEVNULL, "stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    shell = shutil.which("sh")
    if shell is None:
        subprocess.Popen(args, start_new_session=True, **quiet)  # noqa: S603
        return
    subprocess.run([shell, "-c", '"$@" &', "sh", *args], start_new_session=True, check=False, **quiet)  # noqa: S603


def _touch(library: Path) -> None:
    try:
        os.utime(library)
    except OSError:  # a read-only cache still serves its libraries
        pass


def prune(folder: Path, keep: int = CACHE_MAX_LIBRARIES) -> list[Path]:
    """Remove all but the ``keep`` most recently used libraries (and their key files) of ``folder``; the removed.

    Removing a library another process has loaded is safe (the mapping stays until it exits); one that a
    process was about to load is compiled again.
    """
    libraries = []
    for path in folder.glob("kernels_*.so"):
        try:
            libraries.append((path.stat().st_mtime, path))
        except OSError:  # removed meanwhile
            pass
    libraries.sort(reverse=True)
    removed = []
    for _, path in libraries[keep:]:
        for file in (path, path.with_suffix(".json")):
            file.unlink(missing_ok=True)
        removed.append(path)
    return removed


def _compiles_running(folder: Path) -> int:
    """How many background compiles into ``folder`` are under way (fresh ``.building`` markers)."""
    now = time.time()
    count = 0
    for path in folder.glob(".kernels_*.building"):
        try:
            count += now - path.stat().st_mtime < STALE_MARKER_S
        except OSError:  # finished meanwhile
            pass
    return count


def compile_library(library: Path, full_key: str, compiler: str, saved: list[Path]) -> str | None:
    """Generate C for the saved functions (``Function.save`` files, removed) and compile ``library``.

    The work of a background compile (:func:`load_compiled` with ``background=True``); returns None or why
    it failed. The ``.building`` marker of the library is removed in any case.
    """
    library = Path(library)
    marker = library.with_name(f".{library.stem}.building")
    try:
        source = _write_source([ca.Function.load(str(path)) for path in saved], library)
        return _compile(source, library, full_key, compiler)
    except (OSError, RuntimeError) as err:
        return str(err)
    finally:
        for path in [*saved, marker]:
            Path(path).unlink(missing_ok=True)


if __name__ == "__main__":  # the detached background compile: library, key, compiler, saved functions
    failure = compile_library(Path(sys.argv[1]), sys.argv[2], sys.argv[3], [Path(p) for p in sys.argv[4:]])
    sys.exit(0 if failure is None else 1)
