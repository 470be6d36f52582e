"""Output folders of the commands: the default ``--out``, the checks before any work, one writer at a time.

Every command does, in this order: read and validate its input (exit 2), check the memory budget (exit 2),
:meth:`OutputFolder.check` the output folder (exit 2, nothing created, well under a second), then
``with folder.lock():`` — create it, take its lock (a second writer exits 2 naming the holder's pid), remove
the temporary files a killed run left — and only then compute and write.
"""

from __future__ import annotations

import errno
import fcntl
import os
import re
from pathlib import Path
from types import TracebackType

from .errors import ConfigError, OutputError
from .interrupts import add_hard_stop_cleanup, remove_hard_stop_cleanup

__all__ = [
    "DEFAULT_OUTPUT_ROOT",
    "LOCK_NAME",
    "OutputFolder",
    "default_output_folder",
    "input_files",
    "is_output_name",
    "output_path",
    "remove_stale_temporaries",
]

#: folder under which every command writes by default (relative to the current directory)
DEFAULT_OUTPUT_ROOT = Path("out")
#: the lock file of an output folder while a command writes into it (removed when it finishes)
LOCK_NAME = ".mobisense.lock"
#: the temporary files of :func:`mobisense.core.files.atomic_path` (``.NAME.XXXXXXXX.tmp``)
TEMPORARY = re.compile(r"^\..+\.[a-z0-9_]{8}\.tmp$")
#: file systems nothing is written to
_VIRTUAL_FS = {"proc", "sysfs", "devtmpfs", "devpts", "cgroup", "cgroup2", "debugfs", "securityfs", "tracefs",
               "configfs", "fusectl", "pstore", "bpf", "mqueue", "hugetlbfs", "autofs", "binfmt_misc"}  # fmt: skip


#: the names of the files the commands write (figures and animations besides: :func:`is_output_name`)
OUTPUT_NAMES = frozenset({"summary.json", "solution.nc", "result.nc", "results.parquet", "sweep.json", "snapshot.nc",
                          "trace_grid.nc"})  # fmt: skip
#: a sweep's part files (``tasks/part-000001.nc``, results parts)
PART_FILE = re.compile(r"^part-\d+\.(nc|parquet)$")


def is_output_name(name: str) -> bool:
    """Whether a file of this name may be written by a command into its output folder (or a folder under it)."""
    return name in OUTPUT_NAMES or Path(name).suffix in (".png", ".gif", ".mp4") or bool(PART_FILE.match(name))


def input_files(source: str | Path, config: object = None) -> list[Path]:
    """The command's input file and the existing files its ``config`` names, relative to it (resolved).

    ``config`` (a validated model, dict or list) is walked for strings that name an existing file beside
    ``source``: a replay's ``solution`` and ``problem``, a re-plan's ``problem``, a sweep's ``base``. What an output
    folder must not overwrite (:meth:`OutputFolder.check`).
    """
    source = Path(source)
    found = [source.resolve()]
    stack = [config]
    while stack:
        item = stack.pop()
        if hasattr(item, "model_dump"):
            stack.append(item.model_dump())
        elif isinstance(item, dict):
            stack.extend(item.values())
        elif isinstance(item, (list, tuple)):
            stack.extend(item)
        elif isinstance(item, str) and 0 < len(item) < 4096 and "\0" not in item:
            candidate = source.parent / item
            try:
                if candidate.is_file():
                    found.append(candidate.resolve())
            except OSError:  # a name too long for the file system, …: not a file
                pass
    return found


def output_path(text: str) -> Path:
    """``argparse`` type of ``--out`` and ``--copy``: a path, never the empty string (which would mean ``.``)."""
    if not text.strip():
        import argparse

        raise argparse.ArgumentTypeError(f"expected a path, got {text!r} (write . for the current folder)")
    return Path(text)


def default_output_folder(input_file: Path) -> Path:
    """``out/<stem of the input file>``: where a command writes when ``--out`` is not given.

    Parameters
    ----------
    input_file : Path
        The YAML file the command reads (problem, sweep, scenario or formation file).

    Returns
    -------
    Path
        ``out/hussein2008`` for ``problems/hussein2008.yaml``. The file's stem, never a name read from
        inside the file, with every character but letters, digits, ``_``, ``-`` and ``.`` replaced by ``_``
        and no leading dot, so the folder is predictable and always a new folder inside ``out/``.
    """
    stem = re.sub(r"[^A-Za-z0-9_.\-]", "_", Path(input_file).stem).lstrip(".") or "output"
    return DEFAULT_OUTPUT_ROOT / stem


def _mount_type(path: Path) -> str | None:
    """The file-system type of the mount holding ``path`` (``None`` if ``/proc/mounts`` is unreadable)."""
    try:
        mounts = Path("/proc/mounts").read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return None
    best, kind = "", None
    text = str(path)
    for line in mounts:
        fields = line.split()
        if len(fields) < 3:
            continue
        point = fields[1].replace("\\040", " ")
        if (text == point or text.startswith(point.rstrip("/") + "/")) and len(point) >= len(best):
            best, kind = point, fields[2]
    return kind


def remove_stale_temporaries(folder: Path) -> int:
    """Remove the ``.NAME.XXXXXXXX.tmp`` files of interrupted atomic writes under ``folder``; return how many."""
    removed = 0
    for root, _, files in os.walk(folder):
        for name in files:
            if TEMPORARY.match(name):
                try:
                    os.unlink(os.path.join(root, name))
                    removed += 1
                except OSError:
                    pass
    return removed


