"""Every benchmark command the documentation shows runs ("every command in the README and the
documentation must be run by a test"). The slow ones run with smaller arguments of the same script; the figures are
the benchmarks' business, here they must only run to the end and print them."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from conftest import REPO, documentation

COMMANDS = re.findall(r"^\$ (python bench/\S+\.py.*)$", documentation(), re.M)
DESIGN_STUDY = (REPO / "docs" / "tutorials" / "design_study.md").read_text(encoding="utf-8")
# Arguments that keep CI short; each script's logic runs the same.
SMALLER = {
    "bench/estimators.py": ["--seeds", "1", "--rescore", "2e4", "--reference", "1e6"],
    "bench/solve_rx90.py": ["--seeds", "1"],
    "bench/batch.py": ["--problems", "4"],
    "bench/kinematics.py": ["--loop-samples", "2e3", "--repeats", "2"],
    "bench/linearise.py": ["--repeats", "1"],
    "bench/standin.py": ["--repeats", "1", "--count", "50"],
    "bench/maxerror_table.py": ["--starts", "2"],
    "bench/calibrate.py": ["--repeats", "1"],
    "bench/global_search.py": ["--seeds", "1", "--skip-reference", "--problem", "uniform_pull", "--rescore", "2e4"],
    "bench/random_cells.py": [
        "--kinds",
        "linear_non_gaussian",
        "dh_face",
        "--seeds",
        "1",
        "--skip-reference",
        "--rescore",
        "2e4",
        "--draw",
        "1",
        "--efforts",
        "0.5",
    ],
    "bench/commands.py": ["--repeats", "1", "--samples", "2e4"],
    "bench/cameras.py": ["--seeds", "2", "--views", "5", "--noise", "0.5", "--robot", "exact"],
    "bench/maxerror_exact.py": [
        "--starts",
        "1",
        "--random",
        "1",
        "--yield-samples",
        "2e4",
        "--scales",
        "1",
        "--repeats",
        "1",
    ],
}


def test_the_readme_shows_the_benchmarks():
    assert {command.split()[1] for command in COMMANDS} == set(SMALLER)


@pytest.mark.parametrize("command", COMMANDS)
def test_readme_benchmark_runs(command):
    script = command.split()[1]
    run = subprocess.run(
        [sys.executable, script, *SMALLER[script]], cwd=REPO, capture_output=True, text=True, timeout=300
    )
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.strip(), "a benchmark prints its figures"


def test_readme_dask_cluster_commands_run_on_loopback(tmp_path):
    """The design-study tutorial's three cluster commands (scheduler, worker, batch on it), on 127.0.0.1 with a
    free port instead of HEAD:8786, one worker instead of four, and the example problems."""
    pytest.importorskip("dask.distributed")
    import socket
    import time

    lines = [
        line.split("#")[0].strip()
        for line in DESIGN_STUDY.splitlines()
        if line.startswith(("dask ", "bcad batch problems/*.yaml"))
    ]
    assert lines == [
        "dask scheduler",
        "dask worker tcp://HEAD:8786 --nthreads 1 --nworkers 4",
        "bcad batch problems/*.yaml --out results --scheduler tcp://HEAD:8786",
    ]
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    scheduler = subprocess.Popen(
        ["dask", "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    worker = None
    try:
        time.sleep(2)
        worker = subprocess.Popen(
            ["dask", "worker", address, "--nthreads", "1", "--nworkers", "1", "--no-dashboard"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            cwd=REPO,
        )
        problems = sorted(str(path) for path in (REPO / "problems").glob("*.yaml"))
        run = subprocess.run(
            [
                sys.executable,
                "-m",
                "bcad.cli",
                "batch",
                *problems,
                "--out",
                str(tmp_path / "results"),
                "--scheduler",
                address,
                "--quiet",
            ],
            cwd=REPO,
            capture_output=True,
            text=True,
            timeout=240,
        )
        assert run.returncode == 0, run.stderr[-2000:]
        assert len((tmp_path / "results" / "summary.jsonl").read_text().splitlines()) == len(problems)
    finally:
        for process in (worker, scheduler):
            if process is not None:
                process.terminate()
                try:
                    process.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    process.kill()
