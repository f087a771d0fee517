"""The result of ``bcad maxerror``: the largest end-effector errors that joint clearances can
cause, each with a certified upper bound, and what was asked beside them."""

from __future__ import annotations

from typing import Any, Literal

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
    statistics: dict[str, Any] | None = Field(None, description="uniform clearances: percentiles, yield, joint shares")
    allocation: dict[str, Any] | None = Field(None, description="the largest clearance scale that meets the spec")
    warnings: list[Message]