class OutputFolder:
    """An output folder, checked before any work and locked while a command writes into it.

    Parameters
    ----------
    path : Path
        The folder (``--out``).
    option : str
        How the user named it, for messages (``"--out"``).
    """

    def __init__(self, path: Path, option: str = "--out") -> None:
        self.path = Path(path)
        self.option = option
        self._fd: int | None = None
        self._created: list[Path] = []

    # ------------------------------------------------------------------ checks (nothing created)
    @classmethod
    def check(cls, path: str | Path, option: str = "--out", inputs: list[Path] | tuple[Path, ...] = ()) -> OutputFolder:
        """Refuse an output folder that cannot be used, before any work and without creating anything.

        ``inputs``: the files the command reads (:func:`input_files`); none may be one the command would write.

        Raises
        ------
        ConfigError
            ``path`` exists and is not a folder, is a dangling symbolic link, lies under a file, on a
            virtual file system (``/proc``, ``/sys``, ``/dev``) or in a folder this process may not write, or
            holds an input under the name of an output (``solve summary.json --out .``; a replay of
            ``out/solution.nc`` into ``out``).
        """
        folder = cls(Path(path), option)
        p = folder.path
        if p.is_dir():
            inside = p.resolve()
            for item in inputs:
                if is_output_name(item.name) and inside in item.parents:
                    folder._fail(f"holds the input {item}, which this command would overwrite with its "
                                 f"{item.name}; choose another folder")  # fmt: skip
        try:
            os.getcwd()
        except FileNotFoundError:
            folder._fail("the current folder no longer exists; change to a folder that does")
        if p.is_symlink() and not p.exists():
            folder._fail(f"is a symbolic link to the missing {os.readlink(p)}; remove it or choose another folder")
        if p.exists() and not p.is_dir():
            folder._fail("exists and is not a folder; choose another folder")
        ancestor = p.absolute()
        while not ancestor.exists():
            if ancestor.is_symlink():
                folder._fail(f"{ancestor} is a dangling symbolic link")
            ancestor = ancestor.parent
        if not ancestor.is_dir():
            folder._fail(f"lies under {ancestor}, which is a file, not a folder")
        resolved = ancestor.resolve()
        kind = _mount_type(resolved)
        top = resolved.parts[1] if len(resolved.parts) > 1 else ""
        if kind in _VIRTUAL_FS or (top in ("proc", "sys", "dev") and not str(resolved).startswith("/dev/shm")):
            folder._fail(f"lies on the virtual file system {kind or '/' + top}; choose a folder on a disk")
        if not os.access(resolved, os.W_OK | os.X_OK):
            folder._fail(f"cannot be written: {resolved} is not writable by this user")
        return folder

    def _fail(self, problem: str) -> None:
        raise ConfigError(f"{self.option} {self.path}: {problem}")

    # ------------------------------------------------------------------ lock
    def lock(self) -> OutputFolder:
        """Use as ``with folder.lock():`` — create the folder, take its lock, clean stale temporary files."""
        return self

    def __enter__(self) -> OutputFolder:
        self._create()
        lock_path = self.path / LOCK_NAME
        while True:
            try:
                fd = os.open(lock_path, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o644)
            except OSError as exc:
                self._undo_create()
                self._fail(f"cannot be written ({exc.strerror})")
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                holder = os.read(fd, 200).decode("utf-8", "replace").split()
                os.close(fd)
                if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    self._fail(f"cannot be locked ({exc.strerror})")
                pid = holder[0] if holder else "unknown"
                self._fail(f"is in use by another mobisense run (pid {pid}); wait for it or choose another folder")
            try:  # the holder we waited for may have removed the file: lock the file that is there now
                same = os.stat(lock_path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        try:
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
        except OSError:  # a full disk: the lock holds without the pid (writing the results will report it)
            pass
        self._fd = fd
        remove_stale_temporaries(self.path)
        add_hard_stop_cleanup(self._release)  # a command ended inside a long CasADi call leaves nothing either
        return self

    def _release(self) -> None:
        """What a hard stop (core/interrupts.py) leaves: no lock, no temporary file, no folder this run created."""
        remove_stale_temporaries(self.path)
        self.__exit__(None, None, None)

    def __exit__(
        self, kind: type[BaseException] | None, value: BaseException | None, traceback: TracebackType | None
    ) -> None:
        remove_hard_stop_cleanup(self._release)
        if self._fd is not None:
            try:
                os.unlink(self.path / LOCK_NAME)
            except OSError:
                pass
            os.close(self._fd)
            self._fd = None
        # a folder this run created and left empty (invalid input found late, a simulation that diverged before
        # writing): removed, so that nothing is left behind
        self._undo_create()

    def remove_previous(self, names: list[str]) -> None:
        """Delete the files ``names`` (in the folder) that an earlier run wrote and this run replaces.

        Called after the computation, before the new files are written: an earlier run's figures are not left
        beside a new solution (a re-run with ``--no-plot``, or one interrupted while drawing).
        """
        for name in names:
            try:
                (self.path / name).unlink()
            except FileNotFoundError:
                pass
            except OSError as exc:
                raise OutputError(f"{self.path / name}: cannot remove this earlier output ({exc.strerror})") from None

    def _create(self) -> None:
        missing = []
        current = self.path
        while not current.exists():
            missing.append(current)
            current = current.parent
        try:
            for folder in reversed(missing):
                folder.mkdir()
                self._created.append(folder)
        except OSError as exc:
            self._undo_create()
            self._fail(f"cannot be created ({exc.strerror})")

    def _undo_create(self) -> None:
        for folder in reversed(self._created):
            try:
                folder.rmdir()  # only if empty
            except OSError:
                break
        self._created = []
