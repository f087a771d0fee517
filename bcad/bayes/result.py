"""The result of ``bcad solve`` and ``bcad posterior``: the solution X*, the estimate of
log p(X*) I(X*) (Eq. 2) and the posterior of the closing links (Table 2)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field

from bcad.model.results import SCHEMA_VERSION, Message, ResultModel, Units


class ProblemStats(ResultModel):
    """The problem's Table 1 statistics."""

    frames: int
    links: int
    cycles: int
    optimization_dim: int = Field(description="the number of X parameters")
    integration_dim: int = Field(description="the number of L parameters")
    inequality_constraints: int
    seconds: float | None = Field(None, description="the run's wall time, s")


class ObjectiveEstimate(ResultModel):
    """log p(X) I(X) at the solution, with its Monte Carlo standard error."""

    estimator: str = Field(description="importance, linear or mc")
    log_value: float | None = Field(description="log p(X*) I(X*); null where no sample closes the cell")
    log_value_se: float | None
    samples: int | None = Field(description="the samples behind the estimate (null for the linearised one)")
    effective_samples: float | None = None
    pareto_k: float | None = Field(None, description="Pareto k-hat of the importance weights (above 0.7: unreliable)")


class WeightedMoments(ResultModel):
    """The posterior's moments: the samples weighted by the closing link's scores."""

    mean: list[float | None] | None
    std: list[float | None] | None


class LinkPosterior(ResultModel):
    """One closing link's pose in its parent frame: the paper's Table 2 row."""

    parent: str
    child: str
    params: list[str] = Field(description="the pose coordinates, in order (tx, ty, tz, rx, ry, rz)")
    mean: list[float | None] | None
    std: list[float | None] | None
    mean_se: list[float | None] | None
    std_se: list[float | None] | None
    constrained: list[str] = Field(description="the coordinates the link's distributions score")
    weighted: WeightedMoments | None = None
    effective_samples: float | None = None
    satisfied: float | None = Field(None, description="the share of samples meeting the link's inequalities")
    satisfied_se: float | None = Field(
        None, description="its Monte Carlo standard error, sqrt(p (1 - p) / N) over the N prior samples"
    )


class Posterior(ResultModel):
    samples: int
    links: dict[str, LinkPosterior]


class CalibrationApplied(ResultModel):
    """A calibration result that replaced priors of the plan (``calibration:``)."""

    file: str
    applied: list[str]
    not_applied: list[str]


class ConfigurationColumn(ResultModel):
    """One configuration of the cell at X*: its joints and the links that belong to it."""

    joints: dict[str, float | None] = Field(description="each joint's value, in the problem's units")
    links: list[str]
    closing_links: list[str] = Field(description="its closing links: Table 2's rows of those names")


class Contribution(ResultModel):
    """Shares of one scored parameter's linearised variance."""

    std: float | None
    by_robot: dict[str, float]
    by_link: dict[str, float]
    by_parameter: dict[str, float]


class DesignResult(ResultModel):
    """The JSON document of ``bcad solve`` (kind ``solve``) and ``bcad posterior`` (``posterior``)."""

    kind: Literal["solve", "posterior"]
    schema_version: Literal[SCHEMA_VERSION]  # type: ignore[valid-type]
    problem: str
    bcad_version: str
    seed: int
    backend: str = Field(description="bayes or nominal")
    units: Units
    stats: ProblemStats
    solution: dict[str, float | None] = Field(description="X*: each X parameter's value, in the problem's units")
    objective: ObjectiveEstimate
    posterior: Posterior
    contributors: dict[str, dict[str, Contribution]] | None = Field(
        None, description="per closing link and scored parameter, the shares of its variance"
    )
    warnings: list[Message]
    findings: list[Message] = []
    diagnostics: dict[str, Any] = {}
    configurations: dict[str, ConfigurationColumn] | None = None
    calibration: list[CalibrationApplied] | None = None
