"""The temperature relaxation of Sect. 4.2.1 of the 2000 paper.

The objective G(X) can have a narrow support; the GA works on a widened
G^T(X) with lim_{T->0} G^T = G. Every elementary term is widened:

* a Gaussian N(mu, sigma) becomes N(mu, sigma (1 + T));
* an interval indicator 1[a <= x <= b] becomes 1 inside and
  exp(-(d / w)^2 / T) outside, where d is the distance to the interval and
  w = b - a its width.

The paper prints the interval's tail as exp(-(x - a)^2 / (b - a)^T); the
extraction garbled the exponent, and read literally it would not tend to the
indicator as T -> 0. bcad reads it as a Gaussian tail whose variance grows
with T and is measured in units of the interval's width, which tends to the
indicator as T -> 0 and does not depend on the problem's length unit.
Inequality constraints of relations (signed distances) are relaxed the same
way, with w the polygon's width along the constraint's normal (Fig. 2).
"""

from __future__ import annotations

import numpy as np


def relaxed_log_indicator(distance: np.ndarray, width: np.ndarray | float, temperature: float) -> np.ndarray:
    """log f^T for signed distances (<= 0 inside): 0 inside, -(d/w)^2/T outside, -inf at T = 0."""
    outside = np.maximum(distance, 0.0)
    if temperature <= 0.0:
        return np.where(outside > 0.0, -np.inf, 0.0)
    outside /= width
    outside *= outside
    outside *= -1.0 / temperature
    return outside
