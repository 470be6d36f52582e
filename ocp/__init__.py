"""The mobile-sensor Kalman optimal-control problem: its file, its model, the methods that solve it.

Layout: :mod:`~mobisense.ocp.problem` (the YAML schema), :mod:`~mobisense.ocp.model` and
:mod:`~mobisense.ocp.state_layout` (the equations, the state vector), :mod:`~mobisense.ocp.direct`
(collocation + ε-homotopy), :mod:`~mobisense.ocp.indirect` (Pontryagin BVP and continuation),
:mod:`~mobisense.ocp.batch` (sweeps and multi-start on dask), :mod:`~mobisense.ocp.solution` (the result),
:mod:`~mobisense.ocp.registries` (the named choices of a problem file).
"""

from ..core.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "Problem": "mobisense.ocp.problem",
        "load_problem": "mobisense.ocp.problem",
        "Solution": "mobisense.ocp.solution",
        "SolveStatus": "mobisense.ocp.solution",
        "StartKind": "mobisense.ocp.solution",
        "HomotopyStep": "mobisense.ocp.solution",
        "TrajectorySample": "mobisense.ocp.solution",
        "solve": "mobisense.ocp.solving",
        "StateLayout": "mobisense.ocp.state_layout",
        "Structure": "mobisense.ocp.model",
        "ParameterLayout": "mobisense.ocp.model",
        "SensorKalmanModel": "mobisense.ocp.model",
        "CollocationScheme": "mobisense.ocp.collocation",
        "NoiseModel": "mobisense.ocp.noise_models",
        "register_noise_model": "mobisense.ocp.noise_models",
        "METHODS": "mobisense.ocp.registries",
        "SCHEMES": "mobisense.ocp.registries",
        "HOMOTOPY_MODES": "mobisense.ocp.registries",
        "BVP_SOLVERS": "mobisense.ocp.registries",
        "NOISE_MODELS": "mobisense.ocp.registries",
        "Trajectory": "mobisense.ocp.simulate",
        "integrate": "mobisense.ocp.simulate",
        "coast": "mobisense.ocp.simulate",
        "run_continuation": "mobisense.ocp.homotopy",
        "fixed_schedule": "mobisense.ocp.homotopy",
        "solve_both": "mobisense.ocp.compare",
        "agreement": "mobisense.ocp.compare",
        "save_figures": "mobisense.ocp.plots",
        "FieldSpec": "mobisense.ocp.field",
        "FieldProcess": "mobisense.ocp.field",
        "FieldShooting": "mobisense.ocp.shooting",
        "solve_shooting": "mobisense.ocp.field_solve",
        "shooting_memory_bytes": "mobisense.ocp.field",
        "effective_noise": "mobisense.ocp.plots",
        "PathConstraints": "mobisense.ocp.path_constraints",
        "Disturbance": "mobisense.ocp.replan",
        "fly": "mobisense.ocp.replan",
        "replan_monte_carlo": "mobisense.ocp.replan",
    },
)
