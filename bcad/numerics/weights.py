"""The Pareto k̂ diagnostic of importance weights (PSIS).

Vehtari, Simpson, Gelman, Yao and Gabry, "Pareto smoothed importance
sampling" (JMLR 2024), Sect. 3: fit a generalised Pareto distribution to the
M = min(ceil(0.2 N), ceil(3 sqrt(N))) largest weights, as exceedances over
the (M + 1)-th largest; its shape k̂ says how heavy the weights' tail is.
k̂ < 0.5: the variance of the weights is finite and the central limit theorem
holds; 0.5 < k̂ < 0.7: it holds slowly; k̂ > 0.7: the estimate and its
standard error cannot be trusted. The shape is estimated by Zhang and
Stephens' empirical-Bayes profile method (Technometrics 2009, Sect. 3.2),
with PSIS's weakly informative prior shrinking k̂ towards 0.5 with weight 10.

Also Kish's effective sample size and the standard error of a log-ratio of two
weightings of the same samples.

Weights arrive as log-weights; streams keep only their upper tail
(:func:`tail_size` values), which is all k̂ needs. Where MIN_TAIL or more of the
largest weights are equal, the weights are bounded and reach their bound: k̂ is
undefined (nan) and the effective sample size alone judges the estimate
(:mod:`bcad.bayes.trust`).
"""

from __future__ import annotations

import math

import numpy as np

#: prior of the GPD shape in PSIS: k̂ <- (M k + PRIOR_WEIGHT * PRIOR_K) / (M + PRIOR_WEIGHT)
PRIOR_K = 0.5
PRIOR_WEIGHT = 10.0
#: fewer tail weights than this: no k̂ (nan); as many tied at the largest (log-weights within
#: TIE of it): no k̂ either (:func:`pareto_k_of_tail`)
MIN_TAIL = 5
TIE = 1e-12


def tail_count(n: int) -> int:
    """M, the number of tail weights fitted for N samples."""
    return int(min(math.ceil(0.2 * n), math.ceil(3.0 * math.sqrt(n)))) if n > 0 else 0


def tail_size(n: int) -> int:
    """How many of the largest log-weights a stream must keep: M + 1 (the threshold too)."""
    return tail_count(n) + 1


def generalised_pareto_shape(exceedances: np.ndarray) -> float:
    """Zhang-Stephens estimate of the GPD shape k from positive exceedances, with PSIS's prior.

    With theta = -k / sigma (k > 0: a heavy tail), k(theta) = mean(log(1 - theta x))
    and the profile log-likelihood n (log(-theta / k(theta)) - k(theta) - 1) is
    evaluated on a grid of m = 30 + sqrt(n) points
    theta_j = 1 / x_max + (1 - sqrt(m / (j - 1/2))) / (3 x_(n/4)); the estimate of
    theta is the posterior mean over the grid (profile likelihoods as weights),
    and k = mean(log(1 - theta x)) there.
    """
    x = np.sort(np.asarray(exceedances, dtype=float))
    n = len(x)
    grid = 30 + int(math.sqrt(n))
    theta = 1.0 - np.sqrt(grid / (np.arange(1, grid + 1) - 0.5))
    theta = theta / (3.0 * x[int(n / 4 + 0.5) - 1]) + 1.0 / x[-1]
    k = np.mean(np.log1p(-theta[:, None] * x[None, :]), axis=1)
    profile = n * (np.log(-theta / k) - k - 1.0)
    weights = 1.0 / np.sum(np.exp(profile[None, :] - profile[:, None]), axis=1)
    weights /= weights.sum()
    theta_hat = float(weights @ theta)
    k_hat = float(np.mean(np.log1p(-theta_hat * x)))
    return (n * k_hat + PRIOR_WEIGHT * PRIOR_K) / (n + PRIOR_WEIGHT)


def pareto_k_of_tail(tail_log_weights: np.ndarray, n: int) -> float:
    """k̂ from the largest log-weights of N (at least :func:`tail_size` of them); nan if undefined."""
    tail = np.sort(np.asarray(tail_log_weights, dtype=float))
    tail = tail[np.isfinite(tail)]
    m = min(tail_count(n), len(tail) - 1)
    if m < MIN_TAIL:
        return math.nan
    peak = tail[-1]
    if np.count_nonzero(tail >= peak - TIE) >= MIN_TAIL:
        # An atom at the top: the weights reach their bound on a set of positive mass (a
        # plateau of the integrand sampled from the prior), so they are bounded and the bound
        # is attained: no generalised Pareto tail, and a fit to the atom and what lies below
        # it (e.g. 400 of 1e5 weights at 1, the rest below e^-5) reports k = 7.4.
        return math.nan
    weights = np.exp(tail[-(m + 1) :] - peak)
    exceedances = weights[1:] - weights[0]
    exceedances = exceedances[exceedances > 0]
    if len(exceedances) < MIN_TAIL or exceedances[-1] <= exceedances[0] * (1 + 1e-12):
        return math.nan
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        k = generalised_pareto_shape(exceedances)
    return k if math.isfinite(k) else math.nan


def pareto_k(log_weights: np.ndarray) -> float:
    """k̂ of a whole array of log-weights."""
    log_weights = np.asarray(log_weights, dtype=float)
    keep = tail_size(len(log_weights))
    finite = log_weights[np.isfinite(log_weights)]
    tail = finite if len(finite) <= keep else np.partition(finite, len(finite) - keep)[-keep:]
    return pareto_k_of_tail(tail, len(log_weights))


def effective_sample_size(log_weights: np.ndarray) -> float:
    """Kish's (sum w)^2 / sum w^2 of log-weights (0 without weight)."""
    peak = float(np.max(log_weights))
    if not np.isfinite(peak):
        return 0.0
    w = np.exp(log_weights - peak)
    return float(w.sum() ** 2 / np.sum(w * w))


def paired_log_ratio_se(log_a: np.ndarray, log_b: np.ndarray) -> float:
    """Standard error of log mean(a) - log mean(b) for weights a_i, b_i of the same samples (the
    delta method on the paired terms a_i / mean(a) - b_i / mean(b)); inf without weight."""
    peak = max(float(np.max(log_a)), float(np.max(log_b)))
    if not np.isfinite(peak):
        return math.inf
    a, b = np.exp(log_a - peak), np.exp(log_b - peak)
    if a.sum() <= 0.0 or b.sum() <= 0.0:
        return math.inf
    return float(np.std(a / a.mean() - b / b.mean()) / math.sqrt(len(a)))
