"""Target tracking with directional range sensors: the sensor ring and the switching Kalman filter."""

from ...core.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "RangeSensorRing": "mobisense.estimation.tracking.range_ring",
        "triangulate": "mobisense.estimation.tracking.range_ring",
        "SwitchingKalmanFilter": "mobisense.estimation.tracking.switching_filter",
        "random_walk_model": "mobisense.estimation.tracking.switching_filter",
        "C_POSITION": "mobisense.estimation.tracking.switching_filter",
        "KHEPERA_MOUNT_ANGLES_DEG": "mobisense.estimation.tracking.range_ring",
        "KHEPERA_PAIRS": "mobisense.estimation.tracking.range_ring",
    },
)
