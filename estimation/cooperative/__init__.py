"""Cooperative exploration: information model, cooperative and coloured filters, Hessians, steady-state design."""

from ...core.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "taylor_matrices": "mobisense.estimation.cooperative.information_model",
        "transition_matrix": "mobisense.estimation.cooperative.information_model",
        "cross_formation": "mobisense.estimation.cooperative.information_model",
        "CooperativeNoise": "mobisense.estimation.cooperative.noise_config",
        "NoiseConfig": "mobisense.estimation.cooperative.noise_config",
        "SpatialNoise": "mobisense.estimation.cooperative.spatial_noise",
        "CooperativeKalmanFilter": "mobisense.estimation.cooperative.filter",
        "CooperativeFilterResult": "mobisense.estimation.cooperative.filter",
        "run_cooperative_filter": "mobisense.estimation.cooperative.filter",
        "run_coloured_filter": "mobisense.estimation.cooperative.coloured_filter",
        "one_step_filter": "mobisense.estimation.cooperative.hessian",
        "least_squares_hessian": "mobisense.estimation.cooperative.hessian",
        "curvature_hessian": "mobisense.estimation.cooperative.hessian",
        "cross_steady_state": "mobisense.estimation.cooperative.steady_state",
        "cross_trace": "mobisense.estimation.cooperative.steady_state",
        "design_cross_formation": "mobisense.estimation.cooperative.formation_design",
        "adaptive_shape_step": "mobisense.estimation.cooperative.formation_design",
        "FormationFile": "mobisense.estimation.cooperative.design_study",
        "DesignStudy": "mobisense.estimation.cooperative.design_study",
        "design_formation": "mobisense.estimation.cooperative.design_study",
        "model_sequence": "mobisense.estimation.cooperative.filter",
    },
)
