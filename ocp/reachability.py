"""Fixed terminal states that no admissible control reaches, refused when the file is read.

With |u| ≤ u_max a sensor ends within u_max·T²/2 of where it coasts to and within u_max·T of its initial velocity;
under a speed limit within v_max·T of where it starts (T = tf − t0). These are necessary conditions only, so a
reachable target is never refused, and an unreachable one is named with its key instead of Ipopt's
"infeasible problem" blaming a continuity row.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..core.config import InvalidValue

__all__ = ["check_reachable"]


def check_reachable(i: int, sensor: Any, span: float, max_speed: float | None) -> None:
    """Refuse a fixed terminal state that no admissible control reaches in ``span`` (T): ``InvalidValue``.

    Necessary conditions only, so nothing reachable is refused: with |u| ≤ u_max the sensor ends within
    u_max·span²/2 of where it coasts to (p0 + v0·span) and within u_max·span of v0 in velocity; under
    ``max_speed`` within max_speed·span of p0. Ipopt reported such a problem as infeasible after 17 s and blamed
    a continuity row (first-hour audit).
    """
    terminal = sensor.terminal
    if terminal is None:
        return
    p0, v0 = np.asarray(sensor.p0, float), np.asarray(sensor.v0, float)
    slack = 1.0 + 1e-9  # rounding of the data
    if terminal.p is not None:
        offset = float(np.linalg.norm(np.asarray(terminal.p, float) - p0 - span * v0))
        if sensor.u_max is not None and offset > 0.5 * sensor.u_max * span**2 * slack:
            raise InvalidValue(f"sensors[{i}].terminal.p", f"expected a position reachable with |u| ≤ u_max = "
                               f"{sensor.u_max:g}: it is {offset:g} L from where the sensor coasts to (p0 + v0 (tf − "
                               f"t0)), more than u_max (tf − t0)²/2 = {0.5 * sensor.u_max * span**2:g}")  # fmt: skip
        distance = float(np.linalg.norm(np.asarray(terminal.p, float) - p0))
        if max_speed is not None and distance > max_speed * span * slack:
            raise InvalidValue(f"sensors[{i}].terminal.p", f"expected a position reachable under "
                               f"constraints.max_speed = {max_speed:g}: it is {distance:g} L from p0, more than "
                               f"max_speed (tf − t0) = {max_speed * span:g}")  # fmt: skip
    if terminal.v is not None and sensor.u_max is not None:
        change = float(np.linalg.norm(np.asarray(terminal.v, float) - v0))
        if change > sensor.u_max * span * slack:
            raise InvalidValue(f"sensors[{i}].terminal.v", f"expected a velocity reachable with |u| ≤ u_max = "
                               f"{sensor.u_max:g}: it differs from v0 by {change:g} L/T, more than u_max (tf − t0) = "
                               f"{sensor.u_max * span:g}")  # fmt: skip
