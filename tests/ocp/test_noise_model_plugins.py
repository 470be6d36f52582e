"""Noise models added in user code (the recipe of mobisense.ocp.noise_models' docstring)."""

from __future__ import annotations

import itertools
from typing import Any, ClassVar, Literal

import pytest
from reference_problems import hussein2008

import mobisense as ms
from mobisense.core.config import ConfigError, PositiveFloat
from mobisense.ocp import NoiseModel, register_noise_model
from mobisense.ocp import noise_models as noise_module


def _with_noise(noise: dict[str, Any], intervals: int = 30) -> ms.Problem:
    data = hussein2008(collocation={"intervals": intervals})
    data["sensors"][0]["noise"] = noise
    return ms.Problem.from_dict(data)


def test_the_docstring_recipe_runs_as_written() -> None:
    """The example in the module docstring, executed as a user would paste it (it lacked n_parameters once)."""
    lines = noise_module.__doc__.split("To add one in your own code::\n\n", 1)[1].splitlines()
    block = [line for line in itertools.takewhile(lambda line: not line or line.startswith("    "), lines)]
    code = "\n".join(line[4:] for line in block)
    assert "class Exponential" in code and "n_parameters" in code
    header = (
        "import casadi\nfrom typing import ClassVar, Literal\nfrom mobisense.ocp import NoiseModel, "
        "register_noise_model\nfrom mobisense.core.config import PositiveFloat\n"
    )
    # as a user's script runs it: without this test module's `from __future__ import annotations`
    exec(compile(header + code, "<docstring example>", "exec", dont_inherit=True), {})  # noqa: S102
    solution = ms.solve(_with_noise({"model": "exponential", "sigma0": 3.0, "length": 20.0}, intervals=100))
    assert solution.success and solution.cost < solution.baseline["cost"]


def test_a_plugin_equal_to_a_built_in_model_gives_its_optimum() -> None:
    @register_noise_model
    class SquaredRange(NoiseModel):  # quadratic_range written again in user code
        model: Literal["test_squared_range"] = "test_squared_range"
        slope: PositiveFloat
        floor: PositiveFloat
        n_parameters: ClassVar[int] = 2

        def parameters(self) -> list[float]:
            return [self.slope, self.floor]

        @staticmethod
        def variance(p: Any, s: Any, theta: Any) -> Any:
            import casadi

            return theta[0] * casadi.sumsqr(p - s) + theta[1]

    built_in = ms.solve(_with_noise({"model": "quadratic_range", "beta": 5.0, "gamma": 3.0}))
    plugin = ms.solve(_with_noise({"model": "test_squared_range", "slope": 5.0, "floor": 3.0}))
    # the same NLP built from the same expressions: the same iterates up to round-off
    assert plugin.cost == pytest.approx(built_in.cost, rel=1e-10)


def test_a_plugin_whose_parameters_do_not_match_n_parameters_is_refused() -> None:
    @register_noise_model
    class Forgetful(NoiseModel):  # n_parameters left at the base class's 0
        model: Literal["test_forgetful"] = "test_forgetful"
        level: PositiveFloat

        def parameters(self) -> list[float]:
            return [self.level]

        @staticmethod
        def variance(p: Any, s: Any, theta: Any) -> Any:
            return theta[0] + 0 * p[0]

    expected = r"sensors\[0\]\.noise.*parameters\(\) returns 1 values but n_parameters is 0"
    with pytest.raises(ConfigError, match=expected):
        _with_noise({"model": "test_forgetful", "level": 2.0})
