"""Execute notebooks in place and store their outputs (``make notebooks``), so figures show on a code host.

Each notebook runs with its own folder as working directory, on the ``python3`` kernel of the virtual
environment; any cell error stops with the notebook's name and a non-zero exit status, leaving the file
unchanged (it is written atomically only after a successful run). Outputs are stored without execution
counts' noise: a re-run of unchanged code changes only what the code prints.

Usage: ``python docs/tools/execute_notebooks.py notebooks/*.ipynb``
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path


def execute(path: Path, timeout: int = 1200) -> float:
    """Run ``path`` top to bottom and write it back with its outputs; return the seconds it took."""
    import nbformat
    from nbclient import NotebookClient

    started = time.perf_counter()
    notebook = nbformat.read(path, as_version=4)
    client = NotebookClient(notebook, timeout=timeout, kernel_name="python3",
                            resources={"metadata": {"path": str(path.parent)}})  # fmt: skip
    client.execute()
    for cell in notebook.cells:
        cell.get("metadata", {}).pop("execution", None)  # timestamps: noise in every diff
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        nbformat.write(notebook, tmp)
        os.replace(tmp, path)
    finally:
        Path(tmp).unlink(missing_ok=True)
    return time.perf_counter() - started


def main(paths: list[str]) -> int:
    """Execute every notebook given; exit status 1 at the first that fails."""
    # the kernel's inline backend, whatever the caller's MPLBACKEND (CI sets Agg): with Agg, plt.show() draws
    # nothing and the stored notebook would have no figures
    os.environ["MPLBACKEND"] = "module://matplotlib_inline.backend_inline"
    for name in paths:
        path = Path(name)
        try:
            seconds = execute(path)
        except Exception as err:  # noqa: BLE001  (report any cell error with the notebook's name)
            print(f"{path}: failed: {type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}",
                  file=sys.stderr)  # fmt: skip
            return 1
        print(f"{path}: executed in {seconds:.0f} s, outputs stored")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
