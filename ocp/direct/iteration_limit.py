"""An Ipopt iteration callback: an iteration budget, Ctrl-C, and live progress of a long solve.

CasADi fixes Ipopt's ``max_iter`` when the solver is created; the budget of a homotopy that must not cost
more than a multiple of a cold solve (docs/theory/direct.md §5.6) is known only at run time. Ipopt calls the
callback after every iteration; when it returns 1, Ipopt stops with ``User_Requested_Stop``. It also returns
1 once SIGINT or SIGTERM has arrived (:func:`mobisense.core.interrupts.interrupt_received`: a signal during
Ipopt is only recorded), so that a long solve stops within an iteration; the caller then raises
(:func:`~mobisense.core.interrupts.raise_if_interrupted`).

Inside :func:`watch_iterations` each iteration is also reported to a listener, with the NLP objective and the
largest constraint violation: the progress display of ``mobisense solve`` shows a long Ipopt call moving
instead of a still line. A context variable carries the listener, so that no solve signature changes.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...core.interrupts import interrupt_received

__all__ = ["INTERRUPT_CHECK_VARIABLES", "IpoptIteration", "IterationLimit", "watch_iterations"]

#: Direct-collocation NLPs with at least this many variables get the callback on every solve, so that Ctrl-C or SIGTERM
#: stops Ipopt within one iteration (a solve of n = N = 4, K = 300 is one 50-s Ipopt call). It costs ≈ 40 µs
#: per iteration (CasADi hands the callback the iterate): 2.6 % of an iteration of n = N = 1, K = 60 (780
#: variables, 1.3 ms per cold iteration), 1 % at K = 200 (2600 variables, 3.9 ms) and 0.8 % at K = 800 (10 400)
INTERRUPT_CHECK_VARIABLES = 4000


@dataclass(frozen=True)
class IpoptIteration:
    """One Ipopt iteration of a solve with the callback (large direct NLPs, field solves).

    ``iteration`` counts from 0 (the starting point); ``objective`` is Ipopt's objective, J (or J_ε) divided by
    the problem's cost scale, dimensionless; ``violation`` the largest violation of the NLP's scaled constraints
    (0 when all hold).
    """

    iteration: int
    objective: float
    violation: float


_LISTENER: contextvars.ContextVar[Callable[[IpoptIteration], None] | None] = contextvars.ContextVar(
    "ipopt_iteration_listener", default=None
)


@contextlib.contextmanager
def watch_iterations(listener: Callable[[IpoptIteration], None]) -> Iterator[None]:
    """Report every Ipopt iteration of the solves with the callback, inside the block, to ``listener``.

    Only solves that carry the callback report (direct NLPs of at least
    :data:`INTERRUPT_CHECK_VARIABLES` variables, budgeted continuations,
    field solves); smaller solves report their steps only. An exception raised by ``listener`` is not
    propagated through Ipopt: the listener is dropped for the rest of the block.
    """
    token = _LISTENER.set(listener)
    try:
        yield
    finally:
        _LISTENER.reset(token)


class IterationLimit(ca.Callback):
    """Stop after ``limit`` iterations of the current solve (``limit=None``: never), or once interrupted.

    Parameters
    ----------
    nw, ng, n_parameters : int
        Sizes of the NLP the callback is attached to.
    lbg, ubg : ndarray, shape (ng,), optional
        The constraint bounds, for the violation reported to a :func:`watch_iterations` listener (0 if not given).
    """

    def __init__(
        self, nw: int, ng: int, n_parameters: int, lbg: np.ndarray | None = None, ubg: np.ndarray | None = None
    ) -> None:
        ca.Callback.__init__(self)
        self._sizes = {"f": 1, "x": nw, "lam_x": nw, "g": ng, "lam_g": ng, "p": n_parameters, "lam_p": n_parameters}
        self._bounds = None if lbg is None or ubg is None else (np.asarray(lbg, float), np.asarray(ubg, float))
        self._index = {ca.nlpsol_out(i): i for i in range(ca.nlpsol_n_out())}
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
        """Count the iteration, report it if watched; 1 (stop) once over ``limit`` or a signal arrived."""
        listener = _LISTENER.get()
        if listener is not None:
            self._report(listener, arg)
        self.count += 1
        return [int(interrupt_received() or (self.limit is not None and self.count > self.limit))]

    def _report(self, listener: Callable[[IpoptIteration], None], arg: list) -> None:
        violation = 0.0
        if self._bounds is not None and self._bounds[0].size:
            g = np.asarray(arg[self._index["g"]]).ravel()
            lbg, ubg = self._bounds
            violation = float(max(np.max(lbg - g, initial=0.0), np.max(g - ubg, initial=0.0)))
        try:
            listener(IpoptIteration(self.count, float(arg[self._index["f"]]), violation))
        except Exception:  # noqa: BLE001  (an exception cannot cross Ipopt; a broken display must not stop a solve)
            _LISTENER.set(None)
