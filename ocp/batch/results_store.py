"""The result folder of a sweep: ``results.parquet`` appended batch by batch, and the manifest naming the sweep.

``results.parquet`` is a *folder* of parquet fragments (``part-000001.parquet``, …), one written atomically per
batch of finished tasks, so a 10 000-task sweep never rewrites what it wrote before; pandas, pyarrow and
polars read the folder as one table (``pandas.read_parquet("out/results.parquet")``). A task re-run on resume
(an ``error`` row) appears again in a later fragment: the last row of a task wins, and at the end of each
run the fragments are compacted into one.

``sweep.json`` records the sweep that made the folder (the digest of its tasks): a sweep resumes only into
its own folder, and a corrupt fragment is reported by name (``ConfigError``, exit status 2).
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

from ...core.errors import ConfigError, brief
from ...core.files import atomic_path, write_json

__all__ = ["ResultStore", "MANIFEST", "RESULTS", "check_manifest", "write_manifest"]

#: the manifest of a sweep folder
MANIFEST = "sweep.json"
#: the results dataset (a folder of fragments)
RESULTS = "results.parquet"
_FRAGMENT = re.compile(r"^part-(\d{6})\.parquet$")
#: arrow types of the result columns (see :data:`mobisense.ocp.batch.sweep_runner.RESULT_COLUMNS`)
_TYPES = {
    "status": "string",
    "cost": "float64",
    "terminal_cost": "float64",
    "running_cost": "float64",
    "iterations": "int64",
    "time_s": "float64",
    "solve_time_s": "float64",
    "worker": "string",
    "error": "string",
    "start": "string",
    "transcription_cached": "bool",
    "solution_file": "string",
    "warning": "string",
}
#: columns added after the first release of the format (read as missing from older fragments)
_LATER = ("solution_file", "warning")


def _shortened(text: str, limit: int = 100) -> str:
    """``text`` on one line, cut at a word before ``limit`` characters with an ellipsis (not mid-sentence, unmarked)."""
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 1].rsplit(" ", 1)[0] + " …"


def _number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _finite(x: Any) -> bool:
    try:
        return math.isfinite(x)
    except OverflowError:  # an integer beyond the largest double
        return False


def value_kind(values: list[Any]) -> str:
    """How a varied key's values are stored: ``int64``, ``float64``, ``string``, ``list`` (of float64) or ``json``."""
    if values and all(isinstance(x, str) for x in values):
        return "string"
    if values and all(isinstance(x, int) and not isinstance(x, bool) for x in values):
        return "int64" if all(abs(x) < 2**63 for x in values) else "json"
    if values and all(_number(x) and _finite(x) for x in values):
        return "float64"
    if values and all(isinstance(x, list) and all(_number(y) for y in x) for x in values):
        return "list"
    return "json"


