"""Sensor measurement-noise models r(p): the variance of one measurement row vs. the sensor position.

A model is a pydantic class (its YAML keys) that also supplies the symbolic variance, registered by name in
:data:`mobisense.ocp.registries.NOISE_MODELS`. To add one in your own code::

    @register_noise_model
    class Exponential(NoiseModel):
        model: Literal["exponential"] = "exponential"
        sigma0: PositiveFloat
        length: PositiveFloat
        n_parameters: ClassVar[int] = 2  # the length of parameters()

        def parameters(self) -> list[float]:
            return [self.sigma0, self.length]

        @staticmethod
        def variance(p, s, theta):
            return theta[0] * casadi.exp(casadi.sumsqr(p - s) / theta[1] ** 2)

(with ``from typing import ClassVar, Literal``, ``import casadi``, ``from mobisense.ocp import NoiseModel,
register_noise_model`` and ``from mobisense.core.config import PositiveFloat``). ``n_parameters`` sizes the
model's slot in the NLP's parameter vector: a model whose ``parameters()`` returns another number of values is
refused when a problem naming it is read. ``variance`` receives CasADi expressions: ``p`` (2,) sensor
position, ``s`` (2,) the location the row measures, ``theta`` the model's numeric parameters (NLP parameters,
so sweeps over them need no rebuild). It must be positive for every position. An installed package can make
its model available to every problem file without being imported first, through the entry-point group
``mobisense.noise_models``::

    [project.entry-points."mobisense.noise_models"]
    exponential = "my_package.noise:Exponential"
"""

from __future__ import annotations

from typing import Any, ClassVar, Literal

from ..core.config import InvalidValue, PositiveFloat, StrictModel
from .registries import NOISE_MODELS

__all__ = ["NoiseModel", "QuadraticRange", "ConstantNoise", "register_noise_model", "parse_noise"]


class NoiseModel(StrictModel):
    """Base class of measurement-noise models (see module docstring for the contract)."""

    model: str
    #: number of entries returned by :meth:`parameters`
    n_parameters: ClassVar[int] = 0

    def parameters(self) -> list[float]:
        """Numeric parameters ``theta`` passed to :meth:`variance`."""
        raise NotImplementedError

    @staticmethod
    def variance(p: Any, s: Any, theta: Any) -> Any:
        """Measurement variance r (symbolic) at sensor position ``p`` for a row located at ``s``."""
        raise NotImplementedError


def register_noise_model(cls: type[NoiseModel]) -> type[NoiseModel]:
    """Class decorator: make ``cls`` available as ``noise: {model: <name>, …}`` in problem files."""
    name = cls.model_fields["model"].default
    if not isinstance(name, str) or not name:
        raise TypeError(f"{cls.__name__}.model needs a string default naming the model")
    return NOISE_MODELS.register(name, cls)


@register_noise_model
class QuadraticRange(NoiseModel):
    """Noise growing with squared range (docs/theory/ocp.md, eq. ocp.4): ``r = beta * |p - s|^2 + gamma``."""

    model: Literal["quadratic_range"] = "quadratic_range"
    beta: PositiveFloat
    gamma: PositiveFloat
    n_parameters: ClassVar[int] = 2

    def parameters(self) -> list[float]:
        """Return ``[beta, gamma]``."""
        return [self.beta, self.gamma]

    @staticmethod
    def variance(p: Any, s: Any, theta: Any) -> Any:
        """``beta * |p - s|^2 + gamma`` (docs/theory/ocp.md, eq. ocp.4)."""
        import casadi as ca  # here: validating a file must not import CasADi

        return theta[0] * ca.sumsqr(p - s) + theta[1]


@register_noise_model
class ConstantNoise(NoiseModel):
    """Position-independent noise ``r = variance`` (a classical fixed-quality sensor)."""

    model: Literal["constant"] = "constant"
    variance_value: PositiveFloat
    n_parameters: ClassVar[int] = 1

    def parameters(self) -> list[float]:
        """Return ``[variance_value]``."""
        return [self.variance_value]

    @staticmethod
    def variance(p: Any, s: Any, theta: Any) -> Any:
        """The constant ``theta[0]``."""
        return theta[0] + 0 * p[0]


def parse_noise(value: Any) -> NoiseModel:
    """Validate a ``noise:`` mapping against the registered model it names."""
    if isinstance(value, NoiseModel):
        return value
    if not isinstance(value, dict) or "model" not in value:
        raise ValueError(f"expected a mapping with a 'model' key, one of {NOISE_MODELS.names()}")
    name = value["model"]
    if not isinstance(name, str) or name not in NOISE_MODELS:
        raise InvalidValue("model", NOISE_MODELS.unknown(name))
    model = NOISE_MODELS[name]
    if not (isinstance(model, type) and issubclass(model, NoiseModel)):
        raise ValueError(f"noise model {name!r} is registered as {model!r}, which is not a NoiseModel subclass")
    parsed = model.model_validate(value)
    try:
        count = len(parsed.parameters())
    except NotImplementedError:
        raise ValueError(f"noise model {name!r} ({model.__name__}) does not define parameters()") from None
    if count != model.n_parameters:  # the NLP's parameter vector is sized by n_parameters
        raise ValueError(
            f"noise model {name!r} ({model.__name__}): parameters() returns {count} values but n_parameters is "
            f"{model.n_parameters} (declare n_parameters: ClassVar[int] = {count})"
        )
    return parsed
