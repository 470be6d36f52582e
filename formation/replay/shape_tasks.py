"""Shape tasks of the replay: desired Jacobi vectors over time and the controller that holds them.

Theory: docs/theory/formation_control.md §4.

* :class:`OrientedShape` — body-frame offsets (the cross with its current ``a, b``, or any rigid shape) turned to the
  formation angle φ: fixed, or the direction of the centre velocity (the "platforms 1-2 along the level curve" of
  Zhang & Leonard (2010), §V-A: at θ = 0 the velocity is the level-curve tangent). The desired vectors
  ``q^d = g(φ) p^d`` move with φ; the feed-forward uses ``φ' = (r_c' × r_c'')/‖r_c'‖²``, giving ``q^d' = φ' J q^d`` and
  ``q^d'' ≈ −φ'² q^d`` (the ``φ''`` term is neglected: small for a centre on a smooth curve). With φ fixed this is the
  paper's constant-shape law.
* :class:`RotatingShape` — :class:`~mobisense.formation.shape_control.RotatingShapeController` with its frame
  angle ψ and rate Ω as two extra ODE states.

:func:`cross_shape` resolves the cross's ``(a, b)``: given, designed for the filter's steady state
(:func:`~mobisense.estimation.cooperative.formation_design.design_cross_formation`), read from a ``mobisense
steady-state`` ``summary.json``, or adapted online (step 3A,
:func:`~mobisense.estimation.cooperative.formation_design.adaptive_shape_step`).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ...core.config import ConfigError
from ...estimation.cooperative.information_model import cross_formation, rotation
from ...estimation.cooperative.noise_config import NoiseConfig
from ..jacobi import JacobiTransform
from ..shape_control import FixedShapeController, RotatingShapeController, perp
from .scenario import CrossFormation, RigidFormation, RotatingFormation, ShapeConfig

__all__ = ["OrientedShape", "RotatingShape", "cross_shape", "build_shape_task"]


class OrientedShape:
    """Fixed body-frame shape at angle φ (fixed or along the centre velocity), PD on the Jacobi vectors.

    Parameters
    ----------
    jacobi : JacobiTransform
    offsets : ndarray, shape (N, 2)
        Body-frame offsets (L); their mean is removed.
    controller : FixedShapeController
    angle : float or None
        Fixed formation angle (rad), or ``None`` to align body e1 with the centre velocity.
    """

    n_states = 0

    def __init__(
        self,
        jacobi: JacobiTransform,
        offsets: np.ndarray,
        controller: FixedShapeController,
        angle: float | None,
    ) -> None:
        self.jacobi, self.controller, self.fixed_angle = jacobi, controller, angle
        self.set_offsets(offsets)

    def set_offsets(self, offsets: np.ndarray) -> None:
        """Change the desired body-frame shape (adaptive cross)."""
        offsets = np.asarray(offsets, dtype=float)
        self.offsets = offsets - offsets.mean(axis=0)
        self.p_desired = self.jacobi.to_jacobi(self.offsets)[1]

    def angle(self, center_velocity: np.ndarray) -> float:
        """Formation angle φ (rad)."""
        if self.fixed_angle is not None:
            return self.fixed_angle
        return float(np.arctan2(center_velocity[1], center_velocity[0]))

    def desired(
        self, center_velocity: np.ndarray, center_acceleration: np.ndarray, extra: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``q^d, q^d', q^d''``, each ``(N−1, 2)``."""
        q_d = (rotation(self.angle(center_velocity)) @ self.p_desired[..., None])[..., 0]
        if self.fixed_angle is not None:
            return q_d, np.zeros_like(q_d), np.zeros_like(q_d)
        vx, vy = center_velocity
        rate = (vx * center_acceleration[1] - vy * center_acceleration[0]) / (vx**2 + vy**2)  # φ'
        return q_d, rate * perp(q_d), -(rate**2) * q_d

    def forces(
        self,
        t: float,
        q: np.ndarray,
        dq: np.ndarray,
        center_velocity: np.ndarray,
        center_acceleration: np.ndarray,
        extra: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Shape forces ``u`` (N−1, 2) and the (empty) rates of the extra states."""
        return self.controller(q, dq, *self.desired(center_velocity, center_acceleration, extra)), np.empty(0)

    def initial_extra(self, angle: float) -> np.ndarray:
        """No extra states."""
        return np.empty(0)

    def initial_velocities(self, offsets_lab: np.ndarray) -> np.ndarray:
        """Velocities of the platforms relative to the centre at the start (at rest in the body frame)."""
        return np.zeros_like(offsets_lab)


class RotatingShape:
    """A rotating formation (eqs. 42-43); extra ODE states ``(ψ, Ω)``.

    Parameters
    ----------
    jacobi : JacobiTransform
    offsets : ndarray, shape (N, 2)
        Body-frame offsets (L).
    controller_gains : dict
        ``shape_stiffness, shape_damping, angular_gain``.
    angular_speed : float
        ``Ω^d`` (rad/T).
    """

    n_states = 2

    def __init__(
        self, jacobi: JacobiTransform, offsets: np.ndarray, controller_gains: dict, angular_speed: float
    ):
        offsets = np.asarray(offsets, dtype=float)
        self.jacobi, self.offsets = jacobi, offsets - offsets.mean(axis=0)
        self.angular_speed = float(angular_speed)
        self.controller = RotatingShapeController(
            jacobi.to_jacobi(self.offsets)[1], self.angular_speed, **controller_gains
        )

    def angle(self, center_velocity: np.ndarray) -> float:
        """Not used for the start angle of a rotating formation (given by the scenario or the velocity)."""
        return float(np.arctan2(center_velocity[1], center_velocity[0]))

    def desired(
        self, center_velocity: np.ndarray, center_acceleration: np.ndarray, extra: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``q^d = g(ψ) p^d`` and its rates at ``Ω`` (for the shape error)."""
        psi, omega = extra
        q_d = (rotation(psi) @ self.controller.p_desired[..., None])[..., 0]
        return q_d, omega * perp(q_d), -(omega**2) * q_d

    def forces(
        self,
        t: float,
        q: np.ndarray,
        dq: np.ndarray,
        center_velocity: np.ndarray,
        center_acceleration: np.ndarray,
        extra: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Shape forces and ``(ψ', Ω')``."""
        u, dpsi, domega = self.controller(t, q, dq, extra[0], extra[1])
        return u, np.array([dpsi, domega])

    def initial_extra(self, angle: float) -> np.ndarray:
        """``(ψ0, Ω0) = (angle, Ω^d)``: start on the desired rotation."""
        return np.array([angle, self.angular_speed])

    def initial_velocities(self, offsets_lab: np.ndarray) -> np.ndarray:
        """Rigid rotation ``Ω^d J (r_i − r_c)``."""
        return self.angular_speed * perp(offsets_lab)


def _summary_shape(path: Path) -> tuple[float, float]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found (write it with mobisense steady-state)") from None
    except (OSError, json.JSONDecodeError) as err:
        raise ConfigError(f"{path}: cannot read the steady-state summary ({err})") from None
    try:
        a, b = float(data["a"]), float(data["b"])
    except (KeyError, TypeError, ValueError):
        raise ConfigError(
            f"{path}: expected the keys 'a' and 'b' of a cross design (mobisense steady-state)"
        ) from None
    if not (a > 0 and b > 0 and np.isfinite(a) and np.isfinite(b)):
        raise ConfigError(f"{path}: a, b: expected positive numbers, got {a}, {b}")
    return a, b


def cross_shape(
    shape: ShapeConfig, noise: NoiseConfig, scenario_path: Path
) -> tuple[float, float, dict[str, Any]]:
    """Initial ``(a, b)`` of the cross and a description of where they came from.

    For ``adaptive`` the start is the steady-state design within the same bounds (then step 3A takes
    over at the first sample).
    """
    from ...estimation.cooperative.formation_design import design_cross_formation

    if shape.a is not None and shape.b is not None:
        return shape.a, shape.b, {"source": "given"}
    if shape.summary is not None:
        a, b = _summary_shape(scenario_path.parent / shape.summary)
        return a, b, {"source": f"steady-state summary {shape.summary}"}
    design_spec = shape.steady_state if shape.steady_state is not None else shape.adaptive
    design = design_cross_formation(
        noise.sigma_process, noise.sigma_measurement, noise.sigma_hessian, design_spec.bounds.pairs(),
        design_spec.equal_sides,
    )  # fmt: skip
    info = {"source": "adaptive (step 3A)" if shape.adaptive is not None else "steady-state design",
            "stationary_point": design.stationary_point, "message": design.message}  # fmt: skip
    return float(design.x[0]), float(design.x[1]), info


def build_shape_task(
    formation: Any, jacobi: JacobiTransform, noise: NoiseConfig, scenario_path: Path
) -> tuple[OrientedShape | RotatingShape, dict[str, Any]]:
    """The shape task of a scenario's ``formation`` and a description (initial a, b and their source)."""
    if isinstance(formation, RotatingFormation):
        gains = formation.gains.model_dump()
        return RotatingShape(jacobi, np.asarray(formation.offsets), gains, formation.angular_speed), {}
    controller = FixedShapeController(formation.gains.stiffness, formation.gains.damping)
    angle = formation.angle if formation.orientation == "fixed" else None
    if isinstance(formation, RigidFormation):
        return OrientedShape(jacobi, np.asarray(formation.offsets), controller, angle), {}
    if not isinstance(formation, CrossFormation):
        raise TypeError(f"formation: unsupported kind {type(formation).__name__}")
    a, b, info = cross_shape(formation.shape, noise, scenario_path)
    return OrientedShape(jacobi, cross_formation(a, b), controller, angle), {"a0": a, "b0": b, **info}
