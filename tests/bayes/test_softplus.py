"""The inequalities' logistic kernel, log(1 + exp(a)) summed over a row, against numpy's logaddexp."""

from __future__ import annotations

import numpy as np

from bcad.bayes.linear import SOFTPLUS_PRODUCT, softplus_sum


def test_softplus_sum_matches_logaddexp_over_the_whole_range():
    rng = np.random.default_rng(0)
    for scale in (1.0, 30.0, 1000.0):
        a = rng.normal(scale=scale, size=(300, 16))
        a[0, :4] = [-750.0, -710.0, 710.0, 1e6]  # beyond exp's range either way
        expected = np.logaddexp(0.0, a).sum(axis=1)
        found = softplus_sum(a.copy())
        # each entry's factor 1 + exp(-|a|) rounds by half an ulp of 1: a few ulp of each row's sum (or of 1)
        assert np.all(np.abs(found - expected) <= 16 * np.spacing(np.abs(expected) + 1.0))
        assert np.all(np.isfinite(found))


def test_softplus_sum_splits_long_rows_before_the_product_overflows():
    # 2 * SOFTPLUS_PRODUCT + 1 entries at 0: each log(2), a product of 2^2001 if taken at once
    a = np.zeros((3, 2 * SOFTPLUS_PRODUCT + 1))
    np.testing.assert_allclose(softplus_sum(a), (2 * SOFTPLUS_PRODUCT + 1) * np.log(2.0), rtol=1e-14)


def test_softplus_sum_keeps_infinities_and_nan():
    found = softplus_sum(np.array([[np.inf, 0.0], [-np.inf, 0.0], [np.nan, 0.0]]))
    assert found[0] == np.inf
    assert abs(found[1] - np.log(2.0)) < 1e-15
    assert np.isnan(found[2])


def _by_reduce(a: np.ndarray) -> np.ndarray:
    """softplus_sum as numpy's reductions along the last axis compute it (rows of any length)."""
    factors = 1.0 + np.exp(-np.minimum(np.abs(a), 40.0))
    return np.add.reduce(np.maximum(a, 0.0), axis=-1) + np.log(np.multiply.reduce(factors, axis=-1))


def test_short_rows_summed_column_by_column_equal_numpys_reductions_bit_for_bit():
    rng = np.random.default_rng(1)
    for columns in range(1, 12):
        for shape in ((5, columns), (7, 33, columns), (1, 1, columns)):
            a = rng.normal(scale=20.0, size=shape)
            assert np.array_equal(softplus_sum(a.copy()), _by_reduce(a))
