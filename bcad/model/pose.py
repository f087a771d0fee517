"""Pose 6-vectors and status vectors, the vocabulary every link shares.

A pose is ``(tx, ty, tz, rx, ry, rz)``: a translation, then a rotation
R = Rz(rz) Ry(ry) Rx(rx) (URDF's rpy convention). A status vector is a
6-letter string of X (unknown), L (free, known by a distribution) and F
(fixed), one letter per pose parameter in that order (Sect. 3.1 of the 2000
paper).
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from pydantic import AfterValidator, Field

from bcad.kinematics.camera import DISTORTION, INTRINSICS

PARAMETERS: tuple[str, ...] = ("tx", "ty", "tz", "rx", "ry", "rz")
LENGTH_PARAMETERS = frozenset(PARAMETERS[:3])
#: parameter names (the part after the last '.') whose unit is a length: the pose's translations
#: and an entity's uncertain dimensions (``ENTITY.radius``, ``ENTITY.at[0]``: :mod:`bcad.compiler.dimensions`)
LENGTH_NAMES = (
    LENGTH_PARAMETERS
    | {"radius", "length", "size[0]", "size[1]"}
    | {f"{key}[{k}]" for key in ("at", "center") for k in range(3)}
)
#: a camera's parameters (:mod:`bcad.kinematics.camera`: intrinsics in px, distortion coefficients)
CAMERA_NAMES = frozenset(INTRINSICS) | frozenset(DISTORTION["rational_polynomial"])
#: the names a parameter may end in: a pose's six, an entity's uncertain dimensions, a camera's
PARAMETER_NAMES = frozenset(PARAMETERS) | LENGTH_NAMES | CAMERA_NAMES


def parameter_unit(parameter: str, units) -> str:
    """The unit of a parameter named ``parameter`` (tx ... rz, or an entity's dimension: the part
    after the last '.') in ``units`` (a problem's or a result's: its ``length`` and ``angle``)."""
    return units.length if parameter in LENGTH_NAMES else units.angle


def is_parameter_name(name: object) -> bool:
    """Whether ``name`` is a parameter's name, LINK.PARAMETER (``ur5/base.tx``, ``hole.radius``): how
    a file that names parameters (a result, a calibration) shows itself to be of that kind."""
    return (
        isinstance(name, str) and 3 <= len(name) <= 1000 and name.rsplit(".", 1)[-1] in PARAMETER_NAMES and "." in name
    )


def first_unnamed(names) -> int | None:
    """The position (from 1) of the first of ``names`` that is not a parameter's name
    (:func:`is_parameter_name`), or None where every one is: the entry a message names."""
    return next((k for k, name in enumerate(names, 1) if not is_parameter_name(name)), None)


#: which of the six pose parameters are angles (wrapped to [-pi, pi))
ANGULAR = np.array([name not in LENGTH_PARAMETERS for name in PARAMETERS])
STATUS_LETTERS = frozenset("XLF")


def _check_status(value: str) -> str:
    if not isinstance(value, str):
        raise ValueError("a status vector is a 6-letter string such as FFLLLF")
    if len(value) != 6:
        raise ValueError(f"status '{value}' has {len(value)} letters; expected 6, one per parameter tx ty tz rx ry rz")
    wrong = sorted(set(value) - STATUS_LETTERS)
    if wrong:
        raise ValueError(
            f"status '{value}' has the letter(s) {', '.join(repr(w) for w in wrong)}; "
            "expected only X (unknown), L (free, with a distribution) or F (fixed)"
        )
    return value


Status = Annotated[str, AfterValidator(_check_status)]
#: the largest magnitude of a length or angle in a problem file (schemas also refuse inf and NaN)
LIMIT = 1e9
Value = Annotated[float, Field(ge=-LIMIT, le=LIMIT)]
Pose = Annotated[list[Value], Field(min_length=6, max_length=6, description="(tx, ty, tz, rx, ry, rz)")]


def _ordered(value: tuple[float, float]) -> tuple[float, float]:
    if not value[0] < value[1]:
        raise ValueError(f"need low < high, got [{value[0]:g}, {value[1]:g}]")
    return value


#: [low, high] of a value (bounds of an X, a joint's limits), low < high
Bounds = Annotated[tuple[Value, Value], AfterValidator(_ordered)]


def parameter_group(key: str) -> tuple[str, ...]:
    """The parameters a distribution key names: ``"rz"`` or a pair ``"tx,ty"``.

    Raises ``ValueError`` for anything else.
    """
    names = tuple(part.strip() for part in str(key).split(","))
    for name in names:
        if name not in PARAMETERS:
            raise ValueError(f"'{name}' is not a pose parameter; expected one of {', '.join(PARAMETERS)}")
    if len(set(names)) != len(names) or len(names) > 2:
        raise ValueError(f"'{key}' must name one parameter, or two different ones such as 'tx,ty'")
    return names
