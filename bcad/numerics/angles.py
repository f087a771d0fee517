"""Angles as numbers: the one wrapping convention every layer uses."""

from __future__ import annotations

import numpy as np


def wrap_angle(angle: np.ndarray) -> np.ndarray:
    """Angles wrapped to [-pi, pi), rad."""
    return (np.asarray(angle) + np.pi) % (2.0 * np.pi) - np.pi


#: below this |angle| (rad), :func:`cos_sin` evaluates Taylor polynomials: the first term left
#: out, x^10 / 10! for the cosine and x^11 / 11! for the sine, is below 3e-19 of the value there
SMALL_ANGLE = 1.0 / 16.0
#: the polynomials' coefficients after the leading 1 and x, highest power first
_COS_TERMS = (1.0 / 40320.0, -1.0 / 720.0, 1.0 / 24.0, -0.5)
_SIN_TERMS = (1.0 / 362880.0, -1.0 / 5040.0, 1.0 / 120.0, -1.0 / 6.0)


def cos_sin(angle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin of an array of angles, rad. Where |angle| is below SMALL_ANGLE (the errors of a
    joint or a mounting, drawn per sample), by their Taylor polynomials in Horner form: within an
    ulp of ``np.cos`` and ``np.sin`` (tests/numerics), about five times faster, since numpy
    evaluates a polynomial in a few vectorised passes where ``np.sin`` calls the C library per
    element. The choice is made element by element, so a value does not depend on the array it
    came in (a batch evaluated whole or in blocks gives the same bits)."""
    angle = np.asarray(angle, dtype=float)
    small = np.abs(angle) < SMALL_ANGLE  # False for NaN: the library's
    if small.all():
        return _taylor(angle)
    count = int(np.count_nonzero(small))
    if count == 0:
        return np.cos(angle), np.sin(angle)
    if 2 * count >= small.size:
        # mostly small: the polynomials everywhere (the large angles as 0), the library on the rest
        cosine, sine = _taylor(np.where(small, angle, 0.0))
        large = ~small
        beyond = angle[large]
        cosine[large], sine[large] = np.cos(beyond), np.sin(beyond)
    else:  # mostly large: the library everywhere, the polynomials on the small ones
        cosine, sine = np.cos(angle), np.sin(angle)
        cosine[small], sine[small] = _taylor(angle[small])
    return cosine, sine


def _taylor(angle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin by their polynomials (|angle| < SMALL_ANGLE)."""
    square = angle * angle
    cosine = square * _COS_TERMS[0]
    for coefficient in _COS_TERMS[1:]:
        cosine += coefficient
        cosine *= square
    cosine += 1.0
    sine = square * _SIN_TERMS[0]
    for coefficient in _SIN_TERMS[1:]:
        sine += coefficient
        sine *= square
    sine *= angle
    sine += angle
    np.copysign(sine, angle, out=sine)  # sin(-0.0) is -0.0, as the library's (an atan2 of it is -pi)
    return cosine, sine
