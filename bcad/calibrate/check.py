"""The importance-sampling check of the Laplace answer (issue 10).

The Laplace approximation N(MAP, Sigma) is exact for a linear model with
Gaussian priors and noise; a calibration is neither (the kinematics bend,
a prior may be uniform). The check draws N samples from the Laplace
Gaussian widened by 1 + SPREAD / sqrt(n) in each of the n dimensions (so that
its tails cover the posterior's; for an exactly Gaussian posterior this keeps
an effective sample fraction of about exp(-SPREAD^2), whatever n), and
weighs each by the exact posterior over the proposal:

    log w = -1/2 sum_rows w_r |r(theta)|^2 + log p(theta) - log q(theta),

p the exact priors (not their Gaussian surrogates), r the whitened residuals,
w_r the robust loss's row weights. The self-normalised weighted mean and std
are the posterior's, with the standard error of the mean, the effective
sample size and PSIS's Pareto k̂ (:mod:`bcad.numerics.weights`): k̂ > 0.7 means
the check itself cannot be trusted. The two answers disagree when a mean
moves by more than SHIFT Laplace std (beyond 3 standard errors) or a std
changes by a ratio outside STD_RATIO.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bcad.numerics.streaming import WeightedPoseSums

#: the proposal's std over the Laplace std is 1 + SPREAD / sqrt(n)
SPREAD = 0.5
#: samples x parameters drawn at a time (the residuals are evaluated in the model's own chunks)
CHUNK = 1 << 18
#: samples of an adaptation pass at most (held in memory for their covariance)
ADAPT_SAMPLES = 4096
#: the check fails (cannot be trusted) above this k̂, or below MIN_ESS effective samples
MAX_PARETO_K = 0.7
MIN_ESS = 100.0
#: passes of a quarter of the samples that adapt the proposal, each only with this many effective samples at least
ADAPTATIONS = 1
MIN_ADAPT_ESS = 20.0
#: the Laplace answer is off when a mean moves by more than SHIFT of its std, or a std by a ratio outside STD_RATIO
SHIFT = 0.3
STD_RATIO = (0.8, 1.25)


@dataclass
class LaplaceCheck:
    samples: int
    mean: np.ndarray
    std: np.ndarray
    mean_se: np.ndarray
    effective_samples: float
    pareto_k: float

    @property
    def trusted(self) -> bool:
        return bool(self.effective_samples >= MIN_ESS and not self.pareto_k > MAX_PARETO_K)

    def disagreement(self, estimate: np.ndarray, std: np.ndarray) -> list[int]:
        """Positions where the Laplace answer (estimate, std) and the sampled posterior differ."""
        shift = np.abs(self.mean - estimate) - 3.0 * self.mean_se
        ratio = self.std / np.maximum(std, 1e-300)
        off = (shift > SHIFT * std) | (ratio < STD_RATIO[0]) | (ratio > STD_RATIO[1])
        return [int(k) for k in np.flatnonzero(off)]


def _proposal_factor(covariance: np.ndarray) -> tuple[np.ndarray, float]:
    """S with S S^T = the proposal's covariance, and log |det S|: Cholesky's, or, where rounding
    has left the covariance not quite positive definite (noise of 1e-12, 100,000 rows), the
    eigen-decomposition's with the eigenvalues floored at 1e-14 of the largest: a proposal a
    little wider in the directions the data pin down, whose density stays exact."""
    symmetric = 0.5 * (covariance + covariance.T)
    try:
        scale = np.linalg.cholesky(symmetric + 1e-300 * np.eye(len(symmetric)))
        return scale, float(np.sum(np.log(np.diagonal(scale))))
    except np.linalg.LinAlgError:
        values, vectors = np.linalg.eigh(symmetric)
        values = np.maximum(values, max(float(values.max(initial=0.0)), 1e-300) * 1e-14)
        return vectors * np.sqrt(values), float(0.5 * np.sum(np.log(values)))


def _importance_pass(model, objective, rng, mean: np.ndarray, covariance: np.ndarray, samples: int, sink) -> None:
    """``samples`` draws of N(mean, covariance), CHUNK at a time, each chunk's draws and
    log-weights against the exact posterior handed to ``sink(thetas, log_weights)``."""
    priors = objective.priors
    n = len(mean)
    scale, log_determinant = _proposal_factor(covariance)
    held = objective.prior_rows & ~priors.gaussian  # flat X held by a row: that row is their prior here
    # draws per chunk: CHUNK values of theta, and as many of the residuals (100,000 rows: 3 draws)
    step = max(1, CHUNK // max(1, n, len(objective.sqrt_weights)))
    for start in range(0, samples, step):
        normal = rng.standard_normal((min(step, samples - start), n))
        thetas = mean + normal @ scale.T
        log_proposal = -0.5 * np.sum(normal * normal, axis=1) - log_determinant
        r = model.residuals_batch(thetas) * objective.sqrt_weights
        log_likelihood = -0.5 * np.sum(r * r, axis=1)
        z_held = (thetas[:, held] - priors.mean[held]) / priors.std[held]
        log_prior = priors.log_density(thetas) - 0.5 * np.sum(z_held * z_held, axis=1)
        with np.errstate(invalid="ignore"):
            log_weights = log_likelihood + log_prior - log_proposal
        log_weights[~np.isfinite(log_weights)] = -np.inf
        sink(thetas, log_weights)


def _weighted_moments(thetas: np.ndarray, log_weights: np.ndarray):
    """Self-normalised mean, covariance and ESS; None without a finite weight."""
    peak = np.max(log_weights)
    if not math.isfinite(peak):
        return None
    w = np.exp(log_weights - peak)
    w /= w.sum()
    mean = w @ thetas
    centred = thetas - mean
    return mean, (w[:, None] * centred).T @ centred, float(1.0 / np.sum(w * w))


def check_laplace(model, objective, calibration, samples: int, seed: int) -> LaplaceCheck:
    """Importance sampling of the posterior: ADAPTATIONS passes of a quarter of the samples (at
    most ADAPT_SAMPLES), the first from the widened Laplace Gaussian, each next one from the
    Gaussian of the previous pass's weighted moments (blended with the previous proposal's so
    that it cannot collapse), widened the same way; then the samples that count, from the last
    Gaussian, streamed (the memory does not grow with their number). Where the posterior bends
    away from Laplace's Gaussian (a banana between a zero offset and a tool offset, say), the
    last proposal follows it."""
    n = len(calibration.estimate)
    rng = np.random.default_rng(seed)
    widen = (1.0 + SPREAD / math.sqrt(n)) ** 2
    mean, covariance = calibration.estimate, calibration.covariance
    for _ in range(ADAPTATIONS):
        chunks: list[tuple[np.ndarray, np.ndarray]] = []
        _importance_pass(model, objective, rng, mean, covariance * widen, min(ADAPT_SAMPLES, max(100, samples // 4)),
                         lambda thetas, log_weights: chunks.append((thetas, log_weights)))
        found = _weighted_moments(np.concatenate([c[0] for c in chunks]), np.concatenate([c[1] for c in chunks]))
        if found is None or found[2] < MIN_ADAPT_ESS:
            break
        mean, covariance = found[0], 0.5 * (found[1] + covariance)
    sums = WeightedPoseSums(samples, np.zeros(n, dtype=bool))
    _importance_pass(model, objective, rng, mean, covariance * widen, samples, lambda thetas, log_weights: sums.add_values(log_weights, thetas))
    moments = sums.moments()
    if moments is None:
        nan = np.full(n, np.nan)
        return LaplaceCheck(samples, nan, nan, nan, 0.0, math.inf)
    return LaplaceCheck(samples, moments["mean"], moments["std"], moments["mean_se"], sums.effective_samples, sums.pareto_k)
