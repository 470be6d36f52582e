"""Activity and violation of the path constraints of a direct solution (docs/theory/path_constraints.md §3).

The NLP enforces the constraints at the collocation nodes only. :func:`resimulate_sensors` re-integrates
the sensors' double integrators exactly under the optimised control (the Lagrange polynomial through each
interval's d control nodes, integrated in closed form from the interval start of the *re-simulated*
path, so the errors of the collocation do not hide), and :func:`constraint_report` gives, for each
constraint group, whether it is active at the optimum, its largest multiplier and the largest violation
on the re-simulated path between the nodes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.polynomial import polynomial as npoly

from ..collocation import collocation_scheme
from ..path_constraints import group_names, margins
from ..problem import Problem

__all__ = ["ACTIVE_TOLERANCE", "FlownPath", "resimulate_sensors", "refine_maximum", "rows_active", "constraint_report"]

#: a group is active when a scaled row is within this of its bound at a node (Ipopt's tol is 1e-9) …
ACTIVE_TOLERANCE = 1e-6
#: … or when a row's multiplier, relative to J's scale (the NLP's objective is J / cost_scale), is at least this:
#: an inactive row's multiplier is μ / slack ≲ 1e-8 at Ipopt's final μ, a binding one's is what J pays for it
ACTIVE_MULTIPLIER = 1e-6


class FlownPath:
    """The sensors flown under the collocation control: exact positions and velocities at any time.

    The control on interval k is the Lagrange polynomial through its d control nodes; the double integrator
    is integrated in closed form from the interval's start on the *re-simulated* path (so the collocation's
    errors do not hide).

    Parameters
    ----------
    problem : Problem
    u : ndarray, shape (K, d, N, 2)
        Controls at the collocation nodes (L/T²).
    scheme, degree : str, int
        The collocation scheme of ``u``.
    """

    def __init__(self, problem: Problem, u: np.ndarray, scheme: str, degree: int) -> None:
        self.u = np.asarray(u, float)
        self.K = self.u.shape[0]
        self.t0, tf = problem.horizon.t0, problem.horizon.tf
        self.h = (tf - self.t0) / self.K
        tau = collocation_scheme(scheme, degree).tau[1:]
        basis = np.linalg.inv(np.vander(tau, degree, increasing=True)).T  # row j: coefficients of ℓ_j
        # monomial coefficients (rows j, increasing powers up to d + 1) of ∫_0^τ ℓ_j and ∫_0^τ ∫_0^s ℓ_j
        self.I1 = np.array([np.r_[npoly.polyint(c), 0.0] for c in basis])
        self.I2 = np.array([npoly.polyint(npoly.polyint(c)) for c in basis])
        # the interval starts, each flown from the one before: v_{k+1} = v_k + h Σ_j u_kj ∫_0^1 ℓ_j and
        # p_{k+1} = p_k + h v_k + h² Σ_j u_kj ∫_0^1 ∫_0^s ℓ_j
        dv = self.h * np.einsum("j,kjnc->knc", self.I1.sum(axis=1), self.u)
        dp2 = self.h**2 * np.einsum("j,kjnc->knc", self.I2.sum(axis=1), self.u)
        v0 = np.asarray([sensor.v0 for sensor in problem.sensors], float)
        self.v_start = np.concatenate([v0[None], v0 + np.cumsum(dv, axis=0)])  # (K + 1, N, 2)
        p0 = np.asarray([sensor.p0 for sensor in problem.sensors], float)
        self.p_start = np.concatenate([p0[None], p0 + np.cumsum(self.h * self.v_start[:-1] + dp2, axis=0)])

    def _within(self, k: np.ndarray, s: np.ndarray, pk: np.ndarray, vk: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """p, v at fraction ``s`` ∈ [0, 1] of intervals ``k`` (T,) flown from (pk, vk) (T, N, 2)."""
        powers = np.vander(s, self.I2.shape[1], increasing=True).T  # (d + 2, T)
        W1, W2 = self.I1 @ powers, self.I2 @ powers  # (d, T)
        u = self.u[k]  # (T, d, N, 2)
        v = vk + self.h * np.einsum("jt,tjnc->tnc", W1, u)
        p = pk + self.h * s[:, None, None] * vk + self.h**2 * np.einsum("jt,tjnc->tnc", W2, u)
        return p, v

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities at times ``t`` (T,) in [t0, tf], each (T, N, 2)."""
        x = (np.asarray(t, float) - self.t0) / self.h
        k = np.clip(np.floor(x).astype(int), 0, self.K - 1)
        return self._within(k, x - k, self.p_start[k], self.v_start[k])

    def sampled(self, per_interval: int = 20) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Times (K·per_interval + 1,), p and v (T, N, 2) on a grid of ``per_interval`` steps per interval."""
        t = self.t0 + self.h * np.linspace(0.0, self.K, self.K * per_interval + 1)
        p, v = self.at(t)
        return t, p, v


def resimulate_sensors(
    problem: Problem, u: np.ndarray, scheme: str, degree: int, per_interval: int = 20
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions and velocities of the sensors flown under the collocation control, on a fine grid.

    Parameters
    ----------
    problem, u, scheme, degree
        As for :class:`FlownPath`.
    per_interval : int
        Sample times per interval (uniform in τ ∈ (0, 1]).

    Returns
    -------
    t : ndarray, shape (K·per_interval + 1,)
    p, v : ndarray, shape (T, N, 2)
    """
    return FlownPath(problem, u, scheme, degree).sampled(per_interval)


