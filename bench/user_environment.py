"""The environment in which the benchmarks time bcad's commands: a user's fresh shell.

A development environment may set PYTHONDONTWRITEBYTECODE=1 for its tools; a user's shell
usually does not, so Python writes bcad's bytecode at the first run (pip does it at install for a
non-editable install) and reads it from then on. Timed with the variable set and no cache, every
command compiled bcad's sources again: ``bcad calibrate`` on the 50-measurement full-DH cell took
0.63 s instead of 0.53 s (medians of 9, run alternately). The benchmarks therefore run commands
without the variable, after :func:`warm_bytecode` has written the cache, as a user's second run
finds it.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "bcad"


def user_environment() -> dict[str, str]:
    """This process's environment without PYTHONDONTWRITEBYTECODE."""
    return {name: value for name, value in os.environ.items() if name != "PYTHONDONTWRITEBYTECODE"}


def warm_bytecode() -> None:
    """Write bcad's bytecode cache, as a user's first run (or pip's install) does."""
    subprocess.run(
        [sys.executable, "-m", "compileall", "-q", str(PACKAGE)],
        env=user_environment(),
        check=True,
        capture_output=True,
    )
