"""The command line sets its BLAS thread pools and pydantic's plugins itself, unless the user set them."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from bcad.worker_env import THREAD_VARIABLES

PROBE = "import bcad.cli, numpy, os; print(os.environ.get('OPENBLAS_NUM_THREADS'), os.environ.get('OMP_NUM_THREADS'))"


def _run(environment: dict[str, str], probe: str = PROBE) -> list[str]:
    return subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, env=environment, check=True
    ).stdout.split()


def test_one_blas_thread_by_default():
    environment = {key: value for key, value in os.environ.items() if key not in THREAD_VARIABLES}
    assert _run(environment) == ["1", "1"]


def test_a_users_setting_is_kept():
    environment = {key: value for key, value in os.environ.items() if key not in THREAD_VARIABLES}
    environment["OPENBLAS_NUM_THREADS"] = "3"
    assert _run(environment) == ["3", "1"]


PLUGINS_PROBE = "import bcad.cli, os; print(os.environ.get('PYDANTIC_DISABLE_PLUGINS'))"


def test_no_pydantic_plugins_are_looked_for_unless_the_user_names_them():
    environment = {key: value for key, value in os.environ.items() if key != "PYDANTIC_DISABLE_PLUGINS"}
    assert _run(environment, PLUGINS_PROBE) == ["__all__"]
    environment["PYDANTIC_DISABLE_PLUGINS"] = "logfire"
    assert _run(environment, PLUGINS_PROBE) == ["logfire"]
    del environment["PYDANTIC_DISABLE_PLUGINS"]  # the library leaves a program's plugins alone
    library = "import bcad, bcad.api, os; print(os.environ.get('PYDANTIC_DISABLE_PLUGINS'))"
    assert _run(environment, library) == ["None"]


# The Python API: a program has loaded numpy with BLAS's default pool; each run keeps BLAS to one
# thread while it lasts and gives the pool back, unless the user set the thread variables.
API_PROBE = """
import sys, threading
import numpy, bcad
import bcad.bayes.run, bcad.worstcase.run, bcad.calibration.run
from threadpoolctl import threadpool_info, threadpool_limits
from bcad.worker_env import one_blas_thread

def blas():
    return max(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")

seen = []
def spy(module, name):  # the pool as each family's run starts
    inner = getattr(module, name)
    def run(*args, **kwargs):
        seen.append(blas())
        return inner(*args, **kwargs)
    setattr(module, name, run)

spy(bcad.bayes.run, "solve_run")
spy(bcad.bayes.run, "posterior_run")
spy(bcad.worstcase.run, "maxerror_with")
spy(bcad.calibration.run, "calibration_run")
threadpool_limits(limits=2, user_api="blas")  # a pool of two, as on any machine of two cores or more
before = blas()
planar, clearance, tracker = sys.argv[1:4]
solved = bcad.solve(planar, samples=2000)
bcad.posterior(planar, at=solved, samples=2000)
bcad.maxerror(clearance)
bcad.calibrate(tracker, check_samples=200)
# two runs overlapping in two threads: one thread each, the pool given back when the last ends
inside, entered, overlap = [], threading.Event(), threading.Event()
def first():
    with one_blas_thread():
        inside.append(blas()); entered.set(); overlap.wait()
def second():
    entered.wait()
    with one_blas_thread():
        overlap.set(); inside.append(blas())
threads = [threading.Thread(target=first), threading.Thread(target=second)]
for thread in threads:
    thread.start()
for thread in threads:
    thread.join()
print(before, *seen, *inside, blas())
"""


def _api_run(environment: dict[str, str]) -> list[str]:
    problems = Path(__file__).parents[1] / "problems"
    files = [problems / "studies" / "planar_2r.yaml", problems / "clearance" / "2r.yaml"]
    files.append(problems / "calibration" / "ur5_tracker.yaml")
    return subprocess.run(
        [sys.executable, "-c", API_PROBE, *map(str, files)],
        capture_output=True,
        text=True,
        env=environment,
        check=True,
    ).stdout.split()


def _without_thread_variables() -> dict[str, str]:
    return {key: value for key, value in os.environ.items() if key not in THREAD_VARIABLES}


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="BLAS's pool is one thread on one core")
def test_every_api_run_is_on_one_blas_thread_and_gives_the_pool_back():
    # before; solve, posterior, maxerror, calibrate; two overlapping runs; after
    assert _api_run(_without_thread_variables()) == ["2", "1", "1", "1", "1", "1", "1", "2"]


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="BLAS's pool is one thread on one core")
def test_the_api_keeps_a_users_blas_setting():
    environment = _without_thread_variables()
    environment["OPENBLAS_NUM_THREADS"] = "2"
    assert _api_run(environment) == ["2"] * 8
    # OpenBLAS reads its own variable first: OMP_NUM_THREADS alone leaves it to bcad, as the command
    # line does (which sets OPENBLAS_NUM_THREADS where the user did not)
    environment = _without_thread_variables()
    environment["OMP_NUM_THREADS"] = "2"
    assert _api_run(environment) == ["2", "1", "1", "1", "1", "1", "1", "2"]
