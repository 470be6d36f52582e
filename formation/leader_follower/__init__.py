"""Leader–follower unicycle formations: controls, references, paths, sensing and the closed-loop simulation."""

from ...core.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "LeaderFollowerScenario": "mobisense.formation.leader_follower.scenario",
        "run_leader_follower": "mobisense.formation.leader_follower.runs",
        "simulate_scenario": "mobisense.formation.leader_follower.runs",
        "build_ring": "mobisense.formation.leader_follower.runs",
        "summarize": "mobisense.formation.leader_follower.runs",
        "LeaderFollowerResult": "mobisense.formation.leader_follower.runs",
        "Control1": "mobisense.formation.leader_follower.controls",
        "Control2": "mobisense.formation.leader_follower.controls",
        "Control3": "mobisense.formation.leader_follower.controls",
        "CONTROLS": "mobisense.formation.leader_follower.controls",
        "BearingRampReference": "mobisense.formation.leader_follower.references",
        "SteppedReference": "mobisense.formation.leader_follower.references",
        "plot_paths": "mobisense.formation.leader_follower.plots",
        "plot_formation_errors": "mobisense.formation.leader_follower.plots",
        "plot_reference_point_errors": "mobisense.formation.leader_follower.plots",
        "plot_deviation": "mobisense.formation.leader_follower.plots",
        "plot_references": "mobisense.formation.leader_follower.plots",
        "plot_active_pairs": "mobisense.formation.leader_follower.plots",
    },
)
