"""Probability distributions of the problem language.

Each distribution is a pydantic model (the schema) with vectorised ``sample``
and ``logpdf`` methods. A distribution of an L parameter describes the
parameter's *deviation* from its nominal value; see the README.

Two spellings are accepted in a problem file:

* shorthand: ``normal(0, 0.01)``, ``uniform(-1, 1)``,
  ``truncnormal(0, 0.1, -0.2, 0.2)``, ``disc(0.05)`` (keyword arguments such as
  ``normal(mean=0, std=0.01)`` work too);
* mapping: ``{type: normal, mean: 0, std: 0.01}``.
"""

from __future__ import annotations

import math
import re
from typing import Annotated, Any, ClassVar, Literal, Union

import numpy as np
from pydantic import BeforeValidator, Field, model_validator

from bcad.model.base import StrictModel
from bcad.tempering import relaxed_log_indicator

LOG_TWO_PI = math.log(2.0 * math.pi)
#: every length or angle of a distribution is at most this in magnitude, every scale at least TINY:
#: beyond them the arithmetic of densities and samples loses its meaning
HUGE = 1e12
TINY = 1e-12
Finite = Annotated[float, Field(ge=-HUGE, le=HUGE)]
Scale = Annotated[float, Field(ge=TINY, le=HUGE)]


class _Distribution(StrictModel):
    """A distribution's fields: an unknown key refused with the closest valid one (``stdd``: did you
    mean ``std``?), ``std: true`` refused at its place, not read as 1 (:class:`StrictModel`)."""

    #: number of pose parameters the distribution covers (2 for ``disc``)
    dimension: ClassVar[int] = 1

    def scaled(self, factor: float) -> _Distribution:
        """The same distribution with every length multiplied by ``factor`` (unit change). Built
        without checking again: a distribution the schema accepted stays valid in any unit (a
        std of 1e-12 deg, the smallest a file may give, is 1.7e-14 rad, below the schema's floor)."""
        raise NotImplementedError

    def shorthand(self) -> str:
        """The shorthand spelling, e.g. ``normal(0, 0.01)``."""
        values = ", ".join(f"{getattr(self, name):g}" for name in self._positional())
        return f"{self.type}({values})"

    @classmethod
    def _positional(cls) -> tuple[str, ...]:
        return tuple(name for name in cls.model_fields if name != "type")


