"""Single-threaded BLAS, and one core, for batch worker processes.

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
#: "1": this process keeps to one core (no second process for a solve's independent parts:
#: :mod:`bcad.parallel`); set for batch workers, which already keep every core busy
SINGLE_CORE_VARIABLE = "BCAD_SINGLE_CORE"


@contextmanager
def single_threaded_environment() -> Iterator[None]:
    """Single-threaded BLAS and one core each for the processes started inside the block (Dask's
    nanny does the same for BLAS, and its workers are daemons, which :mod:`bcad.parallel` does
    not fork from); the environment is restored afterwards."""
    names = (*THREAD_VARIABLES, SINGLE_CORE_VARIABLE)
    saved = {name: os.environ.get(name) for name in names}
    for name in names:
        os.environ.setdefault(name, "1")
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