def refine_maximum(f: Callable[[np.ndarray], np.ndarray], t: np.ndarray, values: np.ndarray,
                   candidates: int = 3) -> tuple[float, float]:  # fmt: skip
    """The largest value of ``f`` near its largest samples, and where: (value, time).

    ``values = f(t)`` on a grid ``t`` (sorted) may miss a peak between samples (a path grazing a polygon's corner:
    its depth has a kink there; sampled 20 times per interval, keep_out.yaml on K = 12 gave 0.047 for 0.061).
    Around each of the ``candidates`` largest local maxima of the samples (those within twice the largest change
    between neighbouring samples of the largest sample), the bracket of its two neighbours is
    searched on 17 points and shrunk to the best point's neighbours, until it is 1e-9 of the whole span wide
    (each round: an eighth of the bracket).
    """
    values = np.asarray(values, float)
    best = int(np.argmax(values))
    value, when = float(values[best]), float(t[best])
    padded = np.r_[-np.inf, values, -np.inf]
    peaks = np.flatnonzero((values >= padded[:-2]) & (values >= padded[2:]))  # local maxima of the samples
    # a peak between two samples rises above them by about the change between neighbouring samples at most:
    # lower local maxima cannot hold the largest value
    rise = float(np.abs(np.diff(values)).max()) if len(values) > 1 else 0.0
    peaks = peaks[values[peaks] >= value - 2.0 * rise]
    width = 1e-9 * max(float(t[-1] - t[0]), np.finfo(float).tiny)
    for i in peaks[np.argsort(values[peaks])[::-1][:candidates]]:
        lo, hi = float(t[max(i - 1, 0)]), float(t[min(i + 1, len(t) - 1)])
        while hi - lo > width:
            grid = np.linspace(lo, hi, 17)
            sampled = np.asarray(f(grid), float)
            j = int(np.argmax(sampled))
            if sampled[j] > value:
                value, when = float(sampled[j]), float(grid[j])
            lo, hi = grid[max(j - 1, 0)], grid[min(j + 1, 16)]
    return value, when


