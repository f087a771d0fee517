"""The command line sets its BLAS thread pools and pydantic's plugins itself, unless the user set them."""

from __future__ import annotations

import os
import subprocess
import sys

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