class Normal(_Distribution):
    """Gaussian N(mean, std^2)."""

    type: Literal["normal"] = "normal"
    mean: Finite = 0.0
    std: Scale = Field(description="standard deviation, in [1e-12, 1e12]")

    @property
    def support(self) -> tuple[float, float]:
        return (-math.inf, math.inf)

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return rng.normal(self.mean, self.std, size=n)

    def logpdf(self, x: np.ndarray) -> np.ndarray:
        return self.tempered_logpdf(x, 0.0)

    def tempered_logpdf(self, x: np.ndarray, temperature: float) -> np.ndarray:
        """Sect. 4.2.1: the standard deviation widened to sigma (1 + T)."""
        std = self.std * (1.0 + temperature)
        z = (np.asarray(x) - self.mean) / std
        return -0.5 * z * z - math.log(std) - 0.5 * LOG_TWO_PI

    def from_uniform(self, u: np.ndarray) -> np.ndarray:
        from scipy.special import ndtri

        return self.mean + self.std * ndtri(u[..., 0])

    def moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Mean and variance of each covered parameter (the linearised estimator's inputs)."""
        return np.array([self.mean]), np.array([self.std**2])

    def scaled(self, factor: float) -> Normal:
        return Normal.model_construct(mean=self.mean * factor, std=self.std * abs(factor))


class Uniform(_Distribution):
    """Uniform on [low, high]."""

    type: Literal["uniform"] = "uniform"
    low: Finite
    high: Finite

    @model_validator(mode="after")
    def _ordered(self) -> Uniform:
        if not self.high - self.low >= TINY:
            raise ValueError(f"uniform needs low < high, got low={self.low:g}, high={self.high:g}")
        return self

    @property
    def mean(self) -> float:
        return 0.5 * (self.low + self.high)

    @property
    def support(self) -> tuple[float, float]:
        return (self.low, self.high)

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return rng.uniform(self.low, self.high, size=n)

    def logpdf(self, x: np.ndarray) -> np.ndarray:
        return self.tempered_logpdf(x, 0.0)

    def tempered_logpdf(self, x: np.ndarray, temperature: float) -> np.ndarray:
        """Sect. 4.2.1: the interval's indicator relaxed outside [low, high]."""
        x = np.asarray(x)
        width = self.high - self.low
        distance = np.maximum(self.low - x, x - self.high)
        return relaxed_log_indicator(distance, width, temperature) - math.log(width)

    def from_uniform(self, u: np.ndarray) -> np.ndarray:
        return self.low + (self.high - self.low) * u[..., 0]

    def moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Mean and variance: (low + high) / 2 and width^2 / 12."""
        return np.array([self.mean]), np.array([(self.high - self.low) ** 2 / 12.0])

    def scaled(self, factor: float) -> Uniform:
        low, high = sorted((self.low * factor, self.high * factor))
        return Uniform.model_construct(low=low, high=high)


class TruncatedNormal(_Distribution):
    """Gaussian N(mean, std^2) restricted to [low, high] and renormalised."""

    type: Literal["truncnormal"] = "truncnormal"
    mean: Finite = 0.0
    std: Scale = Field(description="standard deviation, in [1e-12, 1e12]")
    low: Finite
    high: Finite

    @model_validator(mode="after")
    def _ordered(self) -> TruncatedNormal:
        if not self.high - self.low >= TINY:
            raise ValueError(f"truncnormal needs low < high, got low={self.low:g}, high={self.high:g}")
        lo, hi = self._cdf_range()
        if not hi - lo > 1e-12:
            raise ValueError(
                f"truncnormal's interval [{self.low:g}, {self.high:g}] has probability {hi - lo:.3g} under "
                f"normal({self.mean:g}, {self.std:g}); it must be above 1e-12 (is the interval where you meant it?)"
            )
        return self

    @property
    def support(self) -> tuple[float, float]:
        return (self.low, self.high)

    def _cdf_range(self) -> tuple[float, float]:
        from scipy.special import ndtr  # imported here: scipy.special costs 0.2 s at start-up

        return (
            float(ndtr((self.low - self.mean) / self.std)),
            float(ndtr((self.high - self.mean) / self.std)),
        )

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        # Inverse-CDF sampling: exact, and one uniform draw per sample.
        return self.from_uniform(rng.uniform(0.0, 1.0, size=(n, 1)))

    def from_uniform(self, u: np.ndarray) -> np.ndarray:
        from scipy.special import ndtri

        lo, hi = self._cdf_range()
        return np.clip(self.mean + self.std * ndtri(lo + (hi - lo) * u[..., 0]), self.low, self.high)

    def moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Mean and variance of the truncated Gaussian (the standard closed form)."""
        from scipy.special import ndtr

        a, b = (self.low - self.mean) / self.std, (self.high - self.mean) / self.std
        mass = float(ndtr(b) - ndtr(a))
        phi_a, phi_b = math.exp(-0.5 * a * a), math.exp(-0.5 * b * b)
        phi_a, phi_b = phi_a / math.sqrt(2 * math.pi), phi_b / math.sqrt(2 * math.pi)
        shift = (phi_a - phi_b) / mass
        spread = (
            1.0
            + ((a * phi_a if math.isfinite(a) else 0.0) - (b * phi_b if math.isfinite(b) else 0.0)) / mass
            - shift * shift
        )
        return np.array([self.mean + self.std * shift]), np.array([self.std**2 * max(spread, 0.0)])

    def logpdf(self, x: np.ndarray) -> np.ndarray:
        return self.tempered_logpdf(x, 0.0)

    def tempered_logpdf(self, x: np.ndarray, temperature: float) -> np.ndarray:
        """Sect. 4.2.1: sigma widened to sigma (1 + T) and the truncation relaxed."""
        x = np.asarray(x)
        lo, hi = self._cdf_range()
        std = self.std * (1.0 + temperature)
        z = (np.clip(x, self.low, self.high) - self.mean) / std
        log_density = -0.5 * z * z - math.log(std) - 0.5 * LOG_TWO_PI - math.log(hi - lo)
        distance = np.maximum(self.low - x, x - self.high)
        return log_density + relaxed_log_indicator(distance, self.high - self.low, temperature)

    def scaled(self, factor: float) -> TruncatedNormal:
        low, high = sorted((self.low * factor, self.high * factor))
        return TruncatedNormal.model_construct(mean=self.mean * factor, std=self.std * abs(factor), low=low, high=high)


class UniformDisc(_Distribution):
    """Uniform over the disc of radius ``radius`` centred at 0, over two parameters.

    This is the joint-clearance model of Eq. 6-9 of the 2010 paper (radial
    clearance of a revolute joint), written on a key naming two parameters,
    e.g. ``tx,ty: disc(0.05)``.
    """

    type: Literal["disc"] = "disc"
    radius: Scale = Field(description="disc radius, in [1e-12, 1e12]")
    dimension: ClassVar[int] = 2

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        # Area-uniform: the radius goes as sqrt(u).
        r = self.radius * np.sqrt(rng.uniform(0.0, 1.0, size=n))
        phi = rng.uniform(0.0, 2.0 * math.pi, size=n)
        return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=-1)

    def moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Mean 0 and variance r^2 / 4 of each coordinate (uncorrelated)."""
        return np.zeros(2), np.full(2, self.radius**2 / 4.0)

    def from_uniform(self, u: np.ndarray) -> np.ndarray:
        r = self.radius * np.sqrt(u[..., 0])
        phi = 2.0 * math.pi * u[..., 1]
        return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=-1)

    def logpdf(self, x: np.ndarray) -> np.ndarray:
        return self.tempered_logpdf(x, 0.0)

    def tempered_logpdf(self, x: np.ndarray, temperature: float) -> np.ndarray:
        """Sect. 4.2.1: the disc's indicator relaxed outside, in units of its diameter."""
        x = np.asarray(x)
        distance = np.sqrt(np.einsum("...i,...i->...", x, x)) - self.radius
        return relaxed_log_indicator(distance, 2.0 * self.radius, temperature) - math.log(math.pi * self.radius**2)

    def scaled(self, factor: float) -> UniformDisc:
        return UniformDisc.model_construct(radius=self.radius * abs(factor))


