"""Indirect method: the Pontryagin boundary-value problem, its solvers and the ε-continuation through folds."""

from ...core.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "solve_indirect": "mobisense.ocp.indirect.solver",
        "indirect_continuation": "mobisense.ocp.indirect.solver",
        "refine_from_direct": "mobisense.ocp.indirect.solver",
        "make_bvp_solver": "mobisense.ocp.indirect.solver",
        "kalman_guess": "mobisense.ocp.indirect.solver",
        "follow_schedule": "mobisense.ocp.indirect.solver",
        "solution_from_bvp": "mobisense.ocp.indirect.solver",
        "HamiltonianSystem": "mobisense.ocp.indirect.hamiltonian",
        "hamiltonian_system": "mobisense.ocp.indirect.hamiltonian",
        "BVPSolver": "mobisense.ocp.indirect.bvp_solvers",
        "BVPSolution": "mobisense.ocp.indirect.bvp_solvers",
        "register_bvp_solver": "mobisense.ocp.indirect.bvp_solvers",
        "collocation_mesh": "mobisense.ocp.indirect.collocation_newton",
        "ArclengthTracker": "mobisense.ocp.indirect.arclength",
        "optimality_residuals": "mobisense.ocp.indirect.residuals",
    },
)
