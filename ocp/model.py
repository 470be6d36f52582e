"""Symbolic model of the mobile-sensor Kalman problem (docs/theory/ocp.md §1): one implementation of each equation.

State vector ``x = [σ, p_1, …, p_N, v_1, …, v_N]`` and controls ``u = [u_1, …, u_N]`` as laid out by
:class:`~mobisense.ocp.state_layout.StateLayout`.
Every number of the problem (ε, weights, matrices, initial and terminal data, noise parameters,
scales) is a symbolic NLP parameter laid out by :class:`ParameterLayout`, so one CasADi graph serves
every problem of the same :class:`Structure`; only the structure triggers a rebuild.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from .path_constraints import path_parameter_blocks, path_parameter_values, path_rows, path_structure
from .problem import Problem
from .registries import NOISE_MODELS
from .state_layout import StateLayout

__all__ = ["Structure", "ParameterLayout", "SensorKalmanModel"]


# ---------------------------------------------------------------------- structure and parameters
@dataclass(frozen=True)
class Structure:
    """What fixes the shape of the CasADi graph (everything else is a parameter)."""

    n: int
    rows: tuple[int, ...]  # measurement rows m_i per sensor
    noise_models: tuple[str, ...]
    fixed_position: tuple[bool, ...]
    fixed_velocity: tuple[bool, ...]
    bounded_control: tuple[bool, ...]
    #: path constraints (:func:`~mobisense.ocp.path_constraints.path_structure`)
    path: tuple[tuple[Any, ...], ...] = ()
    #: per sensor: measures the field at its position (kriging row, docs/theory/field.md §2)
    point: tuple[bool, ...] = ()
    #: the field block (JSON) when any sensor is a point sensor: its kernel is part of the graph
    field: str | None = None

    @classmethod
    def of(cls, problem: Problem) -> Structure:
        """The structure of ``problem``."""
        sensors = problem.sensors
        return cls(
            n=problem.n,
            # a point sensor has one row (its kriging row): counted without building the field's kernel matrix,
            # an O(n³) factorisation (3 s at 50 × 50, paid per task of a sweep over grids before its budget)
            rows=tuple(1 if problem.is_point(i) else problem.measurement_rows(i).shape[0] for i in range(problem.N)),
            noise_models=tuple(s.noise.model for s in sensors),
            fixed_position=tuple(s.terminal is not None and s.terminal.p is not None for s in sensors),
            fixed_velocity=tuple(s.terminal is not None and s.terminal.v is not None for s in sensors),
            bounded_control=tuple(s.u_max is not None for s in sensors),
            path=path_structure(problem.constraints, problem.N),
            point=tuple(problem.is_point(i) for i in range(problem.N)),
            field=problem.process.field.model_dump_json()
            if any(problem.is_point(i) for i in range(problem.N))
            else None,
        )

    @property
    def field_process(self) -> Any:
        """The :class:`~mobisense.ocp.field.FieldProcess` of the point sensors (None without)."""
        from .field import FieldSpec

        return None if self.field is None else FieldSpec.model_validate_json(self.field).process()

    @property
    def N(self) -> int:  # noqa: N802
        """Number of sensors."""
        return len(self.rows)

    @property
    def state(self) -> StateLayout:
        """The layout of the state vector x = [σ, p, v]."""
        return StateLayout(self.n, self.N)

    @property
    def n_sigma(self) -> int:
        """Number of covariance states n(n+1)/2."""
        return self.state.n_sigma

    @property
    def nx(self) -> int:
        """State dimension n(n+1)/2 + 4N."""
        return self.state.nx

    @property
    def nu(self) -> int:
        """Control dimension 2N."""
        return self.state.nu


class ParameterLayout:
    """Ordered named blocks of the NLP parameter vector; packs numbers and unpacks symbols."""

    def __init__(self, structure: Structure) -> None:
        s = structure
        n = s.n
        blocks: list[tuple[str, tuple[int, ...]]] = [
            ("eps", (1,)),
            ("t0", (1,)),
            ("tf", (1,)),
            ("alpha", (1,)),
            ("A", (n, n)),
            ("BQB", (n, n)),
            ("M", (n, n)),
            ("K", (n, n)),
            ("Sigma0", (n, n)),
            ("sigma_scale", (n, n)),
            ("length_scale", (1,)),
            ("velocity_scale", (1,)),
            ("control_scale", (1,)),
            ("cost_scale", (1,)),
        ]
        if s.field is not None:
            blocks += [("Ks_inv", (n, n)), ("field_loc", (n, 2))]
        for i in range(s.N):
            model = NOISE_MODELS[s.noise_models[i]]
            blocks += [
                (f"p0_{i}", (2,)),
                (f"v0_{i}", (2,)),
                (f"C_{i}", (s.rows[i], n)),
                (f"rowloc_{i}", (s.rows[i], 2)),
                (f"theta_{i}", (model.n_parameters,)),
            ]
            if s.fixed_position[i]:
                blocks.append((f"pT_{i}", (2,)))
            if s.fixed_velocity[i]:
                blocks.append((f"vT_{i}", (2,)))
            if s.bounded_control[i]:
                blocks.append((f"umax_{i}", (1,)))
        blocks += path_parameter_blocks(s.path)
        self.blocks = blocks
        self.offsets: dict[str, tuple[int, tuple[int, ...]]] = {}
        self._slices: list[tuple[str, int, int]] = []  # (name, start, stop) of each block
        offset = 0
        for name, shape in blocks:
            self.offsets[name] = (offset, shape)
            size = int(np.prod(shape))
            self._slices.append((name, offset, offset + size))
            offset += size
        self.size = offset

    def pack(self, values: dict[str, Any]) -> np.ndarray:
        """Numeric parameter vector from a dict with one entry per block (row-major matrices)."""
        out = np.empty(self.size)
        for name, start, stop in self._slices:
            arr = np.asarray(values[name], dtype=float).reshape(-1)
            if arr.size != stop - start:
                raise ValueError(f"parameter block {name}: expected {stop - start} values, got {arr.size}")
            out[start:stop] = arr
        return out

    def unpack(self, P: Any) -> dict[str, Any]:
        """Symbolic (or numeric) blocks of a parameter vector; matrices reshaped row-major."""
        numeric = isinstance(P, np.ndarray)
        out: dict[str, Any] = {}
        for name, start, stop in self._slices:
            block = P[start:stop]
            shape = self.offsets[name][1]
            if len(shape) == 2:
                block = block.reshape(shape) if numeric else ca.reshape(block, shape[1], shape[0]).T
            out[name] = block
        return out

    def values(self, problem: Problem, eps: float = 1.0) -> dict[str, Any]:
        """All blocks' numbers for ``problem`` at homotopy parameter ``eps`` (scales chosen here)."""
        mats = problem.matrices()
        d = np.sqrt(np.diag(mats["Sigma0"]))
        scales = problem.reference_scales()
        values: dict[str, Any] = {
            "eps": eps,
            "t0": problem.horizon.t0,
            "tf": problem.horizon.tf,
            "alpha": problem.cost.alpha,
            "A": mats["A"],
            "BQB": mats["BQB"],
            "M": mats["M"],
            "K": mats["K"],
            "Sigma0": mats["Sigma0"],
            "sigma_scale": np.outer(d, d),
            "length_scale": scales["length"],
            "velocity_scale": scales["velocity"],
            "control_scale": scales["control"],
            "cost_scale": 1.0,
        }
        if problem.process.field is not None and any(problem.is_point(i) for i in range(problem.N)):
            process = problem.process.field.process()
            values["Ks_inv"], values["field_loc"] = process.Ks_inv, process.locations
        for i, sensor in enumerate(problem.sensors):
            values[f"p0_{i}"] = sensor.p0
            values[f"v0_{i}"] = sensor.v0
            values[f"C_{i}"] = problem.measurement_rows(i)
            values[f"rowloc_{i}"] = problem.row_locations(i)
            values[f"theta_{i}"] = sensor.noise.parameters()
            if sensor.terminal is not None and sensor.terminal.p is not None:
                values[f"pT_{i}"] = sensor.terminal.p
            if sensor.terminal is not None and sensor.terminal.v is not None:
                values[f"vT_{i}"] = sensor.terminal.v
            if sensor.u_max is not None:
                values[f"umax_{i}"] = sensor.u_max
        values.update(path_parameter_values(problem.constraints, problem.N))
        return values


