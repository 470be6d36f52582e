"""How a solve started and how it ended: the codes ``summary.json`` and the sweep table show.

Kept apart from :mod:`mobisense.ocp.solution` (which re-exports them) so that the modules the solution
uses, such as :mod:`mobisense.ocp.solution_warnings`, can name them too.
"""

from __future__ import annotations

from enum import Enum

__all__ = ["SolveStatus", "StartKind"]


class SolveStatus(str, Enum):
    """Outcome of a solve: ``solved`` (ε = 1 reached and converged) or ``failed`` (what was solved is kept)."""

    SOLVED = "solved"
    FAILED = "failed"


class StartKind(str, Enum):
    """How a direct solve started (``stats["start"]``; the value is what ``summary.json`` shows)."""

    CONTINUATION = "from coasting (solver.strategy)"
    WARM = "warm start from init"
    WARM_FAILED = "warm start from init failed; from coasting (solver.strategy)"
    GUESS = "initial guess, ε = 1 directly"
    COARSE = "ε-homotopy on the coarse grid (solver.shooting)"
    INIT_WITHOUT_POINT = "init ignored: it carries no converged ε = 1 NLP point"
    INIT_OTHER_LAYOUT = "init ignored: different structure or grid"
    INIT_OTHER_METHOD = "init ignored: solved by another method"
