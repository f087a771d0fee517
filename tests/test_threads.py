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
import sys
import numpy, bcad
from threadpoolctl import threadpool_info, threadpool_limits

def blas():
    return max(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")

threadpool_limits(limits=2, user_api="blas")  # a pool of two, as on any machine of two cores or more
before, seen = blas(), []
bcad.solve(sys.argv[1], progress=lambda *_: seen.append(blas()))
print(before, min(seen), max(seen), blas())
"""


def _api_run(environment: dict[str, str]) -> list[str]:
    problem = str(Path(__file__).parents[1] / "problems" / "studies" / "planar_2r.yaml")
    return subprocess.run(
        [sys.executable, "-c", API_PROBE, problem], capture_output=True, text=True, env=environment, check=True
    ).stdout.split()


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="BLAS's pool is one thread on one core")
def test_the_api_runs_on_one_blas_thread_and_gives_the_pool_back():
    environment = {key: value for key, value in os.environ.items() if key not in THREAD_VARIABLES}
    assert _api_run(environment) == ["2", "1", "1", "2"]


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="BLAS's pool is one thread on one core")
def test_the_api_keeps_a_users_blas_setting():
    environment = {key: value for key, value in os.environ.items() if key not in THREAD_VARIABLES}
    environment["OPENBLAS_NUM_THREADS"] = "2"
    assert _api_run(environment) == ["2", "2", "2", "2"]
