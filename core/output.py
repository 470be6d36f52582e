"""Output folders of the commands: the one rule for the default ``--out``."""

from __future__ import annotations

from pathlib import Path

__all__ = ["DEFAULT_OUTPUT_ROOT", "default_output_folder"]

#: folder under which every command writes by default (relative to the current directory)
DEFAULT_OUTPUT_ROOT = Path("out")


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
        inside the file, so the folder is predictable and cannot escape ``out/``.
    """
    return DEFAULT_OUTPUT_ROOT / Path(input_file).stem
