"""The Pareto k̂ of importance weights (bcad.numerics.weights): right on tails of known
shape, and undefined (not a false alarm) on bounded weights that reach their bound."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bcad.bayes.estimators import ObjectiveEstimate
from bcad.bayes.trust import result_warnings
from bcad.numerics.streaming import LogWeightSums
from bcad.numerics.weights import pareto_k

N = 100_000


@pytest.mark.parametrize("shape", [0.3, 0.8])
def test_k_hat_recovers_the_shape_of_a_generalised_pareto_tail(shape):
    """Weights drawn from a generalised Pareto distribution of shape k (by inversion, an
    independent construction): k̂ within 0.1 of k (PSIS's prior pulls it slightly towards 0.5)."""
    u = np.random.default_rng(1).random(N)
    weights = (u ** (-shape) - 1.0) / shape
    assert pareto_k(np.log(weights)) == pytest.approx(shape, abs=0.1)


def test_light_and_bounded_tails_are_below_one_half():
    rng = np.random.default_rng(2)
    assert pareto_k(-0.5 * rng.standard_normal(N) ** 2) < 0.0  # bounded, density peaked at the bound
    assert pareto_k(np.log(rng.random(N))) < 0.0  # uniform weights: k = -1


def test_an_atom_at_the_bound_leaves_k_undefined_and_the_effective_samples_judge():
    """0.4 % of the weights at their bound 1 (a plateau of the integrand), the rest below e^-5:
    the GPD fit to that two-level tail said k = 7.4 (pareto_k_high on a sound estimate). The
    weights are bounded and reach their bound: k̂ is undefined, in a stream too, and with 400
    weights at the top the estimate passes on its effective samples."""
    rng = np.random.default_rng(3)
    top = rng.random(N) < 0.004
    log_weights = np.where(top, 0.0, -5.0 - 0.5 * rng.standard_normal(N) ** 2)
    assert math.isnan(pareto_k(log_weights))
    sums = LogWeightSums(N)
    for chunk in np.array_split(log_weights, 7):
        sums.add(chunk)
    assert math.isnan(sums.pareto_k)
    estimate = ObjectiveEstimate(
        "importance", sums.log_mean, sums.log_mean_se, N, sums.effective_samples, sums.pareto_k, []
    )
    assert sums.effective_samples > 0.005 * N
    assert result_warnings(type("Posterior", (), {"links": [], "samples": 100_000})(), estimate) == []
    # Four ties are not an atom: k̂ is fitted as usual.
    few = log_weights.copy()
    few[np.flatnonzero(top)[4:]] = -5.0
    assert math.isfinite(pareto_k(few))


def test_the_shape_estimate_agrees_with_scipys_maximum_likelihood():
    """Zhang-Stephens' profile estimate against scipy's generalised Pareto MLE on the same
    exceedances (an independent fit): within 0.02 (the prior moves it by about 0.002)."""
    from scipy.stats import genpareto

    from bcad.numerics.weights import generalised_pareto_shape, tail_count

    for seed, shape in [(0, 0.3), (1, 0.6), (2, -0.2)]:
        u = np.random.default_rng(seed).random(N)
        weights = np.sort((u ** (-shape) - 1.0) / shape)
        m = tail_count(N)
        exceedances = weights[-m:] - weights[-m - 1]
        mle = genpareto.fit(exceedances, floc=0)[0]
        assert generalised_pareto_shape(exceedances) == pytest.approx(mle, abs=0.02)