# ---------------------------------------------------------------------- the model
class SensorKalmanModel:
    """CasADi SX functions of the problem for one :class:`Structure`.

    Functions (unscaled variables; ``P`` the parameter vector):
      ``f(x, u, P)`` state derivative; ``running(x, u, P)`` -> [α/2|u|² + Tr KΣ, α/2|u|²];
      ``terminal(x, P)`` -> Tr[M Σ]; ``x0(P)`` initial state; ``scales(P)`` -> (state scale (nx,),
      control scale (nu,)); ``information(p, P)`` -> S(p) = C' R(p)^-1 C flattened (n*n,).
    """

    def __init__(self, structure: Structure) -> None:
        self.structure = s = structure
        self.layout = ParameterLayout(structure)
        x = ca.SX.sym("x", s.nx)
        u = ca.SX.sym("u", s.nu)
        P = ca.SX.sym("P", self.layout.size)
        b = self.layout.unpack(P)
        n, N = s.n, s.N
        Sigma, pos, vel = s.state.symbolic(x)
        S = self._information(pos, b)
        # docs/theory/ocp.md, eq. ocp.7: Σ' = A Σ + Σ A' + B Q B' − Σ C' R(p)^-1 C Σ
        Sigma_dot = b["A"] @ Sigma + Sigma @ b["A"].T + b["BQB"] - Sigma @ S @ Sigma
        xdot = s.state.join_symbolic(Sigma_dot, vel, u)
        energy = 0.5 * b["alpha"] * ca.sumsqr(u)
        self.f = ca.Function("f", [x, u, P], [xdot], ["x", "u", "P"], ["xdot"])
        self.running = ca.Function(
            "running", [x, u, P], [ca.vertcat(energy + ca.trace(b["K"] @ Sigma), energy)], ["x", "u", "P"], ["L"]
        )
        self.terminal = ca.Function("terminal", [x, P], [ca.trace(b["M"] @ Sigma)], ["x", "P"], ["Phi"])
        x0 = s.state.join_symbolic(b["Sigma0"], [b[f"p0_{i}"] for i in range(N)], [b[f"v0_{i}"] for i in range(N)])
        self.x0 = ca.Function("x0", [P], [x0], ["P"], ["x0"])
        x_scale = s.state.join_symbolic(
            b["sigma_scale"], ca.repmat(b["length_scale"], 2 * N, 1), ca.repmat(b["velocity_scale"], 2 * N, 1)
        )
        self.scales = ca.Function(
            "scales", [P], [x_scale, ca.repmat(b["control_scale"], s.nu, 1)], ["P"], ["x_scale", "u_scale"]
        )
        p_sym = ca.SX.sym("p", 2 * N)
        S_p = self._information([p_sym[2 * i : 2 * i + 2] for i in range(N)], b)
        self.information = ca.Function("information", [p_sym, P], [ca.reshape(S_p, n * n, 1)], ["p", "P"], ["S"])
        # path constraints of one instant, g(x, P) ≤ 0 scaled, and the physical size of a unit of each row
        rows, units, self.path_labels = path_rows(
            [pos[i] for i in range(N)], [vel[i] for i in range(N)], b, s.path
        )
        self.n_path_rows = len(rows)
        self.path = ca.Function("path", [x, P], [ca.vertcat(*rows) if rows else ca.SX(0, 1)], ["x", "P"], ["g"])
        self.path_scale = ca.Function("path_scale", [P], [ca.vertcat(*units) if units else ca.SX(0, 1)])

    def _information(self, positions: list[Any], b: dict[str, Any]) -> Any:
        """S(p) = Σ_i C_i' diag(1/r_i(p_i)) C_i  (docs/theory/ocp.md, eq. ocp.3, with R block-diagonal).

        A point sensor contributes c(p_i) c(p_i)' / r_i with the kriging row c(p) = Kₛ⁻¹ k(p)
        (docs/theory/field.md, eq. field.4).
        """
        s = self.structure
        S = ca.SX.zeros(s.n, s.n)
        field = s.field_process
        for i in range(s.N):
            model = NOISE_MODELS[s.noise_models[i]]
            if s.point and s.point[i]:
                c = field.symbolic_weights(positions[i], b["Ks_inv"], b["field_loc"])
                S += c @ c.T / model.variance(positions[i], positions[i], b[f"theta_{i}"])
                continue
            C = b[f"C_{i}"]
            for k in range(s.rows[i]):
                r = model.variance(positions[i], b[f"rowloc_{i}"][k, :].T, b[f"theta_{i}"])
                S += C[k, :].T @ C[k, :] / r
        return S

    def terminal_constraints(self, x: Any, P: Any) -> tuple[Any, list[tuple[str, int]]]:
        """Residuals of the fixed terminal positions/velocities and their labels (what, sensor index)."""
        s = self.structure
        b = self.layout.unpack(P)
        residuals, labels = [], []
        for i in range(s.N):
            p, v = x[s.state.position(i)], x[s.state.velocity(i)]
            if s.fixed_position[i]:
                residuals.append((p - b[f"pT_{i}"]) / b["length_scale"])
                labels += [(f"terminal position {c}", i) for c in "xy"]
            if s.fixed_velocity[i]:
                residuals.append((v - b[f"vT_{i}"]) / b["velocity_scale"])
                labels += [(f"terminal velocity {c}", i) for c in "xy"]
        return (ca.vertcat(*residuals) if residuals else type(x)(0, 1)), labels

    def control_bounds(self, u: Any, P: Any) -> tuple[Any, list[int]]:
        """``(|u_i|² − u_max²)/u_scale² ≤ 0`` for bounded sensors, and which sensors they are."""
        s = self.structure
        b = self.layout.unpack(P)
        out, which = [], []
        for i in range(s.N):
            if s.bounded_control[i]:
                out.append((ca.sumsqr(u[s.state.control(i)]) - b[f"umax_{i}"] ** 2) / b["control_scale"] ** 2)
                which.append(i)
        return (ca.vertcat(*out) if out else type(u)(0, 1)), which