_KINDS: dict[str, type[_Distribution]] = {
    "normal": Normal,
    "uniform": Uniform,
    "truncnormal": TruncatedNormal,
    "disc": UniformDisc,
}
_SHORTHAND = re.compile(r"^\s*([A-Za-z_]\w*)\s*\((.*)\)\s*$")


def parse_shorthand(value: Any) -> Any:
    """Turn ``"normal(0, 0.01)"`` into ``{"type": "normal", "mean": 0, "std": 0.01}``.

    Anything that is not a string is passed through for pydantic to validate.
    """
    if not isinstance(value, str):
        return value
    match = _SHORTHAND.match(value)
    if not match and value.count("(") > value.count(")"):
        raise ValueError(
            f"cannot read distribution '{value}': its parenthesis is not closed; "
            "inside a flow mapping {...}, quote a distribution that has commas, e.g. 'normal(0, 0.01)'"
        )
    if not match:
        raise ValueError(
            f"cannot read distribution '{value}'; expected e.g. normal(0, 0.01), "
            "uniform(-1, 1), truncnormal(0, 0.1, -0.2, 0.2) or disc(0.05)"
        )
    kind, body = match.group(1), match.group(2)
    cls = _KINDS.get(kind)
    if cls is None:
        raise ValueError(f"unknown distribution '{kind}'; expected one of {', '.join(_KINDS)}")
    names = cls._positional()
    result: dict[str, Any] = {"type": kind}
    arguments = [part.strip() for part in body.split(",")] if body.strip() else []
    for position, argument in enumerate(arguments):
        name, _, text = argument.rpartition("=")
        name = name.strip()
        if not name:
            if position >= len(names):
                raise ValueError(f"{kind} takes {len(names)} arguments ({', '.join(names)}), got {len(arguments)}")
            name = names[position]
        elif name not in names:
            raise ValueError(f"{kind} has no argument '{name}'; expected {', '.join(names)}")
        try:
            result[name] = float(text)
        except ValueError:
            raise ValueError(f"argument '{argument}' of {kind} is not a number") from None
    return result


_VARIANTS = Union[tuple(_KINDS.values())]
#: the shorthand spelling, as JSON Schema sees it (the validator reads its arguments)
Shorthand = Annotated[
    str,
    Field(
        pattern=rf"^\s*({'|'.join(_KINDS)})\s*\(.*\)\s*$",
        description="e.g. normal(0, 0.01), uniform(-1, 1), truncnormal(0, 0.1, -0.2, 0.2), disc(0.05)",
    ),
]

Distribution = Annotated[
    Annotated[_VARIANTS, Field(discriminator="type")],
    BeforeValidator(parse_shorthand, json_schema_input_type=Union[Shorthand, _VARIANTS]),
]


class MultivariateNormal:
    """N(mean, covariance) over several parameters, correlations kept: a calibration result's
    joint posterior (:mod:`bcad.compiler.calibration`). Not a shorthand of the language: it
    comes from a result file, in internal units, never from a problem's text."""

    type = "mvnormal"

    def __init__(self, mean: np.ndarray, covariance: np.ndarray):
        self.mean = np.asarray(mean, dtype=float)
        self.covariance = 0.5 * (np.asarray(covariance, dtype=float) + np.asarray(covariance, dtype=float).T)
        self.dimension = len(self.mean)
        # Cholesky on the correlation matrix, with a ridge relative to each parameter's own scale.
        std = np.sqrt(np.diagonal(self.covariance))
        correlation = self.covariance / np.outer(std, std)
        self.root = np.linalg.cholesky(correlation + 1e-12 * np.eye(self.dimension)) * std[:, None]

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.diagonal(self.covariance))

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return self.mean + rng.standard_normal((n, self.dimension)) @ self.root.T

    def from_uniform(self, u: np.ndarray) -> np.ndarray:
        from scipy.special import ndtri

        return self.mean + ndtri(u) @ self.root.T

    def logpdf(self, x: np.ndarray) -> np.ndarray:
        z = np.linalg.solve(self.root, (np.atleast_2d(x) - self.mean).T)
        return -0.5 * np.sum(z * z, axis=0) - np.sum(np.log(np.diagonal(self.root))) - 0.5 * self.dimension * LOG_TWO_PI

    def moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Mean and variance of each covered parameter (the covariance is :attr:`covariance`)."""
        return self.mean.copy(), np.diagonal(self.covariance).copy()

    def shorthand(self) -> str:
        return f"mvnormal({self.dimension} parameters, from a calibration)"
