"""mobisense — optimal mobile sensing: sensor motion planning for Kalman filtering, cooperative estimation, formations.

The public API (imported lazily: ``import mobisense`` loads nothing heavy)::

    import mobisense as ms

    problem = ms.load_problem("problems/hussein2008.yaml")   # or ms.Problem.from_dict({...})
    solution = ms.solve(problem, method="direct")            # Solution: cost, trajectories, costates
    solution.sample([0.0, 2.5, 5.0])                         # the collocation polynomials at any time
    solution.save("out/hussein2008")                         # solution.nc + summary.json
    again = ms.solve(problem.with_solver(tolerance=1e-10), init=solution)   # warm start

    result = ms.load_scenario("problems/replay_two_charges.yaml").run()  # closed-loop simulations
    result.save("out/two_charges")

``sweep`` and ``multistart`` run many solves on dask (extra ``mobisense[sweep]``); ``design_formation``
designs the steady-state cross formation. Subpackages: :mod:`mobisense.ocp` (the optimal-control problem
and its methods), :mod:`mobisense.estimation` (filters, fields, steady states), :mod:`mobisense.formation`
(formation control and the closed-loop simulations), :mod:`mobisense.core` (configuration files, outputs).

Importing the package sets ``OPENBLAS_NUM_THREADS=1`` unless the user set it: CasADi's bundled OpenBLAS
otherwise spin-waits in ``sched_yield`` on the tiny dense fronts of MUMPS, which costs CPU and, with one
worker per core (sweeps), time.
"""

import os as _os

_os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from .core.lazy import lazy_exports as _lazy_exports  # noqa: E402  (after the environment is set)
from .core.version import __version__  # noqa: E402

__getattr__, __dir__, _names = _lazy_exports(
    __name__,
    {
        "ConfigError": "mobisense.core.config",
        "Problem": "mobisense.ocp.problem",
        "load_problem": "mobisense.ocp.problem",
        "Solution": "mobisense.ocp.solution",
        "SolveStatus": "mobisense.ocp.solution",
        "solve": "mobisense.ocp.solving",
        "sweep": "mobisense.ocp.batch.sweep_runner:run_sweep",
        "multistart": "mobisense.ocp.batch.multistart:solve_multistart",
        "design_formation": "mobisense.estimation.cooperative.design_study",
        "steady_state": "mobisense.estimation.cooperative.steady_state",
        "load_scenario": "mobisense.formation.scenarios",
        "SimulationResult": "mobisense.formation.simulation_result",
        "open_dataset": "mobisense.core.netcdf",
    },
)
__all__ = ["__version__", *_names]
