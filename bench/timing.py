"""Timing shared by the benchmarks that time work inside their own process."""

from __future__ import annotations

import time
from collections.abc import Callable


def as_the_command_line() -> None:
    """Run this process's timed work as the ``bcad`` command runs its own: the allocator tuned
    (:func:`bcad.runtime.tune_allocator`) and BLAS kept to one thread, each library unless its
    variable is set (bcad/cli.py sets the variables before numpy loads; here numpy is loaded, so
    threadpoolctl limits the pool, as :func:`bcad.worker_env.one_blas_thread` does for the Python
    API). With OpenBLAS's default pool on a 2-core machine the RX90 chain drawn and evaluated from
    scratch for 1e5 samples took 2.5 times as long (519 ms against 206 ms, another process busy
    on one core): a figure printed as a command's lower bound was no bound."""
    import os

    import threadpoolctl

    from bcad.runtime import tune_allocator
    from bcad.worker_env import BLAS_VARIABLES

    tune_allocator()
    libraries = [library for library, variable in BLAS_VARIABLES.items() if variable not in os.environ]
    if libraries:
        threadpoolctl.ThreadpoolController().select(internal_api=libraries).limit(limits=1)


def best_of(function: Callable[[], object], repeats: int) -> float:
    """The best wall time of ``repeats`` calls of ``function``, s: the figure least disturbed by
    whatever else the machine does."""
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        best = min(best, time.perf_counter() - start)
    return best
