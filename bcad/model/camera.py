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

import math
from typing import Annotated, Literal, Union

from pydantic import Field, model_validator

from bcad.kinematics.camera import DISTORTION
from bcad.model.base import StrictModel
from bcad.model.distributions import Distribution

#: a pixel quantity: a number, or a distribution (an L parameter CAMERA.NAME)
PixelValue = Union[Annotated[float, Field(ge=-1e6, le=1e6)], Distribution]
#: a focal length: a positive number of pixels, or a distribution whose mean is one
FocalLength = Union[Annotated[float, Field(gt=0.0, le=1e6)], Distribution]


class Intrinsics(StrictModel):
    """The pinhole's intrinsics; with a camera_info file, those given replace the file's."""

    fx: FocalLength | None = Field(None, description="focal length along u (pixels)")
    fy: FocalLength | None = Field(None, description="focal length along v (pixels)")
    cx: PixelValue | None = Field(None, description="principal point's u (pixels)")
    cy: PixelValue | None = Field(None, description="principal point's v (pixels)")

    @model_validator(mode="after")
    def _positive_focal_lengths(self):
        for name in ("fx", "fy"):
            value = getattr(self, name)
            if value is None or isinstance(value, (int, float)):
                continue
            if not value.moments()[0][0] > 0:
                raise ValueError(f"{name}: a focal length's distribution has a positive mean (pixels)")
            low = getattr(value, "support", (math.inf, math.inf))[0]
            if math.isfinite(low) and not low > 0:
                # a bounded prior reaching zero or below gives focal lengths no camera has a
                # probability of their own (an unbounded one's tail is the Gaussian's business)
                raise ValueError(
                    f"{name}: the focal length's distribution reaches {low:g} px; expected one above 0 pixels"
                )
        return self


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
    name: str = Field(
        pattern=r"^[A-Za-z_][A-Za-z0-9_\-]{0,63}$", description="the camera's name (parameters CAMERA.fx ...)"
    )
    frame: str = Field(description="its optical frame (x right, y down, z forward), a frame of the problem")
    camera_info: str | None = Field(
        None,
        max_length=4096,
        description="a ROS camera_info YAML file (relative to the "
        "problem) whose numbers fix what intrinsics, distortion and image_size do not give",
    )
    image_size: Annotated[list[Annotated[int, Field(ge=1, le=100_000)]], Field(min_length=2, max_length=2)] | None = (
        Field(None, description="[width, height] in pixels")
    )
    intrinsics: Intrinsics | None = None
    distortion_model: Literal["plumb_bob", "rational_polynomial"] | None = Field(
        None,
        description="plumb_bob (k1 k2 p1 p2 k3) or rational_polynomial (k1 ... k6); default: the camera_info "
        "file's, else plumb_bob",
    )
    distortion: Distortion = Field(default_factory=Distortion)

    @model_validator(mode="after")
    def _coefficients_of_the_model(self):
        if self.camera_info is None:
            missing = [
                k for k in ("fx", "fy", "cx", "cy") if self.intrinsics is None or getattr(self.intrinsics, k) is None
            ]
            if missing or self.image_size is None:
                raise ValueError(
                    f"a camera needs intrinsics ({', '.join(missing) or 'given'}) and image_size, or a "
                    "camera_info file that gives them"
                )
            self.check_coefficients(None)
        return self  # with a camera_info file, the model may come from it: checked when it is read

    def check_coefficients(self, info) -> None:
        """A ValueError where the distortion gives a coefficient its model has not."""
        model = self.model(info)
        extra = sorted(set(self.distortion.model_fields_set) - set(DISTORTION[model]))
        if extra:
            raise ValueError(f"{', '.join(extra)}: not coefficients of {model} ({', '.join(DISTORTION[model])})")

    def model(self, info=None) -> str:
        """The distortion model: this camera's, else its camera_info file's (``info``), else plumb_bob."""
        return self.distortion_model or (info.model if info is not None else "plumb_bob")

    def values(self, info=None) -> dict[str, object]:
        """Each parameter of the camera's vector (:func:`bcad.kinematics.camera.camera_parameters`):
        a number or a distribution; what the problem does not give, from its camera_info file
        (``info``: :class:`bcad.model.camera_info.CameraInfo`)."""
        given = (
            {}
            if self.intrinsics is None
            else {
                k: getattr(self.intrinsics, k)
                for k in ("fx", "fy", "cx", "cy")
                if getattr(self.intrinsics, k) is not None
            }
        )
        given.update({k: getattr(self.distortion, k) for k in self.distortion.model_fields_set})
        coefficients = DISTORTION[self.model(info)]
        values = {}
        for name in ("fx", "fy", "cx", "cy", *coefficients):
            # a coefficient the file's model has not (rational_polynomial over a plumb_bob file): 0
            values[name] = given[name] if name in given else (info.values.get(name, 0.0) if info is not None else 0.0)
        return values

    def size(self, info=None) -> list[int]:
        return list(self.image_size) if self.image_size is not None else [info.width, info.height]