def constraint_report(problem: Problem, tr: Any, result: Any, P: np.ndarray, u: np.ndarray) -> dict[str, Any]:
    """``{group: {active, max_violation, max_violation_at_nodes, max_multiplier, units}}`` of a direct solution.

    The groups are the path constraints' and ``u_max`` (the bounds on |u|, sampled on the controls' polynomials).

    Parameters
    ----------
    problem : Problem
    tr : DirectCollocation
    result : NLPResult
        The converged NLP point.
    P : ndarray
        Its parameters.
    u : ndarray, shape (K, d, N, 2)
        Controls at the nodes.

    Notes
    -----
    ``max_violation`` is the largest physical violation (penetration depth (L), separation deficit (L),
    speed excess (L/T), distance outside the workspace (L), |u| − u_max (L/T²); ≤ 0 means satisfied with that
    margin) on the re-simulated path; ``max_multiplier`` the largest multiplier of the group's rows in cost units
    per unit of the row's physical value (zero when inactive); ``units`` the unit of ``max_violation``, the
    problem's length (or speed) unit in UDUNITS, as in ``solution.nc``.
    """
    k, K, d = tr.kernels, tr.intervals, tr.colloc.degree
    system = problem.units.system()  # the problem's declared units, as in solution.nc (UDUNITS)
    cost_scale = float(tr.layout.unpack(np.asarray(P, float))["cost_scale"][0])
    out: dict[str, Any] = {}

    def block(values: np.ndarray, first: int, count: int) -> np.ndarray:
        """The rows ``first … first + count`` of every interval, as (K·d, count / d) (path rows: one per node)."""
        rows = values[: K * k.nr].reshape(K, k.nr)[:, first : first + count]
        return rows.reshape(K * d, -1) if count % d == 0 else rows

    def rows_of(first: int, count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Scaled rows, NLP multipliers and multipliers per physical unit of those rows."""
        rows, lam = block(result.g, first, count), block(result.lam_g, first, count)
        return rows, lam, lam * cost_scale / block(tr.constraint_scales(P), first, count)

    if k.n_bound:
        out["u_max"] = _control_report(problem, tr, u, *rows_of(k.n_gap + k.n_path, k.n_bound), system.of(length=1,
                                       time=-2))  # fmt: skip
    if not k.n_cons:
        return out
    constraints = problem.constraints
    rows, lam_nlp, lam = rows_of(k.nr - k.n_cons, k.n_cons)
    groups = np.array([g for g, _ in tr.model.path_labels])
    flown = FlownPath(problem, u, tr.colloc.scheme, d)
    t, p, v = flown.sampled()
    violation = margins(constraints, p, v)
    _, p_nodes, v_nodes = _node_states(tr, result, P)
    at_nodes = margins(constraints, p_nodes, v_nodes)
    length, speed = system.of(length=1), system.of(length=1, time=-1)
    for name in group_names(tr.structure.path):
        mask = groups == name
        largest, when = refine_maximum(lambda times, name=name: margins(constraints, *flown.at(times), only=name)[name],
                                       t, violation[name])  # fmt: skip
        out[name] = {
            "active": rows_active(rows[:, mask], lam_nlp[:, mask]),
            "max_violation": largest,
            "max_violation_time": when,
            "max_violation_at_nodes": float(at_nodes[name].max()),
            "max_multiplier": float(np.abs(lam[:, mask]).max()),
            "units": speed if name == "max_speed" else length,
        }
    return out


def rows_active(rows: np.ndarray, multipliers: np.ndarray) -> bool:
    """Whether rows ``g ≤ 0`` bind: one within ACTIVE_TOLERANCE of its bound, or a multiplier of ACTIVE_MULTIPLIER.

    An interior-point optimum keeps every row a little inside its bound (slack × multiplier ≈ μ), so the slack
    alone misses binding rows: a speed limit that raised J by 1e-3 kept slacks of 2e-6…9e-6. The multiplier is
    the price J pays for the row (in units of J's scale, the NLP's objective): ≲ 1e-8 for a row well inside.
    """
    return bool(rows.max() >= -ACTIVE_TOLERANCE or np.abs(multipliers).max() >= ACTIVE_MULTIPLIER)


def _control_report(problem: Problem, tr: Any, u: np.ndarray, rows: np.ndarray, lam_nlp: np.ndarray,
                    lam: np.ndarray, units: str) -> dict[str, Any]:  # fmt: skip
    """The ``u_max`` entry: |u(t)| − u_max of the bounded sensors between the nodes, activity, multipliers."""
    K = tr.intervals
    s = np.linspace(0.0, 1.0, 21)  # from the interval's start (the right limit there) to its end
    samples = np.einsum("sj,kjnc->ksnc", tr.colloc.interpolation_matrix(s), u)  # (K, S, N, 2)
    bounded = [i for i, sensor in enumerate(problem.sensors) if sensor.u_max is not None]
    u_max = np.array([problem.sensors[i].u_max for i in bounded])
    excess = (np.linalg.norm(samples[:, :, bounded], axis=-1) - u_max).max(axis=-1)  # (K, S)
    k = int(np.argmax(excess.max(axis=1)))  # the interval of the largest sample: its polynomial refined

    def interval_excess(local: np.ndarray) -> np.ndarray:
        values = np.einsum("sj,jnc->snc", tr.colloc.interpolation_matrix(local), u[k])[:, bounded]
        return (np.linalg.norm(values, axis=-1) - u_max).max(axis=-1)

    largest, at = refine_maximum(interval_excess, s, excess[k])
    h = (problem.horizon.tf - problem.horizon.t0) / K
    return {
        "active": rows_active(rows, lam_nlp),
        "max_violation": largest,
        "max_violation_time": float(problem.horizon.t0 + h * (k + at)),
        "max_violation_at_nodes": float((np.linalg.norm(u[:, :, bounded], axis=-1) - u_max).max()),
        "max_multiplier": float(np.abs(lam).max()),
        "units": units,
    }


def _node_states(tr: Any, result: Any, P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """States at the collocation nodes: Σ entries, p (K·d, N, 2), v (K·d, N, 2)."""
    xc = tr.unpack(result.w, P)["xc"].reshape(-1, tr.structure.nx)
    layout = tr.structure.state
    Sigma, p, v = layout.split(xc)
    return Sigma, p, v
