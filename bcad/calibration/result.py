"""The result of ``bcad calibrate``: the calibrated parameters with their uncertainty, what the
data cannot identify, the residuals and the importance check."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field

from bcad.model.results import SCHEMA_VERSION, Message, ResultModel, Units


class CalibratedParameter(ResultModel):
    """One parameter: its estimate and std (the joint MAP and its Laplace std) and its prior."""

    kind: str = Field(description="L (a prior) or X (no prior)")
    estimate: float | None
    std: float | None
    map: float | None = None
    laplace_std: float | None = None
    prior_mean: float | None = None
    prior_std: float | None = None
    identified: bool = Field(description="false where the data leave it at its prior")
    unit: str


class Correlation(ResultModel):
    names: list[str]
    matrix: list[list[float | None]]


class Unobservable(ResultModel):
    """A combination of parameters the data do not inform (a weak direction of the Hessian)."""

    information: float | None
    combination: dict[str, float | None]


class CalibrationResult(ResultModel):
    """The JSON document of ``bcad calibrate`` (kind ``calibrate``)."""

    kind: Literal["calibrate"]
    schema_version: Literal[SCHEMA_VERSION]  # type: ignore[valid-type]
    problem: str
    bcad_version: str
    units: Units
    measurements: dict[str, int] = Field(description="rows per measurement")
    parameters: dict[str, CalibratedParameter]
    correlation: Correlation
    unobservable: list[Unobservable]
    residuals: dict[str, Any]
    warnings: list[Message]
    seconds: float | None = None
    check: dict[str, Any] | None = Field(None, description="the importance-sampled check of the Laplace reading")
    cameras: dict[str, Any] | None = None
    proposal: dict[str, Any] | None = None
    prediction: dict[str, Any] | None = None
    urdf: dict[str, str] | None = None
    camera_info: dict[str, str] | None = None