class ResultStore:
    """``results.parquet/`` of a sweep folder: append rows batch by batch, read them back as one table.

    Parameters
    ----------
    folder : Path
        The sweep's output folder.
    value_kinds : dict
        Varied key path -> :func:`value_kind` of its values (the column types).
    """

    def __init__(self, folder: Path, value_kinds: dict[str, str]) -> None:
        import pyarrow as pa

        self.path = Path(folder) / RESULTS
        self.kinds = value_kinds
        arrow = {"int64": pa.int64(), "float64": pa.float64(), "string": pa.string(), "list": pa.list_(pa.float64()),
                 "json": pa.string()}  # fmt: skip
        fields = [pa.field("task", pa.string()), pa.field("index", pa.int64())]
        fields += [pa.field(key, arrow[kind]) for key, kind in value_kinds.items()]
        types = {"string": pa.string(), "float64": pa.float64(), "int64": pa.int64(), "bool": pa.bool_()}
        fields += [pa.field(name, types[kind]) for name, kind in _TYPES.items()]
        self.schema = pa.schema(fields)

    # ------------------------------------------------------------------ fragments
    def fragments(self) -> list[Path]:
        """The fragment files, oldest first."""
        if not self.path.is_dir():
            return []
        return sorted(p for p in self.path.iterdir() if _FRAGMENT.match(p.name))

    def _next_name(self) -> Path:
        last = max((int(_FRAGMENT.match(p.name).group(1)) for p in self.fragments()), default=0)  # type: ignore[union-attr]
        return self.path / f"part-{last + 1:06d}.parquet"

    def read(self) -> dict[str, dict[str, Any]]:
        """Every task's last row (task id -> row, varied values decoded); ``ConfigError`` naming a corrupt file."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        if self.path.exists() and not self.path.is_dir():
            raise ConfigError(f"{self.path}: a single-file results table of an earlier version; choose another --out")
        rows: dict[str, dict[str, Any]] = {}
        for fragment in self.fragments():
            try:
                table = pq.read_table(fragment)
                for name in _LATER:
                    if name not in table.column_names:
                        table = table.append_column(name, pa.nulls(len(table), self.schema.field(name).type))
                if not set(self.schema.names) <= set(table.column_names):
                    missing = sorted(set(self.schema.names) - set(table.column_names))
                    raise ValueError(f"missing columns {brief(missing, 60)}")
                records = table.select(self.schema.names).cast(self.schema).to_pylist()
            except ConfigError:
                raise
            except Exception as exc:  # noqa: BLE001  (pyarrow raises many kinds for a damaged file)
                raise ConfigError(
                    f"{fragment}: not a readable results fragment ({_shortened(str(exc))}); delete it "
                    "to re-run its tasks, or choose another --out"
                ) from None
            for record in records:
                rows[record["task"]] = self._decode(record)
        return rows

    def append(self, rows: list[dict[str, Any]]) -> None:
        """Write ``rows`` as one new fragment (atomically)."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        if not rows:
            return
        table = pa.Table.from_pylist([self._encode(r) for r in rows], schema=self.schema)
        self.path.mkdir(parents=True, exist_ok=True)
        with atomic_path(self._next_name()) as tmp:
            pq.write_table(table, tmp)

    def compact(self) -> None:
        """Rewrite the fragments as one (last row of each task, in task order) when there are several."""
        old = self.fragments()
        if len(old) <= 1:
            return
        rows = sorted(self.read().values(), key=lambda r: r["index"])
        self.append(rows)  # the newest fragment holds everything: a crash now leaves duplicates, never a loss
        for fragment in old:
            fragment.unlink()

    # ------------------------------------------------------------------ values
    def _encode(self, row: dict[str, Any]) -> dict[str, Any]:
        out = dict(row)
        for key, kind in self.kinds.items():
            if key not in out:
                continue
            if kind == "json":
                out[key] = json.dumps(out[key], sort_keys=True)
            elif kind == "float64" and out[key] is not None:  # an integer among floats, beyond 2^53 too: the
                out[key] = float(out[key])  # double the problem itself was given (pyarrow refuses it inexact)
            elif kind == "list" and out[key] is not None:
                out[key] = [float(y) for y in out[key]]
        return out

    def _decode(self, row: dict[str, Any]) -> dict[str, Any]:
        for key, kind in self.kinds.items():
            if kind == "json" and isinstance(row.get(key), str):
                row[key] = json.loads(row[key])
        return row


def check_manifest(folder: Path, digest: str, source: str) -> bool:
    """Whether ``folder`` holds this sweep (``True``), nothing yet (``False``), or something else (``ConfigError``)."""
    manifest = folder / MANIFEST
    if manifest.is_file():
        try:
            made_by = json.loads(manifest.read_text(encoding="utf-8"))["sweep_digest"]
        except (OSError, ValueError, KeyError, TypeError):
            raise ConfigError(f"{manifest}: not a readable sweep manifest; choose another --out") from None
        if made_by != digest:
            raise ConfigError(
                f"{source}: --out {folder} holds the results of another sweep (digest {str(made_by)[:16]}, this "
                f"sweep {digest}: other base problem, values or solver options); choose another --out"
            )
        return True
    others = [p.name for p in folder.iterdir() if not p.name.startswith(".")] if folder.is_dir() else []
    if others:
        raise ConfigError(
            f"{source}: --out {folder} is not empty and was not made by a sweep ({brief(sorted(others), 60)}); "
            "choose another --out"
        )
    return False


def write_manifest(folder: Path, digest: str, source: str, tasks: int, mode: str, vary: list[str]) -> None:
    """Write ``sweep.json``: which sweep made the folder."""
    write_json(folder / MANIFEST, {"sweep_digest": digest, "file": source, "tasks": tasks, "mode": mode, "vary": vary})
