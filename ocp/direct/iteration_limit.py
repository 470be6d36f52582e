"""An Ipopt iteration callback that stops a solve once an iteration budget is spent, or on Ctrl-C.

CasADi fixes Ipopt's ``max_iter`` when the solver is created; the budget of a homotopy that must not cost
more than a multiple of a cold solve (docs/theory/direct.md §5.6) is known only at run time. Ipopt calls the
callback after every iteration; when it returns 1, Ipopt stops with ``User_Requested_Stop``. It also returns
1 once SIGINT or SIGTERM has arrived (:func:`mobisense.core.interrupts.interrupt_received`: a signal during
Ipopt is only recorded), so that a long solve stops within an iteration; the caller then raises
(:func:`~mobisense.core.interrupts.raise_if_interrupted`).
"""

from __future__ import annotations

import casadi as ca

from ...core.interrupts import interrupt_received

__all__ = ["IterationLimit"]


class IterationLimit(ca.Callback):
    """Stop after ``limit`` iterations of the current solve (``limit=None``: never), or once interrupted.

    Parameters
    ----------
    nw, ng, n_parameters : int
        Sizes of the NLP the callback is attached to.
    """

    def __init__(self, nw: int, ng: int, n_parameters: int) -> None:
        ca.Callback.__init__(self)
        self._sizes = {"f": 1, "x": nw, "lam_x": nw, "g": ng, "lam_g": ng, "p": n_parameters, "lam_p": n_parameters}
        self.limit: int | None = None
        self.count = 0
        self.construct("iteration_limit", {})

    def reset(self, limit: int | None) -> None:
        """Start counting for a new solve that may take ``limit`` iterations."""
        self.count, self.limit = 0, limit

    def get_n_in(self) -> int:
        """Inputs: the nlpsol outputs."""
        return ca.nlpsol_n_out()

    def get_n_out(self) -> int:
        """One output: 1 to stop."""
        return 1

    def get_name_in(self, i: int) -> str:
        """Names of the nlpsol outputs."""
        return ca.nlpsol_out(i)

    def get_name_out(self, i: int) -> str:
        """The output's name."""
        return "ret"

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        """Dense inputs of the NLP's sizes."""
        return ca.Sparsity.dense(self._sizes.get(ca.nlpsol_out(i), 0), 1)

    def eval(self, arg: list) -> list:
        """Count the iteration; 1 (stop) once more than ``limit`` have been taken or a signal arrived."""
        self.count += 1
        return [int(interrupt_received() or (self.limit is not None and self.count > self.limit))]
