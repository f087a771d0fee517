"""A task function for the pool-restart test: the first call of a given task kills its worker."""

from __future__ import annotations

import os
from pathlib import Path

from bcad.batch import run_task


def crash_once(task):
    marker = Path(task.output + ".crashed")
    if task.name.startswith("crash") and not marker.exists():
        marker.write_text("x")
        os._exit(9)  # the worker dies as under kill -9
    return run_task(task)
