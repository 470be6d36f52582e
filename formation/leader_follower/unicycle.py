"""Unicycle kinematics and the leader–follower relative state (docs/theory/leader_follower.md §1–§2).

Source: Karasalo & Hu (2010), eqs. 1–4, 8, 10.

Poses are arrays ``(..., 3)`` holding ``(x, y, φ)``: position (m) and heading (rad, counter-clockwise from
the x axis). Follower ``i`` tracks its predecessor ``i − 1``; the relative state is

* ``d``  distance between the two agents (m),
* ``β``  bearing of the predecessor seen from the follower, measured from the follower's heading
  (rad, counter-clockwise positive, wrapped to (−π, π]), so that ``r_{i−1} = r_i + d (cos(φ_i + β), sin(φ_i + β))``,
* ``γ = φ_i − φ_{i−1}`` heading difference (rad, wrapped).

The reference point of the follower (eq. 8) lies at distance ``d0`` and bearing ``β0`` from it; the
reference-point error ``(x_e, y_e)`` (eq. 10) is its offset from the predecessor, in the world frame.
"""

from __future__ import annotations

import numpy as np

__all__ = ["wrap_angle", "unicycle_rates", "relative_state", "relative_rates", "reference_point_error"]


def wrap_angle(angle: np.ndarray | float) -> np.ndarray:
    """Wrap angles (rad) to the interval (−π, π]."""
    wrapped = np.remainder(np.asarray(angle, dtype=float) + np.pi, 2.0 * np.pi) - np.pi
    return np.where(wrapped == -np.pi, np.pi, wrapped)


def unicycle_rates(pose: np.ndarray, speed: np.ndarray | float, turn_rate: np.ndarray | float) -> np.ndarray:
    """Time derivative of unicycle poses.

    Parameters
    ----------
    pose : ndarray, shape (..., 3)
        ``(x, y, φ)`` in m, m, rad.
    speed, turn_rate : ndarray or float, broadcastable to shape (...)
        Forward speed ``v`` (m/s) and turn rate ``ω`` (rad/s).

    Returns
    -------
    ndarray, shape (..., 3)
        ``(ẋ, ẏ, φ̇)``.
    """
    pose = np.asarray(pose, dtype=float)
    phi = pose[..., 2]
    # docs/theory/leader_follower.md, eq. leader_follower.1: x' = v cos φ, y' = v sin φ, φ' = ω
    return np.stack(np.broadcast_arrays(speed * np.cos(phi), speed * np.sin(phi), turn_rate + 0.0 * phi), axis=-1)


def relative_state(follower: np.ndarray, predecessor: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distance, bearing and heading difference of a follower with respect to its predecessor.

    Parameters
    ----------
    follower, predecessor : ndarray, shape (..., 3)
        Poses ``(x, y, φ)`` of agent ``i`` and agent ``i − 1``.

    Returns
    -------
    d : ndarray, shape (...)
        Distance (m).
    beta : ndarray, shape (...)
        Bearing of the predecessor from the follower's heading (rad, in (−π, π]).
    gamma : ndarray, shape (...)
        ``φ_i − φ_{i−1}`` (rad, in (−π, π]).
    """
    follower = np.asarray(follower, dtype=float)
    predecessor = np.asarray(predecessor, dtype=float)
    dx = predecessor[..., 0] - follower[..., 0]
    dy = predecessor[..., 1] - follower[..., 1]
    d = np.hypot(dx, dy)
    beta = wrap_angle(np.arctan2(dy, dx) - follower[..., 2])
    gamma = wrap_angle(follower[..., 2] - predecessor[..., 2])
    return d, beta, gamma


def relative_rates(
    d: np.ndarray | float,
    beta: np.ndarray | float,
    gamma: np.ndarray | float,
    speed: np.ndarray | float,
    turn_rate: np.ndarray | float,
    predecessor_speed: np.ndarray | float,
    predecessor_turn_rate: np.ndarray | float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rates of change of ``(d, β, γ)`` (docs/theory/leader_follower.md, eq. leader_follower.2).

    Source: Karasalo & Hu (2010), eqs. 2–4.

    Parameters
    ----------
    d, beta, gamma : ndarray or float
        Relative state (m, rad, rad).
    speed, turn_rate : ndarray or float
        Follower inputs ``v_i`` (m/s), ``ω_i`` (rad/s).
    predecessor_speed, predecessor_turn_rate : ndarray or float
        Predecessor inputs ``v_{i−1}``, ``ω_{i−1}``.

    Returns
    -------
    d_dot, beta_dot, gamma_dot : ndarray
        m/s, rad/s, rad/s.
    """
    v, w, v_p, w_p = speed, turn_rate, predecessor_speed, predecessor_turn_rate
    # eq. leader_follower.2 (the paper's eq. 2): d' = −v_i cos β + v_{i−1} cos(γ + β)
    d_dot = -v * np.cos(beta) + v_p * np.cos(gamma + beta)
    # eq. leader_follower.2 (the paper's eq. 3): β' = −ω_i + (v_i/d) sin β − (v_{i−1}/d) sin(γ + β)
    beta_dot = -w + (v / d) * np.sin(beta) - (v_p / d) * np.sin(gamma + beta)
    # eq. leader_follower.2 (the paper's eq. 4): γ' = ω_i − ω_{i−1}
    gamma_dot = w - w_p + 0.0 * d_dot
    return np.asarray(d_dot), np.asarray(beta_dot), np.asarray(gamma_dot)


def reference_point_error(
    follower: np.ndarray,
    predecessor: np.ndarray,
    distance: np.ndarray | float,
    bearing: np.ndarray | float,
) -> tuple[np.ndarray, np.ndarray]:
    """Reference-point error ``(x_e, y_e)`` of a follower (docs/theory/leader_follower.md, eq. leader_follower.3).

    Source: Karasalo & Hu (2010), eqs. 8 and 10.

    Parameters
    ----------
    follower, predecessor : ndarray, shape (..., 3)
        Poses of agents ``i`` and ``i − 1``.
    distance, bearing : ndarray or float, broadcastable to shape (...)
        Formation parameters ``d0`` (m) and ``β0`` (rad).

    Returns
    -------
    xe, ye : ndarray, shape (...)
        World-frame offset (m) of the reference point from the predecessor.
    """
    follower = np.asarray(follower, dtype=float)
    predecessor = np.asarray(predecessor, dtype=float)
    heading = follower[..., 2] + bearing
    # docs/theory/leader_follower.md, eq. leader_follower.3:
    # x_e = x_i + d0 cos(φ_i + β0) − x_{i−1}, y_e likewise with sin
    xe = follower[..., 0] + distance * np.cos(heading) - predecessor[..., 0]
    ye = follower[..., 1] + distance * np.sin(heading) - predecessor[..., 1]
    return xe, ye
