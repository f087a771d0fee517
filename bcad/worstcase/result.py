"""The result of ``bcad maxerror``: the largest end-effector errors that joint clearances can
cause, each with a certified upper bound, and what was asked beside them."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from bcad.model.results import SCHEMA_VERSION, Message, ResultModel, Units


class ExactMaximum(ResultModel):
    """The exact (non-linearised) model's maximum found and its certified bound."""

    max: float | None
    bound: float | None
    gap: float | None


class ErrorMaximum(ResultModel):
    """One of the two problems (rotation, translation): max |dp| over the clearances."""

    max: float | None = Field(description="the error at a feasible clearance (a true lower bound)")
    upper_bound: float | None = Field(description="certified: no clearance within the bounds gives more")
    argmax: list[list[float | None]] = Field(
        description="the clearance screws reaching max, one per joint [dr_x, dr_y, dr_z, dt_x, dt_y, dt_z]"
    )
    seconds: float | None
    gap: float | None = Field(description="(upper_bound - max) / upper_bound")
    converged: bool
    exact: ExactMaximum | None = None


class ErrorSummary(ResultModel):
    """A pose error's distribution over uniform clearances (exact model, Monte Carlo)."""

    mean: float
    mean_se: float
    p50: float
    p95: float
    p99_7: float = Field(alias="p99.7", description="the 99.7th percentile")
    max_sampled: float


class JointShare(ResultModel):
    """One joint's first-order share of the mean squared errors."""

    rotation: float
    translation: float


class YieldEstimate(ResultModel):
    """The share of uniform clearances whose errors meet the spec."""

    value: float
    se: float
    interval_95: list[float] = Field(description="Wilson's 95 % interval")
    effective_samples: int
    spec: dict[str, float] = Field(description="the limits, as given, in the problem's units")
    certain: bool = Field(False, description="the exact model's certified bounds are within the spec: yield 1")


class ErrorStatistics(ResultModel):
    """``--samples``: the errors' distribution over uniform clearances."""

    samples: int
    rotation: ErrorSummary
    translation: ErrorSummary
    joints: list[JointShare]
    yield_: YieldEstimate | None = Field(None, alias="yield")


class Allocation(ResultModel):
    """``--allocate``: the largest clearance scale that meets the spec, bracketed."""

    spec: dict[str, float]
    weights: list[float] | None
    lambda_low: float = Field(description="proven safe: the exact model's certified bound is within the spec")
    lambda_high: float | None = Field(description="shown unsafe (null: no unsafe clearance found)")
    relative_width: float | None


class MaxErrorResult(ResultModel):
    """The JSON document of ``bcad maxerror`` (kind ``maxerror``)."""

    kind: Literal["maxerror"]
    schema_version: Literal[SCHEMA_VERSION]  # type: ignore[valid-type]
    problem: str
    bcad_version: str
    model: str = Field(description="first-order or exact")
    units: Units
    rotation: ErrorMaximum
    translation: ErrorMaximum
    statistics: ErrorStatistics | None = Field(None, description="uniform clearances: percentiles, yield, joint shares")
    allocation: Allocation | None = Field(None, description="the largest clearance scale that meets the spec")
    warnings: list[Message]
