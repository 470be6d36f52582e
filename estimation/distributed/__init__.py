"""Distributed constrained cooperative Kalman filter: sensor meshes, the finite-volume PDE constraint, the filter."""

from ...core.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "SensorMesh": "mobisense.estimation.distributed.mesh",
        "MeshError": "mobisense.estimation.distributed.mesh",
        "grid_network": "mobisense.estimation.distributed.mesh",
        "paper_network": "mobisense.estimation.distributed.mesh",
        "pde_constraint": "mobisense.estimation.distributed.fvm",
        "project": "mobisense.estimation.distributed.fvm",
        "DistributedFilter": "mobisense.estimation.distributed.filter",
        "FilterOptions": "mobisense.estimation.distributed.filter",
        "PdeModel": "mobisense.estimation.distributed.filter",
        "AssumedPde": "mobisense.estimation.distributed.filter",
        "error_map": "mobisense.estimation.distributed.stability",
        "spectral_radius": "mobisense.estimation.distributed.stability",
        "steady_gain": "mobisense.estimation.distributed.stability",
        "rescale_length_unit": "mobisense.estimation.distributed.stability",
        "translating_mesh_errors": "mobisense.estimation.distributed.stability",
    },
)
