"""The problem's units: of every length and angle in it, and of its results."""

from __future__ import annotations

import math
from typing import Literal

from bcad.model.base import StrictModel

#: radians per angle unit (the compiler's conversions and the schema's checks in a unit alike)
RADIANS_PER_UNIT = {"rad": 1.0, "deg": math.pi / 180.0}


class Units(StrictModel):
    """Units of every length and angle in the problem (and of its results)."""

    length: Literal["m", "mm", "cm"] = "m"
    angle: Literal["rad", "deg"] = "rad"
