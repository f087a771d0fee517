"""Space-filling designs of starting points.

A Halton sequence (radical inverses in the first d prime bases) fills the unit cube far more
evenly than uniform draws: its discrepancy falls like (log n)^d / n, not 1 / sqrt(n). A random
shift modulo 1 (Cranley-Patterson rotation, drawn from a seeded stream) makes each seed's design
a different, equally even one. (scipy.stats.qmc's Sobol would do; importing scipy.stats costs
a large share of the command's start-up.)
"""

from __future__ import annotations

import numpy as np

#: designs of at most this many dimensions (the bases: the first 64 primes)
MAX_DIMENSION = 64


def _primes(count: int) -> list[int]:
    primes: list[int] = []
    candidate = 2
    while len(primes) < count:
        if all(candidate % p for p in primes if p * p <= candidate):
            primes.append(candidate)
        candidate += 1
    return primes


def radical_inverse(indices: np.ndarray, base: int) -> np.ndarray:
    """The base-``base`` radical inverse of each index: its digits mirrored about the point."""
    result = np.zeros(len(indices))
    factor = 1.0 / base
    remaining = indices.astype(np.int64).copy()
    while np.any(remaining > 0):
        remaining, digit = np.divmod(remaining, base)
        result += digit * factor
        factor /= base
    return result


def halton(count: int, dimension: int, rng: np.random.Generator | None = None) -> np.ndarray:
    """``count`` points of the ``dimension``-cube [0, 1)^d, shape (count, dimension): Halton's
    sequence from index 1, shifted modulo 1 by a uniform vector drawn from ``rng`` (if given).
    Beyond MAX_DIMENSION dimensions, uniform draws (Halton's high bases correlate)."""
    if dimension > MAX_DIMENSION:
        generator = rng if rng is not None else np.random.default_rng(0)
        return generator.random((count, dimension))
    indices = np.arange(1, count + 1)
    points = (
        np.column_stack([radical_inverse(indices, base) for base in _primes(dimension)])
        if dimension
        else np.zeros((count, 0))
    )
    if rng is not None:
        points = (points + rng.random(dimension)) % 1.0
    return points
