"""Direct collocation of the mobile-sensor problem: the NLP transcription and the ε-continuation driver."""

from ...core.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "solve_direct": "mobisense.ocp.direct.solver",
        "solve_starts": "mobisense.ocp.direct.solver",
        "DirectCollocation": "mobisense.ocp.direct.transcription",
        "NLPResult": "mobisense.ocp.direct.transcription",
        "IPOPT_DEFAULTS": "mobisense.ocp.direct.transcription",
        "transcription_for": "mobisense.ocp.direct.transcription",
        "transcription_cache_hits": "mobisense.ocp.direct.transcription",
        "initial_guess": "mobisense.ocp.direct.guesses",
        "state_grid": "mobisense.ocp.direct.guesses",
        "coasting_baseline": "mobisense.ocp.direct.guesses",
        "coasting_start": "mobisense.ocp.direct.guesses",
        "random_guess": "mobisense.ocp.direct.guesses",
        "clear_transcription_cache": "mobisense.ocp.direct.transcription",
        "solution_sensitivities": "mobisense.ocp.direct.sensitivities",
        "resimulate_sensors": "mobisense.ocp.direct.path_report",
        "watch_iterations": "mobisense.ocp.direct.iteration_limit",
        "worst_violation": "mobisense.ocp.direct.violations",
        "constraint_rows": "mobisense.ocp.direct.violations",
        "IpoptIteration": "mobisense.ocp.direct.iteration_limit",
    },
)
