"""Timing shared by the benchmarks that time work inside their own process."""

from __future__ import annotations

import time
from collections.abc import Callable


def best_of(function: Callable[[], object], repeats: int) -> float:
    """The best wall time of ``repeats`` calls of ``function``, s: the figure least disturbed by
    whatever else the machine does."""
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        best = min(best, time.perf_counter() - start)
    return best
