"""The named choices of an optimal-control problem file, each listed once.

The YAML schema (:mod:`mobisense.ocp.problem`), the command-line ``choices`` (:mod:`mobisense.ocp.commands`)
and the code that dispatches on a name all read these registries, so a solver, scheme or noise model
registered here (or by an installed package, for noise models through the ``mobisense.noise_models``
entry-point group) can be chosen from a problem file and from the command line.
"""

from __future__ import annotations

from typing import Any

from ..core.registry import Lazy, Registry

__all__ = [
    "METHODS",
    "SCHEMES",
    "HOMOTOPY_MODES",
    "STRATEGIES",
    "BVP_SOLVERS",
    "NOISE_MODELS",
]
# also importable, made on first use (module ``__getattr__`` below): MethodName, SchemeName,
# HomotopyModeName, StrategyName, BVPSolverName

#: solver.method -> function ``(problem, progress=None, init=None) -> Solution``
METHODS: Registry[Any] = Registry(
    "method",
    {
        "direct": Lazy("mobisense.ocp.direct.solver:solve_direct"),
        "indirect": Lazy("mobisense.ocp.indirect.solver:solve_indirect"),
        "both": Lazy("mobisense.ocp.compare:solve_both"),
        "shooting": Lazy("mobisense.ocp.field_solve:solve_shooting"),
    },
)

#: solver.collocation.scheme -> CasADi collocation point set (``casadi.collocation_points``)
SCHEMES: Registry[str] = Registry("collocation scheme", {"radau": "radau", "legendre": "legendre"})

#: solver.homotopy.mode -> continuation driver ``(attempt, options) -> last ε solved``
HOMOTOPY_MODES: Registry[Any] = Registry(
    "homotopy mode",
    {
        "fixed": Lazy("mobisense.ocp.homotopy:fixed_continuation"),
        "adaptive": Lazy("mobisense.ocp.homotopy:adaptive_continuation"),
        "none": Lazy("mobisense.ocp.homotopy:direct_to_one"),
    },
)

#: solver.strategy -> ``(SolveContext) -> (starts run, start kept)`` (docs/theory/direct.md §5.6)
STRATEGIES: Registry[Any] = Registry(
    "solve strategy",
    {
        "auto": Lazy("mobisense.ocp.direct.strategy:auto_strategy"),
        "thorough": Lazy("mobisense.ocp.direct.strategy:thorough_strategy"),
        "homotopy": Lazy("mobisense.ocp.direct.strategy:homotopy_strategy"),
        "cold": Lazy("mobisense.ocp.direct.strategy:cold_strategy"),
    },
)

#: solver.bvp.solver and solver.bvp.refine_solver -> :class:`mobisense.ocp.indirect.bvp_solvers.BVPSolver`
BVP_SOLVERS: Registry[Any] = Registry(
    "BVP solver",
    {
        "collocation": Lazy("mobisense.ocp.indirect.bvp_solvers:CollocationBVP"),
        "scipy": Lazy("mobisense.ocp.indirect.bvp_solvers:ScipyBVP"),
    },
)

#: sensors[i].noise.model -> :class:`mobisense.ocp.noise_models.NoiseModel` subclass
NOISE_MODELS: Registry[Any] = Registry(
    "noise model",
    {
        "quadratic_range": Lazy("mobisense.ocp.noise_models:QuadraticRange"),
        "constant": Lazy("mobisense.ocp.noise_models:ConstantNoise"),
    },
    entry_point_group="mobisense.noise_models",
)

# the pydantic types of the schema fields that name an entry (validated against the registry at read time),
# made on first use: listing the names (``--help``) does not import pydantic
_CHOICES = {
    "MethodName": METHODS,
    "SchemeName": SCHEMES,
    "HomotopyModeName": HOMOTOPY_MODES,
    "StrategyName": STRATEGIES,
    "BVPSolverName": BVP_SOLVERS,
}


def __getattr__(name: str) -> Any:
    if name not in _CHOICES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = globals()[name] = _CHOICES[name].choice()
    return value
