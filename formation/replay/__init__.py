"""Closed-loop replays: formations on a field, and optimised plans flown by platforms with Monte Carlo validation."""

from ...core.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "run_field_replay": "mobisense.formation.replay.runs",
        "run_plan_replay": "mobisense.formation.replay.runs",
        "FieldReplayResult": "mobisense.formation.replay.runs",
        "PlanReplayResult": "mobisense.formation.replay.runs",
        "FieldReplayScenario": "mobisense.formation.replay.scenario",
        "OcpReplayScenario": "mobisense.formation.replay.plan",
        "replay_solution": "mobisense.formation.replay.plan",
        "ReferenceTrajectory": "mobisense.formation.replay.reference",
        "TrackingController": "mobisense.formation.replay.reference",
        "plot_paths": "mobisense.formation.replay.plots",
        "ClosedLoopEstimator": "mobisense.formation.replay.estimator",
        "build_system": "mobisense.formation.replay.simulation",
        "mean_abs_curvature": "mobisense.formation.replay.results",
        "simulate": "mobisense.formation.replay.simulation",
    },
)
