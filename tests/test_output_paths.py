"""`-o` and `bcad batch --out` never lose data: no input replaced, devices and FIFOs written
into, symbolic links followed, bad paths refused before any work."""

from __future__ import annotations

import json
import os
import stat
import threading

import pytest
from typer.testing import CliRunner

from bcad.cli import app
from bcad.errors import InputError
from bcad.io import write_json_atomic

from conftest import ONE_LINK_GRAPH

runner = CliRunner()
DOCUMENT = {"answer": 42}


def test_a_fifo_is_written_into_not_replaced(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    received = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_text()))
    reader.start()
    write_json_atomic(DOCUMENT, fifo)
    reader.join(timeout=10)
    assert json.loads(received[0]) == DOCUMENT
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)


def test_a_symbolic_link_is_followed(tmp_path):
    target = tmp_path / "real.json"
    target.write_text("old")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    write_json_atomic(DOCUMENT, link)
    assert link.is_symlink() and json.loads(target.read_text()) == DOCUMENT


def test_an_input_is_never_replaced_even_through_a_link(tmp_path):
    problem = tmp_path / "problem.yaml"
    problem.write_text("name: x\n")
    link = tmp_path / "out.json"
    link.symlink_to(problem)
    for output in (problem, link):
        with pytest.raises(InputError, match="input file"):
            write_json_atomic(DOCUMENT, output, problem)
    assert problem.read_text() == "name: x\n"


@pytest.mark.parametrize("name", ["", "missing/result.json", "a_folder"])
def test_bad_outputs_are_refused_before_solving(tmp_path, name):
    (tmp_path / "a_folder").mkdir()
    problem = tmp_path / "problem.yaml"
    problem.write_text(ONE_LINK_GRAPH)
    result = runner.invoke(app, ["solve", str(problem), "--quiet", "-o", str(tmp_path / name) if name else ""])
    assert result.exit_code == 2
    assert "Traceback" not in result.output


def test_batch_refuses_to_write_over_a_problem_written_as_json(tmp_path):
    problem = tmp_path / "study.json"
    problem.write_text(json.dumps({"name": "x", "frames": ["a"]}))
    before = problem.read_text()
    result = runner.invoke(app, ["batch", str(problem), "--out", str(tmp_path), "--quiet"])
    assert result.exit_code == 2
    assert "input files" in result.output
    assert problem.read_text() == before
