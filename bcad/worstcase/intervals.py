"""Outward-rounded interval arithmetic on numpy arrays.

IEEE 754 rounds every +, -, *, / and sqrt to the nearest double, so the exact
result lies within one ulp of the computed one. Stepping each computed bound
one ulp outward (``np.nextafter``) therefore encloses the exact result: the
same guarantee as switching the rounding mode, without touching the FPU
state, and vectorised over as many intervals as numpy holds. Used for the
certified bounds of ``bcad maxerror``, where every quantity is a handful of
products and sums per box.
"""

from __future__ import annotations

import numpy as np


def down(x: np.ndarray) -> np.ndarray:
    return np.nextafter(x, -np.inf)


def up(x: np.ndarray) -> np.ndarray:
    return np.nextafter(x, np.inf)


class Interval:
    """Arrays of intervals [lo, hi] with outward-rounded operations."""

    __slots__ = ("lo", "hi")

    def __init__(self, lo, hi=None):
        self.lo = np.asarray(lo, dtype=float)
        self.hi = self.lo if hi is None else np.asarray(hi, dtype=float)

    @staticmethod
    def _of(value) -> Interval:
        return value if isinstance(value, Interval) else Interval(value)

    def __getitem__(self, index) -> Interval:
        return Interval(self.lo[index], self.hi[index])

    def __add__(self, other) -> Interval:
        other = self._of(other)
        return Interval(down(self.lo + other.lo), up(self.hi + other.hi))

    __radd__ = __add__

    def __sub__(self, other) -> Interval:
        other = self._of(other)
        return Interval(down(self.lo - other.hi), up(self.hi - other.lo))

    def __neg__(self) -> Interval:
        return Interval(-self.hi, -self.lo)

    def __mul__(self, other) -> Interval:
        other = self._of(other)
        products = np.stack([self.lo * other.lo, self.lo * other.hi, self.hi * other.lo, self.hi * other.hi])
        return Interval(down(products.min(axis=0)), up(products.max(axis=0)))

    __rmul__ = __mul__

    def scale(self, values: np.ndarray) -> Interval:
        """Products with exact floats (two products instead of four)."""
        a, b = self.lo * values, self.hi * values
        return Interval(down(np.minimum(a, b)), up(np.maximum(a, b)))

    def square(self) -> Interval:
        low = self.mignitude()
        high = self.magnitude()
        return Interval(down(low * low), up(high * high))

    def sqrt(self) -> Interval:
        return Interval(down(np.sqrt(np.maximum(self.lo, 0.0))), up(np.sqrt(np.maximum(self.hi, 0.0))))

    def magnitude(self) -> np.ndarray:
        """max |x| over the interval."""
        return np.maximum(np.abs(self.lo), np.abs(self.hi))

    def mignitude(self) -> np.ndarray:
        """min |x| over the interval."""
        return np.where(self.lo > 0, self.lo, np.where(self.hi < 0, -self.hi, 0.0))

    def sum(self, axis: int) -> Interval:
        """Sum along an axis: numpy's sums of the ends, widened by the error bound of floating-point
        summation, |fl(sum x_i) - sum x_i| <= gamma_(k-1) sum |x_i| with gamma_m = m u / (1 - m u),
        u = 2^-53, for k terms in any order (Higham, *Accuracy and Stability of Numerical
        Algorithms*, Sect. 4.2); 2 gamma covers the rounding of sum |x_i| and of the product, and
        the final subtraction is stepped outward."""
        terms = self.lo.shape[axis]
        if terms <= 1:
            return Interval(np.sum(self.lo, axis=axis), np.sum(self.hi, axis=axis))
        unit = 2.0**-53
        gamma = (terms - 1) * unit / (1.0 - (terms - 1) * unit)
        low = down(np.sum(self.lo, axis=axis) - 2.0 * gamma * np.sum(np.abs(self.lo), axis=axis))
        high = up(np.sum(self.hi, axis=axis) + 2.0 * gamma * np.sum(np.abs(self.hi), axis=axis))
        return Interval(low, high)


def norm_upper(components: list[Interval]) -> np.ndarray:
    """An upper bound of the Euclidean norm of vectors whose components are intervals."""
    total = np.zeros_like(components[0].lo)
    for component in components:
        magnitude = component.magnitude()
        total = up(total + up(magnitude * magnitude))
    return up(np.sqrt(total))


def norm_lower(components: list[Interval]) -> np.ndarray:
    """A lower bound of the Euclidean norm of vectors whose components are intervals."""
    total = np.zeros_like(components[0].lo)
    for component in components:
        mignitude = component.mignitude()
        total = down(total + down(mignitude * mignitude))
    return np.maximum(down(np.sqrt(np.maximum(total, 0.0))), 0.0)  # a norm's bound is never below 0
