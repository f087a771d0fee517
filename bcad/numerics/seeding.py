"""Named random streams derived from one seed.

Each use of randomness (the GA, the refinement, the posterior, ...) gets its
own stream, derived from ``--seed`` and the stream's name only, so that adding
a draw in one place never shifts the numbers of another, and ``bcad posterior
--seed S`` reproduces the posterior that ``bcad solve --seed S`` reported.
"""

from __future__ import annotations

import zlib

import numpy as np


def stream(seed: int, name: str) -> np.random.Generator:
    """A generator determined by ``seed`` and ``name``."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(zlib.crc32(name.encode()),)))
