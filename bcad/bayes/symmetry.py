"""Mirror-image configurations: two X whose integrands are one another's up to reflected L.

A 6R arm reaches a pose in up to eight ways (shoulder, elbow and wrist flips). Where a flip moves
the tool by some L's errors exactly as the other configuration moves it by their opposites (a
wrist flip turns joint 5's axis end over end, so its zero error acts with the opposite sign), and
those L are distributed symmetrically about their means (a joint zero N(0, σ)), the two integrands
are one another's with those L reflected, f(X_b, L) = f(X_a, S(L)), and I(X_b) = I(X_a) exactly.
A planar two-joint arm reaches a line in two mirror images. On the RX90 example, pairs (one
arm's shoulder turned half a turn, its next two joints negated) turn up among maxima 0.3 below
the best, and once among the best two (seed 9, below); its other best maxima are distinct
contacts (the part turned on the face).

The finalists' choice (:func:`bcad.bayes.estimators.choose_finalist`) cannot separate such twins:
their estimates differ by noise alone, and raising the samples until each is known within ±0.005
buys nothing. A finalist spent on a twin is also one not spent on another configuration. So the
finalists are chosen distinct up to mirror images (:func:`mirror_image`).

The test, at the integrand's inputs (the poses of the chains the scores and relations read),
each row measured in its own spread (its linearised std in L, with its score's where it is
scored), as the integrand sees them:

1. log p(X) equal (within TOLERANCE);
2. every row's pose at L = mean equal, and every L's column of the Jacobians equal or opposite
   (within TOLERANCE of the rows' spreads): the opposite columns are the reflected L;
3. every reflected L's distribution symmetric about its mean and independent of the others
   (a normal, a uniform, a truncated normal with bounds symmetric about its centre, a disc; a
   calibration's joint normal where its covariance does not tie reflected and kept L);
4. at DRAWS prior draws of L, the poses at X_b equal those at X_a with the reflected L, again
   within TOLERANCE of the spreads (the reflection holds beyond first order).

Two configurations that pass are as robust as one another to within TOLERANCE of their scores'
widths. Twins that separate climbs converged to pass (the planar arm's); a pair converged less
closely passes once the finalists are polished, where they are checked again: on seed 9 of the
RX90 example the two best maxima are 4.6 % of a spread apart at the prior draws before their
polish and 0.1 % after it, and setting one aside there took the choice from 131,072 samples to
88,250 (the finalists' phase from 2.1 s to 1.0 s).
"""

from __future__ import annotations

import numpy as np

from bcad.bayes.model import BayesModel
from bcad.kinematics.chain import Samples
from bcad.kinematics.se3 import wrap_angle
from bcad.model.distributions import MultivariateNormal, Normal, TruncatedNormal, Uniform, UniformDisc

#: differences within this share of a row's spread (its std) are equal, and log p(X) within this
TOLERANCE = 0.02
#: prior draws of L at which the reflection is checked beyond first order
DRAWS = 32
#: a row whose spread is below this share of its pose's magnitude (and 1) does not move with L:
#: its poses must agree to this, relatively
FLOOR = 1e-9


def mirror_image(model: BayesModel, a: np.ndarray, b: np.ndarray) -> bool:
    """Whether X ``b``'s integrand is X ``a``'s with some L reflected about their means (module
    docstring): then p(b) I(b) = p(a) I(a), and the two are one configuration for the choice.

    Args:
        model: the problem's Bayesian model.
        a, b: two unknown vectors X, shape (nX,).
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    prior = model.objective.log_prior(np.array([a, b]))
    if not np.all(np.isfinite(prior)) or abs(prior[0] - prior[1]) > TOLERANCE:
        return False
    linear = model.linear
    rows = np.concatenate([linear.scored_rows, linear.relation_rows]).astype(int)
    if not len(rows):
        return False
    found = linear.linearise(np.array([a, b]))
    poses, jacobians = found.poses[:, rows], found.jacobians[:, rows]  # (2, r), (2, r, nL)
    angular = np.isin(rows % 6, (3, 4, 5))
    spread = np.sqrt(jacobians[0] ** 2 @ linear.variance_l + _score_variance(linear, rows))
    spread = np.maximum(spread, FLOOR * np.maximum(np.abs(poses[0]), 1.0))
    if not _close(poses[1] - poses[0], angular, spread):
        return False
    sigma = np.sqrt(linear.variance_l)
    same = np.max(np.abs(jacobians[1] - jacobians[0]) * sigma / spread[:, None], axis=0)
    opposite = np.max(np.abs(jacobians[1] + jacobians[0]) * sigma / spread[:, None], axis=0)
    reflected = (opposite <= TOLERANCE) & (same > TOLERANCE)
    if np.any((same > TOLERANCE) & ~reflected):
        return False  # an L that moves the two differently
    if reflected.any() and not _symmetric(model, reflected):
        return False
    # beyond first order: the poses at prior draws of L, the reflected ones mirrored at X_a
    deviations = model.compiled.parameters.sample_free_parameters(np.random.default_rng(0), DRAWS)
    mirrored = deviations.copy()
    mirrored[:, reflected] = 2.0 * linear.mean_l[reflected] - deviations[:, reflected]
    at_b = _poses(linear, b, Samples(deviations))[:, rows]
    at_a = _poses(linear, a, Samples(mirrored))[:, rows]
    return _close(at_b - at_a, angular, spread)


def _score_variance(linear, rows: np.ndarray) -> np.ndarray:
    variance = np.zeros(len(rows))
    scored = {int(row): k for k, row in enumerate(linear.scored_rows)}
    for k, row in enumerate(rows):
        if int(row) in scored:
            variance[k] = linear.scored_variance[scored[int(row)]]
    return variance


def _close(difference: np.ndarray, angular: np.ndarray, spread: np.ndarray) -> bool:
    difference = np.array(difference, dtype=float)
    difference[..., angular] = wrap_angle(difference[..., angular])
    return bool(np.all(np.abs(difference) <= TOLERANCE * spread))


def _poses(linear, x: np.ndarray, samples: Samples) -> np.ndarray:
    """Every chain's poses at X for each sample, stacked as the linear model's rows, (N, R)."""
    return np.concatenate([chain.evaluate(x, samples).poses() for chain in linear.chains], axis=1)


def _symmetric(model: BayesModel, reflected: np.ndarray) -> bool:
    """Whether reflecting the ``reflected`` L about their means leaves p(L) unchanged."""
    for group in model.compiled.parameters.l_groups:
        columns = list(group.columns)
        flips = reflected[columns]
        if not flips.any():
            continue
        d = group.distribution
        if isinstance(d, (Normal, Uniform, UniformDisc)):
            continue
        if isinstance(d, TruncatedNormal):
            if abs((d.low - d.mean) + (d.high - d.mean)) <= 1e-12 * max(d.high - d.low, 1e-300):
                continue
            return False
        if isinstance(d, MultivariateNormal):
            if np.all(d.covariance[np.ix_(flips, ~flips)] == 0.0):
                continue
            return False
        return False  # a distribution not known to be symmetric
    return True
