"""cos_sin: Taylor polynomials for small angles, the C library's functions otherwise."""

from __future__ import annotations

import numpy as np
import pytest

from bcad.numerics.angles import SMALL_ANGLE, cos_sin


@pytest.mark.parametrize("scale", [1e-9, 1e-4, 1e-3, 1e-2, 0.04, 0.999 * SMALL_ANGLE])
def test_small_angles_are_within_an_ulp_of_the_library(scale):
    angle = np.random.default_rng(7).uniform(-scale, scale, 200_000)
    cosine, sine = cos_sin(angle)
    assert np.all(np.abs(cosine - np.cos(angle)) <= np.spacing(np.cos(angle)))
    assert np.all(np.abs(sine - np.sin(angle)) <= np.spacing(np.abs(np.sin(angle))))


def test_each_value_is_the_same_whatever_array_it_comes_in():
    """Large angles go to the library, small ones to the polynomials, element by element: a
    batch evaluated whole or in blocks gives the same bits."""
    angle = np.random.default_rng(3).normal(0.0, 0.03, 10_000)
    angle[::97] = 3.0  # past SMALL_ANGLE
    angle[5000:5800] = 2.0  # a block of mostly large angles: the other path
    whole = cos_sin(angle)
    blocks = [cos_sin(angle[start : start + 1000]) for start in range(0, len(angle), 1000)]
    for k in (0, 1):
        assert np.array_equal(whole[k], np.concatenate([block[k] for block in blocks]))
    assert np.array_equal(whole[0][::97], np.cos(angle[::97]))
    small = np.abs(angle) < SMALL_ANGLE
    assert np.array_equal(cos_sin(angle[small])[1], whole[1][small])


def test_not_finite_and_empty_arrays_are_the_library_s():
    cosine, sine = cos_sin(np.array([np.nan, 0.01]))
    assert np.isnan(cosine[0]) and np.isnan(sine[0]) and cosine[1] == np.cos(0.01)
    assert cos_sin(np.zeros(0))[0].shape == (0,)


def test_negative_zero_keeps_its_sign():
    assert np.signbit(cos_sin(np.array([-0.0, 0.0]))[1]).tolist() == [True, False]
