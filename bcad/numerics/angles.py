"""Angles as numbers: the one wrapping convention every layer uses."""

from __future__ import annotations

import numpy as np


def wrap_angle(angle: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi), rad."""
    return (np.asarray(angle) + np.pi) % (2.0 * np.pi) - np.pi
