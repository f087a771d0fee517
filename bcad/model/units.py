"""The problem's units: of every length and angle in it, and of its results."""

from __future__ import annotations

from typing import Literal

from bcad.model.base import StrictModel


class Units(StrictModel):
    """Units of every length and angle in the problem (and of its results)."""

    length: Literal["m", "mm", "cm"] = "m"
    angle: Literal["rad", "deg"] = "rad"
