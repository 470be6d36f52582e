"""Many solves at once on dask: parameter sweeps and multi-start (extra ``mobisense[sweep]``)."""

from ...core.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "run_sweep": "mobisense.ocp.batch.sweep_runner",
        "SweepResult": "mobisense.ocp.batch.sweep_runner",
        "SweepSpec": "mobisense.ocp.batch.sweep",
        "SweepTask": "mobisense.ocp.batch.sweep",
        "load_sweep": "mobisense.ocp.batch.sweep",
        "expand_sweep": "mobisense.ocp.batch.sweep",
        "solve_multistart": "mobisense.ocp.batch.multistart",
        "distinct_optima": "mobisense.ocp.batch.multistart",
        "open_client": "mobisense.ocp.batch.engine",
        "run_tasks": "mobisense.ocp.batch.engine",
        "solve_task": "mobisense.ocp.batch.worker",
    },
)
