"""The ``measurements:`` section: what a sensor saw, for calibration.

Each measurement names a measured frame, the frame it is measured in
(``reference``: a tracker, a camera, the robot's base), either of them
possibly an entity (its entity frame: a probe's tip as a point, a part's
face whose z is its normal, so that a touch is ``tz`` = 0), the measured pose
parameters (``parameters: tx,ty,tz``, a subset of the six, in that order),
the sensor's noise on each (a distribution, the same for every row), and its
data: ``rows`` inline, or ``data:`` a CSV file (relative to the problem) whose
header names the joint columns (``ROBOT/JOINT``) and the measured parameters.
Each row is one configuration: the value of every robot joint that is X in
the problem, in the problem's units, and the measured values.

A camera's measurement (``reference``: a camera of ``cameras:``, ``frame``: a
target entity, ``parameters: u,v``) has a row per detected point: the view's
joint values, the target point's id (``point``, a CSV column of that name) and
its pixel (u, v); the noise is in pixels.
"""

from __future__ import annotations

from pydantic import Field, ValidationInfo, field_validator

from bcad.errors import quoted
from bcad.model.base import StrictModel
from bcad.model.distributions import Distribution
from bcad.model.pose import PARAMETERS, Value, parameter_group

#: rows of one measurement at most (inline or CSV)
MAX_ROWS = 100_000


class MeasurementRow(StrictModel):
    joints: dict[str, Value] = Field(description="joint values by ROBOT/JOINT, in the problem's units")
    values: list[Value] = Field(min_length=1, max_length=6, description="the measured parameters, in order")
    point: int | None = Field(None, ge=0, le=99_999, description="a camera's row: the id of the target's point it saw")


class Measurement(StrictModel):
    name: str
    frame: str = Field(description="the measured frame, or an entity (its entity frame)")
    reference: str = Field(description="the frame it is measured in, or an entity")
    parameters: str = Field(
        description="the measured pose parameters, e.g. tx,ty,tz; u,v: pixels, where the "
        "reference is a camera and the frame a target"
    )
    noise: Distribution = Field(description="the sensor's noise on each measured parameter")
    data: str | None = Field(None, description="a CSV file of rows, relative to the problem file")
    rows: list[MeasurementRow] = Field(
        default_factory=list, max_length=MAX_ROWS, description="the rows inline (or data:, not both)"
    )
    joint_noise: Distribution | None = Field(
        None,
        description="the noise of the robot's joint readings (encoders), in the "
        "joints' units: each configuration of this measurement gets its own joint "
        "errors, identified as L with this prior",
    )
    allow_outside_limits: bool = Field(
        False,
        description="accept rows whose joint values lie beyond the joints' limits "
        "(a robot whose limits are set tighter than its travel); refused otherwise",
    )

    @field_validator("rows")
    @classmethod
    def _rows_or_data(cls, value: list, info: ValidationInfo) -> list:
        if value and info.data.get("data") is not None:
            raise ValueError(
                f"both inline rows and data: {quoted(info.data['data'], 60)}; expected one of them: the rows inline, "
                "or data: a CSV file of them"
            )
        return value

    @field_validator("parameters")
    @classmethod
    def _parameters(cls, value: str) -> str:
        names = [part.strip() for part in value.split(",")]
        if names == ["u", "v"]:
            return "u,v"  # pixels, read by a camera (its reference)
        if {"u", "v"} & set(names):
            raise ValueError(f"'{value}': a camera's pixels are read as u,v, both and in that order")
        for name in names:
            parameter_group(name)  # raises for anything but tx ... rz
        if len(set(names)) != len(names) or [n for n in PARAMETERS if n in names] != names:
            raise ValueError(f"'{value}': each of tx, ty, tz, rx, ry, rz at most once, in that order")
        return ",".join(names)

    @property
    def measured(self) -> list[str]:
        return self.parameters.split(",")
