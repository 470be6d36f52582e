"""Distributed constrained cooperative Kalman filter: sensor meshes, the finite-volume PDE constraint, the filter."""

from ...core.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "SensorMesh": "mobisense.estimation.distributed.mesh",
        "MeshError": "mobisense.estimation.distributed.mesh",
        "grid_network": "mobisense.estimation.distributed.mesh",
        "pde_constraint": "mobisense.estimation.distributed.fvm",
        "project": "mobisense.estimation.distributed.fvm",
        "DistributedFilter": "mobisense.estimation.distributed.filter",
        "FilterOptions": "mobisense.estimation.distributed.filter",
        "PdeModel": "mobisense.estimation.distributed.filter",
    },
)
