"""Estimation: cooperative, coloured, switching and distributed Kalman filters, Hessians, steady-state design.

Layout: :mod:`~mobisense.estimation.kalman` (the predict/update kernels every filter uses),
:mod:`~mobisense.estimation.fields` (scalar fields with exact derivatives), :mod:`~mobisense.estimation.cooperative`
(information model, cooperative and coloured filters, Hessian estimation, steady states, formation design),
:mod:`~mobisense.estimation.tracking` (range-sensor ring, switching filter), :mod:`~mobisense.estimation.distributed`
(sensor meshes, the finite-volume PDE constraint, the distributed constrained filter).
"""

from ..core.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "Field": "mobisense.estimation.fields.base",
        "make_field": "mobisense.estimation.fields.base",
        "CooperativeNoise": "mobisense.estimation.cooperative.noise_config",
        "CooperativeKalmanFilter": "mobisense.estimation.cooperative.filter",
        "run_cooperative_filter": "mobisense.estimation.cooperative.filter",
        "run_coloured_filter": "mobisense.estimation.cooperative.coloured_filter",
        "SpatialNoise": "mobisense.estimation.cooperative.spatial_noise",
        "steady_state": "mobisense.estimation.cooperative.steady_state",
        "cross_steady_state": "mobisense.estimation.cooperative.steady_state",
        "design_cross_formation": "mobisense.estimation.cooperative.formation_design",
        "design_formation": "mobisense.estimation.cooperative.design_study",
        "gramians": "mobisense.estimation.cooperative.gramians",
        "SwitchingKalmanFilter": "mobisense.estimation.tracking.switching_filter",
        "RangeSensorRing": "mobisense.estimation.tracking.range_ring",
        "DistributedFilter": "mobisense.estimation.distributed.filter",
        "SensorMesh": "mobisense.estimation.distributed.mesh",
    },
)
