"""Shared helpers: writing problem files and running the CLI."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
RX90_URDF = REPO / "robots" / "rx90.urdf"
RX90_EXAMPLE = REPO / "problems" / "rx90_face_on_face.yaml"


@pytest.fixture
def write_problem(tmp_path):
    """Write a (dedented) YAML problem into the test's folder and return its path."""

    def write(text: str, name: str = "problem.yaml") -> Path:
        path = tmp_path / name
        path.write_text(textwrap.dedent(text).lstrip("\n"), encoding="utf-8")
        return path

    return write


def run_bcad(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """Run the real ``bcad`` entry point in a subprocess (exit code, stdout, stderr)."""
    return subprocess.run(
        [sys.executable, "-m", "bcad.cli", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
    )
