"""The ``solver:`` block of a problem file: method, strategy, transcription, homotopy, BVP and Ipopt options.

Split from :mod:`mobisense.ocp.problem` (which re-exports every name) so each module stays one concept: what
the problem is there, how to solve it here (docs/theory/direct.md §5, indirect.md §3).
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from ..core.config import FiniteFloat, InvalidValue, StrictModel
from .field import ShootingOptions
from .registries import BVPSolverName, HomotopyModeName, MethodName, SchemeName, StrategyName

__all__ = ["CollocationOptions", "MIN_HOMOTOPY_STEP", "HomotopyOptions", "BVPOptions", "SolverOptions"]


class CollocationOptions(StrictModel):
    """Direct-collocation transcription: scheme, polynomial degree, number of intervals."""

    scheme: SchemeName = "radau"
    degree: int = Field(3, ge=1, le=9)
    intervals: int = Field(100, ge=1, le=100_000)


#: smallest ε step: at most 10⁴ steps from ε = 0 to 1
MIN_HOMOTOPY_STEP = 1e-4


class HomotopyOptions(StrictModel):
    """ε-continuation (docs/theory/direct.md §5.2): ``fixed`` steps of ``step``, ``adaptive`` steps, or ``none``.

    ``step`` ≥ 10⁻⁴ (at most 10⁴ fixed steps); ``adaptive`` halves a failed step down to ``min_step`` ≥ 10⁻⁶
    and makes at most :data:`mobisense.ocp.homotopy.MAX_ATTEMPTS` attempts.

    ``budget``: the direct method's continuation (strategies ``homotopy`` and ``thorough``) may take at most
    ``budget`` × the Ipopt iterations of the cold ε = 1 solve; beyond that it is stopped and the cold solve is
    kept (docs/theory/direct.md §5.6; ``null``: no limit, and strategy ``homotopy`` runs no cold solve).
    """

    mode: HomotopyModeName = "fixed"
    step: float = Field(0.05, ge=MIN_HOMOTOPY_STEP, le=1.0)
    min_step: float = Field(1e-3, ge=1e-6, le=1.0)
    growth: float = Field(2.0, ge=1.0, le=10.0)
    budget: float | None = Field(1.5, gt=0.0, le=1000.0)

    @model_validator(mode="after")
    def _steps(self) -> HomotopyOptions:
        if self.min_step > self.step:
            raise InvalidValue("min_step", f"expected min_step <= step = {self.step:g}, got {self.min_step:g}")
        return self


class BVPOptions(StrictModel):
    """Indirect method: BVP solver of the ε-continuation and of the direct-seeded refinement.

    Theory: docs/theory/indirect.md §4.

    ``collocation`` uses the scheme and degree of ``solver.collocation`` on ``intervals`` uniform intervals
    (default: ``solver.collocation.intervals``), Newton to ``tolerance`` (max-norm of the scaled residual),
    and arclength continuation; ``scipy`` is ``scipy.integrate.solve_bvp`` to ``scipy_tolerance``. With
    ``polish`` the collocation result at ε = 1 is re-solved by ``solve_bvp`` on an adaptive mesh.
    """

    solver: BVPSolverName = Field("collocation", description="BVP solver of the ε-continuation")
    refine_solver: BVPSolverName = Field(
        "scipy", description="BVP solver of the direct-seeded refinement (method 'both')"
    )
    intervals: int | None = Field(None, ge=2, le=100_000)
    tolerance: float = Field(1e-10, gt=0.0, lt=1e-2)
    newton_iterations: int = Field(50, ge=1, le=10_000)
    max_arclength_steps: int = Field(400, ge=1, le=100_000)
    # solve_bvp raises anything below 100 machine epsilons to that, with a warning: refused instead
    scipy_tolerance: float = Field(1e-8, ge=2.3e-14, lt=1e-2, description="solve_bvp tol (relative residual)")
    max_nodes: int = Field(
        20_000, ge=10, le=10_000_000, description="solve_bvp mesh limit (bounds the time of a failing step)"
    )
    polish: bool = Field(
        True, description="re-solve the collocation result at ε = 1 with solve_bvp (adaptive mesh to scipy_tolerance)"
    )


class SolverOptions(StrictModel):
    """How to solve: method, transcription, homotopy and Ipopt tolerances."""

    method: MethodName = Field(
        "direct", description="direct collocation, indirect (PMP), both, or shooting (default for a field)"
    )
    strategy: StrategyName = Field(
        "auto", description="direct method: which starts to solve and which optimum to keep (direct.md §5.6)"
    )
    starts: int = Field(4, ge=1, le=1000, description="random starts of strategy thorough; at most these in auto")
    consensus: int = Field(
        3,
        ge=1,
        le=1001,
        description="strategy auto stops drawing random starts once this many starts reach the lowest cost",
    )
    agreement: float = Field(
        1e-6, gt=0.0, lt=1.0, description="relative cost difference under which two optima count as one"
    )
    codegen: Literal["auto", "on", "off"] = Field(
        "auto",
        description="compile the collocation kernels with the C compiler, cached on disk (auto: in the background "
        "on a cache miss, this run uses the virtual machine; on: wait for the compiler)",
    )
    collocation: CollocationOptions = CollocationOptions()
    shooting: ShootingOptions = ShootingOptions()
    homotopy: HomotopyOptions = HomotopyOptions()
    bvp: BVPOptions = BVPOptions()
    tolerance: float = Field(1e-9, gt=0.0, lt=1e-2, description="Ipopt tol (scaled NLP error)")
    max_iterations: int = Field(500, ge=1, le=1_000_000)
    time_limit: FiniteFloat | None = Field(None, gt=0.0, le=1e9, description="wall-clock limit of each Ipopt solve (s)")

    @model_validator(mode="after")
    def _shooting_ignores_nothing(self) -> SolverOptions:
        """Refuse a collocation or strategy setting the shooting method would silently not use.

        Compared with the defaults rather than with the keys given, so that a normalised problem (every default
        written out, as stored in solution files) reads back.
        """
        if self.method != "shooting":
            return self
        for key, why in SHOOTING_IGNORES.items():
            value, default = getattr(self, key), type(self).model_fields[key].default
            if value != default:
                if isinstance(value, StrictModel):  # name the sub-key that differs
                    key += "." + next(k for k in type(value).model_fields if getattr(value, k) != getattr(default, k))
                raise InvalidValue(f"solver.{key}", f"not used by solver.method 'shooting' ({why}); leave it out "
                                   "or use method 'direct'")  # fmt: skip
        return self


SHOOTING_IGNORES = {
    "strategy": "it runs its own ε schedule, docs/theory/field.md §3.4",
    "starts": "its random starts are solver.shooting.starts",
    "consensus": "its random starts are solver.shooting.starts",
    "homotopy": "its ε schedule is solver.shooting.homotopy",
    "collocation": "it has no collocation polynomials; its grid is solver.shooting.intervals",
    "codegen": "it compiles no collocation kernels",
}
"""The ``solver`` keys of the direct method that a field's shooting solve does not use, and why."""
