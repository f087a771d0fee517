"""Conversion of a problem's values to bcad's internal units.

Internally lengths stay in the problem's length unit (results are reported
in it) and angles are radians. URDF lengths (metres) are converted to the
problem's length unit.
"""

from __future__ import annotations

import numpy as np

from bcad.model.pose import LENGTH_NAMES, PARAMETERS
from bcad.model.units import RADIANS_PER_UNIT, Units

METRES_PER_UNIT = {"m": 1.0, "cm": 0.01, "mm": 0.001}


def urdf_length_scale(units: Units) -> float:
    """Factor from URDF metres to the problem's length unit."""
    return 1.0 / METRES_PER_UNIT[units.length]


def angle_scale(units: Units) -> float:
    """Factor from the problem's angle unit to radians."""
    return RADIANS_PER_UNIT[units.angle]


def parameter_scale(parameter: str, units: Units) -> float:
    """Factor from a pose parameter's problem unit to its internal unit."""
    return 1.0 if parameter in LENGTH_NAMES else angle_scale(units)


def pose_to_internal(pose: list[float], units: Units) -> np.ndarray:
    """A pose 6-vector with its angles in radians."""
    return np.array([value * parameter_scale(name, units) for name, value in zip(PARAMETERS, pose)])


def parameter_scales(compiled, names: list[str]) -> np.ndarray:
    """Factors from internal units (rad) to the problem's units, per parameter name
    (``LINK.PARAMETER``): the inverses of :func:`parameter_scale`."""
    units = compiled.problem.units
    return np.array([1.0 / parameter_scale(name.rsplit(".", 1)[1], units) for name in names])


def pose_scales(compiled) -> np.ndarray:
    """Factors from internal units (rad) to the problem's units, per pose parameter tx ... rz."""
    return np.array([1.0 / parameter_scale(name, compiled.problem.units) for name in PARAMETERS])
