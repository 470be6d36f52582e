"""The one shape of every closed-loop simulation's outcome: a dataset, a summary, its figures.

A scenario runs (:func:`mobisense.formation.scenarios.load_scenario` → :meth:`Scenario.run`) into a
:class:`SimulationResult`: ``to_xarray()`` is the data (``result.nc``), ``summary`` the headline numbers
(``summary.json``), ``plot(folder)`` writes the figures and ``save(folder)`` writes all three atomically.
Each simulation subclasses it with its own figures and console report.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["SimulationResult", "MUST_BE_FINITE"]

#: result kind -> the variables of its dataset that are finite in any valid run (positions, the estimate):
#: NaN or inf there means the simulation diverged, and it is reported as a failure instead of being saved
MUST_BE_FINITE: dict[str, tuple[str, ...]] = {
    "leader_follower": ("x", "y", "phi"),
    "distributed": ("sensor_position", "z_constrained"),
    "field_replay": ("r", "z_est"),
    "plan_replay": ("r", "nees_predicted"),
    "replan": ("p", "Sigma"),
}


class SimulationResult:
    """Outcome of one closed-loop simulation.

    Parameters
    ----------
    dataset : xarray.Dataset
        Everything simulated, on its time axis (written as ``result.nc``).
    summary : dict
        Plain-JSON headline numbers (written as ``summary.json``, with the list of files written).
    """

    #: what kind of simulation produced the result (``summary.json`` key ``kind`` where it has none)
    kind: str = "simulation"

    def __init__(self, dataset: Any, summary: dict[str, Any]) -> None:
        self.dataset = dataset
        self.summary = summary

    def to_xarray(self) -> Any:
        """The simulated data as an ``xarray.Dataset``."""
        return self.dataset

    def non_finite(self) -> str | None:
        """Which of the :data:`MUST_BE_FINITE` variables holds NaN or inf (``None`` when the run is finite)."""
        import numpy as np

        for name in MUST_BE_FINITE.get(self.kind, ()):
            if name in self.dataset.data_vars:
                values = np.asarray(self.dataset[name].values, dtype=float)
                bad = int(values.size - np.isfinite(values).sum())
                if bad:
                    return f"{name} has {bad} NaN or infinite values"
        return None

    def plot(self, folder: str | Path) -> list[Path]:
        """Write the figures into ``folder``; return their paths (none by default)."""
        return []

    def extra_files(self, folder: Path) -> list[Path]:
        """Files beyond ``result.nc``, figures and ``summary.json`` that :meth:`save` writes (none by default)."""
        return []

    def save(self, folder: str | Path, figures: bool = True) -> list[Path]:
        """Write ``result.nc``, the figures (unless ``figures=False``) and ``summary.json`` into ``folder``.

        Every file is written atomically; ``summary.json`` last, listing the files written. The files an earlier
        run listed in ``summary.json`` (its figures, an animation) are removed first, so that none of them is
        left beside the new results.
        """
        from ..core.errors import ConfigError
        from ..core.files import write_json, write_netcdf
        from ..core.reader import read_document

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        try:
            earlier = read_document(folder / "summary.json").get("files", [])
        except (ConfigError, AttributeError):  # no earlier run here, or not a summary of one
            earlier = []
        for name in earlier if isinstance(earlier, list) else []:
            if isinstance(name, str) and name == Path(name).name and name.endswith((".png", ".mp4", ".gif")):
                (folder / name).unlink(missing_ok=True)
        write_netcdf(folder / "result.nc", self.dataset)
        written = [folder / "result.nc", folder / "summary.json"]
        written += self.extra_files(folder)
        if figures:
            written += self.plot(folder)
        self.summary["files"] = [p.name for p in written]
        write_json(folder / "summary.json", self.summary)
        return written

    def report(self, folder: Path) -> None:
        """Print the headline numbers to the terminal (after :meth:`save`)."""
        print(f"results in {folder}/: {', '.join(self.summary.get('files', []))}")

    def __repr__(self) -> str:
        dims = ", ".join(f"{k}={v}" for k, v in dict(self.dataset.sizes).items())
        keys = ", ".join(list(self.summary)[:8])
        variables = len(self.dataset.data_vars)
        return f"{type(self).__name__}(dataset: {variables} variables over {dims}; summary: {keys}, …)"
