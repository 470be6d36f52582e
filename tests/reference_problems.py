"""Shared test problems with known answers (dicts in the YAML schema; build with Problem.from_dict)."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
PROBLEMS = ROOT / "problems"


def hussein2008(**solver: Any) -> dict[str, Any]:
    """The paper's worked example (Hussein (2008), §V; docs/theory/ocp.md §4)."""
    data = {
        "name": "hussein2008",
        "horizon": {"t0": 0.0, "tf": 10.0},
        "process": {"A": [[-0.5]], "B": [[1.0]], "Q": [[1.0]], "Sigma0": [[200.0]], "locations": [[0.0, 0.0]]},
        "sensors": [
            {
                "name": "s1",
                "p0": [10.0, 10.0],
                "v0": [0.0, -2.0],
                "noise": {"model": "quadratic_range", "beta": 5.0, "gamma": 3.0},
            }
        ],
        "cost": {"M": [[20.0]], "K": [[0.0]], "alpha": 0.004},
        "solver": {
            "method": "direct",
            "collocation": {"scheme": "radau", "degree": 3, "intervals": 100},
            "homotopy": {"mode": "fixed", "step": 0.05},
        },
    }
    return with_solver(data, **solver)


def with_solver(data: dict[str, Any], **solver: Any) -> dict[str, Any]:
    """Copy of ``data`` with solver sub-options updated (nested dicts merged)."""
    data = copy.deepcopy(data)
    for key, value in solver.items():
        if isinstance(value, dict):
            data["solver"].setdefault(key, {}).update(value)
        else:
            data["solver"][key] = value
    return data


def scalar_steady_state(a: float, Q: float, r: float) -> float:
    """Positive root of 2 a Σ + Q − Σ²/r = 0: Σ∞ = a r + sqrt(a² r² + Q r) (docs/theory/ocp.md, eq. ocp.14)."""
    return a * r + np.sqrt(a * a * r * r + Q * r)


def sensor_at_rest(alpha: float = 1e6, tf: float = 40.0, p0: tuple[float, float] = (3.0, 4.0)) -> dict[str, Any]:
    """One sensor with zero velocity, very expensive control, range 5 from the process."""
    data = hussein2008()
    data["name"] = "sensor_at_rest"
    data["horizon"]["tf"] = tf
    data["sensors"][0].update(p0=list(p0), v0=[0.0, 0.0])
    data["cost"]["alpha"] = alpha
    return data


def two_scalar_processes() -> tuple[dict[str, Any], dict[str, Any], dict[str, Any]]:
    """A decoupled n = 2 problem where sensor i measures state i only, and its two n = 1 halves."""
    joint = {
        "name": "decoupled2",
        "horizon": {"t0": 0.0, "tf": 6.0},
        "process": {
            "A": [[-0.5, 0.0], [0.0, 0.2]],
            "B": [[1.0, 0.0], [0.0, 1.0]],
            "Q": [[1.0, 0.0], [0.0, 0.5]],
            "Sigma0": [[50.0, 0.0], [0.0, 20.0]],
            "locations": [[0.0, 0.0], [6.0, -2.0]],
        },
        "sensors": [
            {
                "name": "a",
                "p0": [5.0, 5.0],
                "v0": [0.0, -1.0],
                "measures": [[1.0, 0.0]],
                "noise": {"model": "quadratic_range", "beta": 2.0, "gamma": 1.0},
            },
            {
                "name": "b",
                "p0": [2.0, -6.0],
                "v0": [1.0, 0.0],
                "measures": [[0.0, 1.0]],
                "noise": {"model": "quadratic_range", "beta": 1.0, "gamma": 2.0},
            },
        ],
        "cost": {"M": [[10.0, 0.0], [0.0, 5.0]], "K": [[1.0, 0.0], [0.0, 0.5]], "alpha": 0.05},
        "solver": {"collocation": {"intervals": 60}, "homotopy": {"mode": "fixed", "step": 0.1}},
    }
    halves = []
    for i in range(2):
        half = copy.deepcopy(joint)
        half["name"] = f"half{i}"

        def pick(m: list[list[float]], i: int = i) -> list[list[float]]:
            return [[m[i][i]]]

        half["process"] = {
            "A": pick(joint["process"]["A"]),
            "B": [[1.0]],
            "Q": pick(joint["process"]["Q"]),
            "Sigma0": pick(joint["process"]["Sigma0"]),
            "locations": [joint["process"]["locations"][i]],
        }
        sensor = copy.deepcopy(joint["sensors"][i])
        sensor["measures"] = [[1.0]]
        half["sensors"] = [sensor]
        half["cost"] = {"M": pick(joint["cost"]["M"]), "K": pick(joint["cost"]["K"]), "alpha": joint["cost"]["alpha"]}
        halves.append(half)
    return joint, halves[0], halves[1]


def coupled_two_sensor(terminal_velocity: bool = True) -> dict[str, Any]:
    """A coupled, correlated 2-state process observed by two sensors; sensor 1 must stop at tf."""
    data = {
        "name": "coupled2",
        "horizon": {"t0": 0.0, "tf": 5.0},
        "process": {
            "A": [[-0.3, 0.4], [-0.2, -0.1]],
            "B": [[1.0, 0.0], [0.3, 1.0]],
            "Q": [[1.0, 0.2], [0.2, 0.5]],
            "Sigma0": [[30.0, 5.0], [5.0, 20.0]],
            "locations": [[0.0, 0.0], [4.0, 3.0]],
        },
        "sensors": [
            {
                "name": "s1",
                "p0": [6.0, -4.0],
                "v0": [0.0, 1.0],
                "noise": {"model": "quadratic_range", "beta": 1.0, "gamma": 2.0},
            },
            {
                "name": "s2",
                "p0": [-3.0, 5.0],
                "v0": [1.0, 0.0],
                "measures": [[1.0, 1.0]],
                "noise": {"model": "quadratic_range", "beta": 0.5, "gamma": 1.0},
            },
        ],
        "cost": {"M": [[10.0, 2.0], [2.0, 8.0]], "K": [[1.0, 0.0], [0.0, 1.0]], "alpha": 0.1},
        "solver": {"collocation": {"intervals": 50}, "homotopy": {"mode": "fixed", "step": 0.1}},
    }
    if terminal_velocity:
        data["sensors"][0]["terminal"] = {"v": [0.0, 0.0]}
    return data
