"""Formation control, level-curve tracking, leader–follower formations, and the closed-loop simulations.

Layout: :mod:`~mobisense.formation.jacobi`, :mod:`~mobisense.formation.shape_control`,
:mod:`~mobisense.formation.level_curve`, :mod:`~mobisense.formation.platforms` (the controllers),
:mod:`~mobisense.formation.replay` (formations on a field and optimised plans flown in closed loop),
:mod:`~mobisense.formation.leader_follower` (unicycle formations with range sensors),
:mod:`~mobisense.formation.distributed` (sensor meshes in an advection–diffusion field), and
:mod:`~mobisense.formation.scenarios` (every simulation behind one shape: load → run → result).
"""

from ..core.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "load_scenario": "mobisense.formation.scenarios",
        "Scenario": "mobisense.formation.scenarios",
        "SimulationResult": "mobisense.formation.simulation_result",
        "JacobiTransform": "mobisense.formation.jacobi",
        "FixedShapeController": "mobisense.formation.shape_control",
        "RotatingShapeController": "mobisense.formation.shape_control",
        "LevelCurveController": "mobisense.formation.level_curve",
        "PlatformLimits": "mobisense.formation.platforms",
    },
)
