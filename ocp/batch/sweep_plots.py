"""Figure of a sweep: the optimal cost over the varied key paths (``cost.png`` in the sweep's folder).

One varied key: J against its values (a line; categorical ticks for vector values such as a start
position). Two keys: a heat map of J over their grid, each cell labelled with its value. More keys: J of
every task, in task order, labelled by its values. Tasks that did not solve are marked, not dropped.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["plot_sweep", "save_sweep_figures"]


def _label(value: Any) -> str:
    if isinstance(value, (list, tuple, np.ndarray)):
        return "(" + ", ".join(_label(v) for v in value) + ")"
    return f"{value:g}" if isinstance(value, (int, float, np.number)) else str(value)


def _numeric(values: list[Any]) -> bool:
    return all(isinstance(v, (int, float, np.number)) and not isinstance(v, bool) for v in values)


def _levels(table: Any, key: str) -> list[Any]:
    levels: list[Any] = []
    for value in table[key]:
        value = value.tolist() if hasattr(value, "tolist") else value
        if value not in levels:
            levels.append(value)
    return levels


def plot_sweep(table: Any, vary: list[str], title: str = "sweep") -> Any:
    """The cost over the sweep (a matplotlib Figure; see the module notes).

    Parameters
    ----------
    table : pandas.DataFrame
        One row per task: a column per varied key, ``status`` and ``cost`` (as ``results.parquet``).
    vary : list of str
        The varied key paths, as named in the sweep file.
    title : str
        Figure title.
    """
    import matplotlib.pyplot as plt

    cost = np.where(table["status"] == "solved", table["cost"].astype(float), np.nan)
    if len(vary) == 1:
        key = vary[0]
        values = [v.tolist() if hasattr(v, "tolist") else v for v in table[key]]
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        x = np.asarray(values, float) if _numeric(values) else np.arange(len(values))
        order = np.argsort(x)
        ax.plot(x[order], cost[order], "o-", label="optimal cost J (solved tasks)")
        failed = np.isnan(cost)
        if failed.any():
            ax.plot(x[failed], np.full(failed.sum(), np.nanmin(cost) if np.isfinite(cost).any() else 0.0), "rx",
                    ms=9, label="task not solved")  # fmt: skip
        if not _numeric(values):
            ax.set_xticks(x, [_label(v) for v in values], rotation=20)
        if _numeric(values) and np.all(x > 0) and x.max() / x.min() > 20:
            ax.set_xscale("log")
        ax.set(xlabel=key, ylabel="optimal cost J", title=title)
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
        return fig
    if len(vary) == 2:
        rows, cols = (_levels(table, k) for k in vary)
        grid = np.full((len(rows), len(cols)), np.nan)
        for (i_value, j_value), c in zip(zip(table[vary[0]], table[vary[1]], strict=True), cost, strict=True):
            i = rows.index(i_value.tolist() if hasattr(i_value, "tolist") else i_value)
            j = cols.index(j_value.tolist() if hasattr(j_value, "tolist") else j_value)
            grid[i, j] = c
        fig, ax = plt.subplots(figsize=(1.4 * len(cols) + 3.2, 0.7 * len(rows) + 2.6))
        image = ax.imshow(grid, cmap="viridis", aspect="auto", origin="lower")
        fig.colorbar(image, ax=ax, label="optimal cost J")
        norm = image.norm
        for i in range(len(rows)):
            for j in range(len(cols)):
                value = grid[i, j]
                if np.isnan(value):
                    text, colour = "not solved", "r"
                else:
                    text, colour = f"{value:.6g}", "k" if norm(value) > 0.6 else "w"
                ax.text(j, i, text, ha="center", va="center", fontsize=8, color=colour)
        ax.set_xticks(range(len(cols)), [_label(v) for v in cols], rotation=20)
        ax.set_yticks(range(len(rows)), [_label(v) for v in rows])
        ax.set(xlabel=vary[1], ylabel=vary[0], title=title)
        return fig
    fig, ax = plt.subplots(figsize=(max(6.4, 0.35 * len(table) + 2), 4.2))
    ax.bar(np.arange(len(table)), np.nan_to_num(cost), color=np.where(np.isnan(cost), "tab:red", "tab:blue"))
    labels = [", ".join(_label(row[k]) for k in vary) for _, row in table.iterrows()]
    ax.set_xticks(np.arange(len(table)), labels, rotation=70, fontsize=7)
    ax.set(xlabel=" | ".join(vary), ylabel="optimal cost J (red: not solved)", title=title)
    return fig


def save_sweep_figures(result: Any) -> list[Path]:
    """Write ``cost.png`` into the folder of a :class:`~mobisense.ocp.batch.sweep_runner.SweepResult`."""
    from ...core.files import write_figure

    path = Path(result.folder) / "cost.png"
    vary = list(result.summary["vary"])
    title = f"{result.summary['mode']} sweep: optimal cost over {' and '.join(vary) if len(vary) < 3 else 'the tasks'}"
    write_figure(path, lambda: plot_sweep(result.table, vary, title))
    return [path]
