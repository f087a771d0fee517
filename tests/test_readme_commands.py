"""Every benchmark command the README shows runs (issue 9: "every command in the README must be
run by a test"). The slow ones run with smaller arguments of the same script; the figures are
the benchmarks' business, here they must only run to the end and print them."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from conftest import REPO

README = (REPO / "README.md").read_text(encoding="utf-8")
COMMANDS = re.findall(r"^\$ (python bench/\S+\.py.*)$", README, re.M)
# Arguments that keep CI short; each script's logic runs the same.
SMALLER = {
    "bench/estimators.py": ["--seeds", "1", "--rescore", "2e4", "--reference", "1e6"],
    "bench/solve_rx90.py": ["--seeds", "1"],
    "bench/batch.py": ["--problems", "4"],
    "bench/kinematics.py": ["--loop-samples", "2e3", "--repeats", "2"],
    "bench/maxerror_table.py": ["--starts", "2"],
}


def test_the_readme_shows_the_benchmarks():
    assert {command.split()[1] for command in COMMANDS} == set(SMALLER)


@pytest.mark.parametrize("command", COMMANDS)
def test_readme_benchmark_runs(command):
    script = command.split()[1]
    run = subprocess.run([sys.executable, script, *SMALLER[script]], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.strip(), "a benchmark prints its figures"
