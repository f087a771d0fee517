"""The inequalities' logistic kernel, log(1 + exp(a)), against numpy's logaddexp."""

from __future__ import annotations

import numpy as np

from bcad.bayes.linear import softplus


def test_softplus_matches_logaddexp_over_the_whole_range():
    rng = np.random.default_rng(0)
    a = np.concatenate([rng.normal(scale=s, size=20000) for s in (1.0, 30.0, 1000.0)] + [[-750.0, -710.0, 710.0, 1e6]])
    expected = np.logaddexp(0.0, a)
    found = softplus(a.copy())
    inside = np.abs(a) <= 700.0
    np.testing.assert_allclose(found[inside], expected[inside], rtol=4e-16, atol=0.0)
    # beyond, the exponential term is under 1e-304: a itself above, (almost) nothing below
    np.testing.assert_allclose(found[~inside], expected[~inside], rtol=4e-16, atol=1e-303)
    assert np.all(np.isfinite(found))
    # the input untouched unless overwriting is asked for
    kept = a.copy()
    softplus(kept)
    assert np.array_equal(kept, a)
