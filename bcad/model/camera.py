"""The ``cameras:`` section: pinhole cameras with OpenCV's distortion, as sensors of the graph.

A camera names its optical frame (``frame``: x right, y down, z forward, out of the lens; ROS's
``*_optical_frame``), a frame of the problem whose link from the robot's flange (eye-in-hand) or
from the world (eye-to-hand) is the camera's mount: an ordinary link whose pose has an X/L/F
status like any other. Its intrinsics (``fx``, ``fy``, ``cx``, ``cy``, pixels) and distortion
coefficients (``distortion_model``: ROS camera_info's ``plumb_bob``, k1 k2 p1 p2 k3, or
``rational_polynomial``, k1 ... k6, in OpenCV's order) are each a number (fixed) or a
distribution (L: identified by ``bcad calibrate``, the distribution its prior). A measurement
whose ``reference`` is the camera reads pixels ``u,v`` of a target's points
(:mod:`bcad.model.measurement`); the projection is :mod:`bcad.kinematics.camera`'s.
"""

from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import Field, model_validator

from bcad.kinematics.camera import DISTORTION
from bcad.model.base import StrictModel
from bcad.model.distributions import Distribution

#: a pixel quantity: a number, or a distribution (an L parameter CAMERA.NAME)
PixelValue = Union[Annotated[float, Field(ge=-1e6, le=1e6)], Distribution]


class Intrinsics(StrictModel):
    fx: PixelValue = Field(description="focal length along u (pixels)")
    fy: PixelValue = Field(description="focal length along v (pixels)")
    cx: PixelValue = Field(description="principal point's u (pixels)")
    cy: PixelValue = Field(description="principal point's v (pixels)")


class Distortion(StrictModel):
    k1: PixelValue = 0.0
    k2: PixelValue = 0.0
    p1: PixelValue = 0.0
    p2: PixelValue = 0.0
    k3: PixelValue = 0.0
    k4: PixelValue = 0.0
    k5: PixelValue = 0.0
    k6: PixelValue = 0.0


class Camera(StrictModel):
    name: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_\-]{0,63}$", description="the camera's name (parameters CAMERA.fx ...)")
    frame: str = Field(description="its optical frame (x right, y down, z forward), a frame of the problem")
    image_size: Annotated[list[Annotated[int, Field(ge=1, le=100_000)]], Field(min_length=2, max_length=2)] = Field(
        description="[width, height] in pixels")
    intrinsics: Intrinsics
    distortion_model: Literal["plumb_bob", "rational_polynomial"] = "plumb_bob"
    distortion: Distortion = Field(default_factory=Distortion)

    @model_validator(mode="after")
    def _coefficients_of_the_model(self):
        allowed = DISTORTION[self.distortion_model]
        given = {name for name in self.distortion.model_fields_set}
        extra = sorted(given - set(allowed))
        if extra:
            raise ValueError(f"{', '.join(extra)}: not coefficients of {self.distortion_model} ({', '.join(allowed)})")
        return self

    def values(self) -> dict[str, object]:
        """Each parameter of the camera's vector (:func:`bcad.kinematics.camera.camera_parameters`):
        a number or a distribution."""
        coefficients = DISTORTION[self.distortion_model]
        return {**{k: getattr(self.intrinsics, k) for k in ("fx", "fy", "cx", "cy")},
                **{k: getattr(self.distortion, k) for k in coefficients}}
