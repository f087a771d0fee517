"""Single-threaded BLAS: for batch worker processes, and for the Python API's runs.

``bcad batch`` runs one worker process per core; if each also ran
OpenBLAS's thread pool, the cores would be oversubscribed (measured: the
pool's tasks took 1.8 times as long). The variables must be in a worker's
environment before it imports numpy, so they are set while the pool starts
its processes.

A program that calls the API has imported numpy already, with BLAS's default
thread pool: each run then keeps BLAS to one thread while it lasts
(:func:`one_blas_thread`), as the command line does from its start.
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


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """BLAS kept to one thread inside the block, unless the user set one of THREAD_VARIABLES (the
    command line sets them before numpy loads, so it never gets here): bcad's hot loops are many
    small (3 x 3) @ (3 x N) products and two threads of its own, beside which BLAS's pool only
    oversubscribes the cores. On a 2-core machine, ``bcad.posterior`` on the RX90 example took
    1.1 s with the pool and 0.55 s without, ``bcad.solve`` 10.9 s and 8.0 s, with the same
    results. The pool's size is restored when the block ends; processes forked inside it keep
    one thread."""
    if any(name in os.environ for name in THREAD_VARIABLES):
        yield
        return
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        yield
