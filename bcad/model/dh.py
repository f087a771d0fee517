"""Denavit-Hartenberg rows: of a robot given by DH parameters and of a clearance chain."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from bcad.model.base import StrictModel
from bcad.model.pose import Bounds, Value

DH_PARAMETERS = ("a", "alpha", "d", "theta")
#: rows of a DH robot at most
MAX_DH_ROWS = 64


class DhJoint(StrictModel):
    """One row of a DH robot: the joint's four parameters (classic: Eq. 2 of the
    2010 paper, T = Rz(theta) Tz(d) Tx(a) Rx(alpha); modified: T = Rx(alpha)
    Tx(a) Rz(theta) Tz(d)), its type and its limits. The joint variable adds
    to ``theta`` (revolute) or ``d`` (prismatic)."""

    name: str | None = Field(None, description="the joint's name (default joint_1, joint_2, ...)")
    a: Value
    alpha: Value
    d: Value
    theta: Value
    type: Literal["revolute", "prismatic"] = "revolute"
    limits: Bounds | None = Field(None, description="[low, high] of the joint variable, in the problem's units")
