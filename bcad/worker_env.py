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
import threading
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


#: each BLAS library threadpoolctl knows, and the variable by which a user sets its threads (the
#: command line sets all three, and OpenBLAS reads its own before OMP_NUM_THREADS)
BLAS_VARIABLES = {
    "openblas": "OPENBLAS_NUM_THREADS",
    "mkl": "MKL_NUM_THREADS",
    "blis": "OMP_NUM_THREADS",
    "flexiblas": "OMP_NUM_THREADS",
}
_runs_lock = threading.Lock()
_runs = 0  # API runs in progress in this process
_limiter = None  # their limit, made by the first and undone by the last


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """BLAS kept to one thread inside the block, each library unless the user set its variable
    (BLAS_VARIABLES; the command line sets them all before numpy loads, so it limits nothing
    here): bcad's hot loops are many small (3 x 3) @ (3 x N) products and two threads of its
    own, beside which BLAS's pool only oversubscribes the cores (docs/performance.md gives the
    figures). The limit is the process's, as BLAS's pool is: runs that overlap in several
    threads share it, the first sets it and the last gives the pool back; processes forked
    inside it keep one thread."""
    global _runs, _limiter
    libraries = [library for library, variable in BLAS_VARIABLES.items() if variable not in os.environ]
    if not libraries:
        yield
        return
    import threadpoolctl

    with _runs_lock:
        if _runs == 0:
            # entered and left as a context, so that threadpoolctl hands OpenBLAS's pool (which
            # one thread controls at a time) back to whichever thread runs next
            _limiter = threadpoolctl.ThreadpoolController().select(internal_api=libraries).limit(limits=1).__enter__()
        _runs += 1
    try:
        yield
    finally:
        with _runs_lock:
            _runs -= 1
            if _runs == 0:
                # threadpoolctl lets one thread at a time set OpenBLAS's shared pool (the first to
                # set it, while it lives); the run that entered first may have ended in another
                # thread that still lives, and no bcad run is left to use the limit
                openblas = getattr(threadpoolctl, "OpenBLASController", None)
                if hasattr(openblas, "clear_controlling_thread"):
                    openblas.clear_controlling_thread(force=True)
                _limiter.__exit__(None, None, None)
                _limiter = None
