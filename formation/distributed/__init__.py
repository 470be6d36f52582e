"""Sensor meshes in an advection–diffusion field: gradient-based formations and the distributed-filter simulation."""

from ...core.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "DistributedScenario": "mobisense.formation.distributed.simulation",
        "run_distributed": "mobisense.formation.distributed.simulation",
        "simulate": "mobisense.formation.distributed.simulation",
        "error_table": "mobisense.formation.distributed.simulation",
        "DistributedResult": "mobisense.formation.distributed.simulation",
        "GradientFormation": "mobisense.formation.distributed.gradient_formation",
        "FormationOptions": "mobisense.formation.distributed.gradient_formation",
        "plot_paths": "mobisense.formation.distributed.plots",
        "plot_estimates": "mobisense.formation.distributed.plots",
    },
)
