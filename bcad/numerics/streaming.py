"""Streaming sums of importance weights: Monte Carlo figures with their standard errors.

Posteriors are sampled in chunks so that memory does not grow with the
sample count; these accumulators keep what the figures need. Weights arrive
as log-weights; sums are kept relative to the running maximum and rescaled
when it grows, so nothing overflows or underflows where the logs are finite.
Only the upper tail of the weights is kept, for the Pareto k̂ of PSIS.
"""

from __future__ import annotations

import math

import numpy as np

from bcad.numerics.angles import wrap_angle
from bcad.numerics.weights import pareto_k_of_tail, tail_size


def weighted_row_sums(rows: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """sum_n rows[:, n] * weights[n], by numpy's own loops (einsum) rather than BLAS: a
    multithreaded BLAS splits long dot products by thread, so ``rows @ weights`` changed in the
    last bits with the thread count, and a batch's serial and pooled (single-threaded) results
    differed."""
    return np.einsum("kn,n->k", rows, weights)


class LogWeightSums:
    """Sum of w and w^2 over a stream, and the largest log-weights.

    ``log_mean`` is log((1/N) sum w): log Î for importance or Monte Carlo
    weights, with its delta-method standard error sd(w) / (mean(w) sqrt(N)).
    """

    def __init__(self, expected: int):
        self.count = 0
        self.log_scale = -math.inf
        self.w = 0.0
        self.w2 = 0.0
        self.keep = tail_size(expected)
        self.tail = np.empty(0)

    def _rescale(self, peak: float) -> float:
        """Move the reference to ``peak``; returns the factor applied to sums of w."""
        shrink = math.exp(self.log_scale - peak) if math.isfinite(self.log_scale) else 0.0
        self.log_scale = peak
        self.w *= shrink
        self.w2 *= shrink * shrink
        return shrink

    def add(self, log_weights: np.ndarray) -> np.ndarray | None:
        """Add a chunk; returns its weights relative to the reference (None if all are 0)."""
        self.count += len(log_weights)
        finite = log_weights[np.isfinite(log_weights)]
        merged = np.concatenate([self.tail, finite])
        self.tail = merged if len(merged) <= self.keep else np.partition(merged, len(merged) - self.keep)[-self.keep :]
        if not finite.size:
            return None
        peak = float(finite.max())
        if peak > self.log_scale:
            self._rescale(peak)
        weights = np.exp(log_weights - self.log_scale)
        self.w += float(weights.sum())
        self.w2 += float(np.sum(weights * weights))
        return weights

    @property
    def log_mean(self) -> float:
        return self.log_scale + math.log(self.w / self.count) if self.w > 0 else -math.inf

    @property
    def log_mean_se(self) -> float:
        if self.w <= 0:
            return math.inf
        mean = self.w / self.count
        variance = max(self.w2 / self.count - mean * mean, 0.0)
        return math.sqrt(variance / self.count) / mean

    @property
    def effective_samples(self) -> float:
        """Kish's (sum w)^2 / sum w^2."""
        return self.w * self.w / self.w2 if self.w2 > 0 else 0.0

    @property
    def pareto_k(self) -> float:
        return pareto_k_of_tail(self.tail, self.count)


class WeightedPoseSums(LogWeightSums):
    """Also the self-normalised weighted mean and std of values (N, d), with standard errors.

    With normalised weights v_i = w_i / sum w and e = x - mean:
    se(mean)^2 = sum v_i^2 e_i^2; for the variance s^2 = sum v_i e_i^2,
    se(s^2)^2 = sum v_i^2 (e_i^2 - s^2)^2 and se(s) = se(s^2) / (2 s) (the
    delta method for self-normalised importance sampling; with equal weights,
    the iid formulas s / sqrt(N) and sqrt((m4 - s^4) / N) / (2 s)). The sums
    are of powers of x - c about a centre c from the first chunk (the circular
    mean for angles), so nothing cancels and angles do not wrap.
    """

    def __init__(self, expected: int, angular: np.ndarray):
        super().__init__(expected)
        self.angular = np.asarray(angular, dtype=bool)
        width = len(self.angular)
        self.centre: np.ndarray | None = None
        self.first = np.zeros(width)  # sum w d
        self.second = np.zeros(width)  # sum w d^2
        self.squared = np.zeros((5, width))  # sum w^2 d^p, p = 0..4

    def _rescale(self, peak: float) -> float:
        shrink = super()._rescale(peak)
        self.first *= shrink
        self.second *= shrink
        self.squared *= shrink * shrink
        return shrink

    def add_values(self, log_weights: np.ndarray, values: np.ndarray) -> None:
        if self.centre is None:
            self.centre = values.mean(axis=0)
            angles = values[:, self.angular]
            self.centre[self.angular] = np.arctan2(np.sin(angles).mean(axis=0), np.cos(angles).mean(axis=0))
        weights = self.add(log_weights)
        if weights is None:
            return
        width, count = len(self.centre), len(values)
        # powers[p] = d^p, d = values - centre as rows (width, N): every sum below is then one
        # product over contiguous rows
        powers = np.empty((5, width, count))
        powers[0] = 1.0
        d = powers[1]
        np.subtract(values.T, self.centre[:, None], out=d)
        d[self.angular] = wrap_angle(d[self.angular])
        np.multiply(d, d, out=powers[2])
        np.multiply(powers[2], d, out=powers[3])
        np.multiply(powers[2], powers[2], out=powers[4])
        first_and_second = weighted_row_sums(powers[1:3].reshape(2 * width, count), weights)
        self.first += first_and_second[:width]
        self.second += first_and_second[width:]
        self.squared += weighted_row_sums(powers.reshape(5 * width, count), weights * weights).reshape(5, width)

    def moments(self) -> dict[str, np.ndarray] | None:
        """mean, std, mean_se, std_se of each column; None when every weight is 0."""
        if self.w <= 0.0:
            return None
        a = self.first / self.w  # the mean of d
        variance = np.maximum(self.second / self.w - a * a, 0.0)
        S = self.squared / (self.w * self.w)  # S[p] = sum v^2 d^p
        # sum v^2 (d - a)^2 and sum v^2 (d - a)^4, expanded in the powers of d.
        e2 = np.maximum(S[2] - 2 * a * S[1] + a * a * S[0], 0.0)
        e4 = S[4] - 4 * a * S[3] + 6 * a**2 * S[2] - 4 * a**3 * S[1] + a**4 * S[0]
        spread = np.maximum(e4 - 2 * variance * e2 + variance**2 * S[0], 0.0)
        std = np.sqrt(variance)
        mean = a + self.centre
        mean[self.angular] = wrap_angle(mean[self.angular])
        std_se = np.where(std > 0, np.sqrt(spread) / np.where(std > 0, 2 * std, 1.0), 0.0)
        return {"mean": mean, "std": std, "mean_se": np.sqrt(e2), "std_se": std_se}
