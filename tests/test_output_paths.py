"""`-o` and `bcad batch --out` never lose data: no input replaced, devices and FIFOs written
into (a FIFO without a reader refused at once), a symbolic link replaced and never the file it
points to, only bcad's own temporary files removed, bad paths refused before any work."""

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


def test_a_symbolic_link_is_replaced_never_what_it_points_to(tmp_path):
    target = tmp_path / "elsewhere" / "precious.txt"
    target.parent.mkdir()
    target.write_text("old")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    write_json_atomic(DOCUMENT, link)
    assert not link.is_symlink() and json.loads(link.read_text()) == DOCUMENT
    assert target.read_text() == "old"


def test_a_dangling_link_is_replaced_not_followed(tmp_path):
    link = tmp_path / "out.json"
    link.symlink_to(tmp_path / "nowhere" / "made.json")
    write_json_atomic(DOCUMENT, link)
    assert not link.is_symlink() and json.loads(link.read_text()) == DOCUMENT
    assert not (tmp_path / "nowhere").exists()


def test_a_fifo_without_a_reader_is_refused_after_a_bounded_wait(tmp_path, monkeypatch):
    import bcad.io

    monkeypatch.setattr(bcad.io, "FIFO_READER_WAIT", 0.2)
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="no process read within 0.2 s"):
        write_json_atomic(DOCUMENT, fifo)
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)


def test_samples_out_through_a_link_and_onto_a_lone_fifo(tmp_path, monkeypatch):
    import bcad.io

    monkeypatch.setattr(bcad.io, "FIFO_READER_WAIT", 0.2)
    problem = tmp_path / "problem.yaml"
    problem.write_text(ONE_LINK_GRAPH)
    target = tmp_path / "precious.txt"
    target.write_text("old")
    link = tmp_path / "samples.npz"
    link.symlink_to(target)
    result = runner.invoke(
        app, ["solve", str(problem), "--quiet", "--samples-out", str(link), "-o", str(tmp_path / "r.json")]
    )
    assert result.exit_code in (0, 3), result.output
    assert target.read_text() == "old" and not link.is_symlink() and link.read_bytes()[:2] == b"PK"
    fifo = tmp_path / "pipe.npz"
    os.mkfifo(fifo)
    result = runner.invoke(
        app, ["solve", str(problem), "--quiet", "--samples-out", str(fifo), "-o", str(tmp_path / "r.json")]
    )
    assert result.exit_code == 2 and "no process read within" in result.output


def test_batch_replaces_a_summary_link_and_keeps_the_users_files(tmp_path):
    problem = tmp_path / "problems" / "one.yaml"
    problem.parent.mkdir()
    problem.write_text(ONE_LINK_GRAPH + "solver: {search_starts: 2, posterior_samples: 2000}\n")
    out = tmp_path / "out"
    out.mkdir()
    outside = tmp_path / "outside.txt"
    outside.write_text("keep me")
    (out / "summary.jsonl").symlink_to(outside)
    notes = [out / ".notes.2023.tmp", out / ".one.json.99999999.tmp", out / ".x.bcad-99999999.tmp"]
    for note in notes:
        note.write_text("mine")
    stale = out / ".one.json.bcad-99999999.tmp"  # a writer of bcad's that was killed (no such process)
    stale.write_text("{")
    result = runner.invoke(app, ["batch", str(problem), "--out", str(out), "--quiet", "--jobs", "1"])
    assert result.exit_code in (0, 3), result.output
    assert outside.read_text() == "keep me"
    assert (
        not (out / "summary.jsonl").is_symlink()
        and json.loads((out / "summary.jsonl").read_text())["file"] == "one.yaml"
    )
    assert all(note.read_text() == "mine" for note in notes)
    assert not stale.exists()


def test_a_long_output_name_is_refused_before_solving(tmp_path):
    problem = tmp_path / "problem.yaml"
    problem.write_text(ONE_LINK_GRAPH)
    for option in ("-o", "--samples-out"):
        result = runner.invoke(app, ["solve", str(problem), "--quiet", option, str(tmp_path / ("r" * 300 + ".json"))])
        assert result.exit_code == 2 and "at most 200" in result.output, result.output


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
