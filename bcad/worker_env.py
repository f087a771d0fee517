"""Single-threaded BLAS for batch worker processes.

``bcad batch`` runs one worker process per core; if each also ran
OpenBLAS's thread pool, the cores would be oversubscribed (measured: the
pool's tasks took 1.8 times as long). The variables must be in a worker's
environment before it imports numpy, so they are set while the pool starts
its processes.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


@contextmanager
def single_threaded_environment() -> Iterator[None]:
    """Single-threaded BLAS for the processes started inside the block (Dask's nanny
    does the same for its workers); the environment is restored afterwards."""
    saved = {name: os.environ.get(name) for name in THREAD_VARIABLES}
    for name in THREAD_VARIABLES:
        os.environ.setdefault(name, "1")
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
