"""What a file or a flag can ask for is bounded: thousands of X are refused up front,
thousands of L and frames are streamed in bounded chunks, the calibration check and --propose
have a work budget, and the caches that make the hot loop fast stop growing at CACHE_BYTES
without changing a number."""

from __future__ import annotations

import csv
import json
import shutil

import numpy as np
import pytest
from typer.testing import CliRunner

from bcad.cli import app

from conftest import REPO

runner = CliRunner()


def _chain_problem(path, count: int, status: str = "XLFFFF") -> None:
    """``count`` links in a row, each with an X tx and an L ty, closed by one link."""
    lines = ["name: chain", "frames: [" + ", ".join(f"f{i}" for i in range(count + 1)) + "]", "links:"]
    for i in range(1, count + 1):
        lines.append(
            f"  - {{name: k{i}, parent: f{i - 1}, child: f{i}, status: {status}, bounds: {{tx: [-1, 1]}}, "
            "distributions: {ty: 'normal(0, 0.001)'}}"
        )
    lines.append(
        f"  - {{name: u, parent: f0, child: f{count}, pose: [3, 0, 0, 0, 0, 0], status: LLFFFF, close: true, "
        "distributions: {tx: 'normal(0, 0.01)', ty: 'normal(0, 0.01)'}}"
    )
    path.write_text("\n".join(lines) + "\n")


def test_thousands_of_unknowns_are_refused_up_front(tmp_path):
    from bcad.bayes.solvable import MAX_UNKNOWNS

    problem = tmp_path / "many.yaml"
    _chain_problem(problem, 2000)
    result = runner.invoke(app, ["solve", str(problem), "--quiet"])
    assert result.exit_code == 2, result.output
    assert f"2000 unknown parameters (X); the search handles at most {MAX_UNKNOWNS}" in result.output
    assert runner.invoke(app, ["validate", str(problem)]).exit_code == 0  # the problem itself is fine


def test_posterior_chunks_shrink_with_many_free_parameters():
    from bcad.bayes.sampling import CHUNK_VALUES, chunk_rows

    assert chunk_rows(30, 1 << 16) == 1 << 16
    assert chunk_rows(3000, 1 << 16) * 3000 <= CHUNK_VALUES
    assert chunk_rows(10**7, 1 << 16) == 256


def test_a_full_cache_changes_no_number(monkeypatch):
    """The RX90 example's closing links on 40,000 samples (over BLOCK: evaluated in blocks), with
    every cache on and with none (CACHE_BYTES = 0): the same transforms to the last bit."""
    from bcad.compiler import compile_problem
    from bcad.kinematics import chain as chain_module
    from bcad.kinematics.chain import Samples
    from bcad.model import load_problem

    compiled = compile_problem(load_problem(REPO / "problems" / "rx90_face_on_face.yaml"))
    rng = np.random.default_rng(3)
    values = rng.normal(0.0, 0.01, size=(40_000, len(compiled.parameters.l)))
    x = rng.uniform(-0.5, 0.5, size=len(compiled.parameters.x))
    cached = [chain.evaluate(x, Samples(values)).matrices() for chain in compiled.cycle_chains]
    monkeypatch.setattr(chain_module, "CACHE_BYTES", 0)
    batch = Samples(values)
    uncached = [chain.evaluate(x, batch).matrices() for chain in compiled.cycle_chains]
    assert batch._cached_bytes == 0 and not batch._segments and not batch._trig
    for a, b in zip(cached, uncached):
        np.testing.assert_array_equal(a, b)


def test_a_picture_of_thousands_of_frames_draws_their_axes_not_their_names(tmp_path):
    pytest.importorskip("matplotlib")
    from bcad.compiler import compile_problem
    from bcad.model import load_problem
    from bcad.plot.arms import MAX_FRAME_LABELS, draw_arms

    problem = tmp_path / "frames.yaml"
    _chain_problem(problem, 600, status="FLFFFF")
    text = problem.read_text().replace("status: FLFFFF, bounds: {tx: [-1, 1]}, ", "status: FLFFFF, ")
    text = text.replace(
        "links:\n", "links:\n  - {name: place, parent: f0, child: g, status: XFFFFF, bounds: {tx: [-1, 1]}}\n", 1
    )
    problem.write_text(text.replace("frames: [f0,", "frames: [g, f0,"))
    compiled = compile_problem(load_problem(problem))
    figure, (drawing,) = draw_arms(compiled, [("start", np.zeros(1), {})], problem)
    assert len(drawing.frames) == 602 > MAX_FRAME_LABELS
    assert not any(label.startswith("f") for label in drawing.labels)  # no 602 names piled up
    # every frame's axes are drawn: three collections of 602 segments
    collections = [c for c in figure.axes[0].collections if len(getattr(c, "_segments3d", [])) == 602]
    assert len(collections) == 3


def _tracker_copy(folder, rows: int | None = None):
    for name in ("ur5_tracker.yaml", "ur5_tracker.csv"):
        shutil.copy(REPO / "problems" / "calibration" / name, folder)
    if rows is not None:
        table = list(csv.reader((folder / "ur5_tracker.csv").open()))
        body = [table[1 + i % (len(table) - 1)] for i in range(rows)]
        with (folder / "ur5_tracker.csv").open("w", newline="") as stream:
            csv.writer(stream).writerows([table[0], *body])
    return folder / "ur5_tracker.yaml"


@pytest.mark.parametrize("count", ["1", "99"])
def test_a_check_of_too_few_samples_to_judge_is_exit_2(count):
    """One sample gave Pareto k nan and "the posterior is far from Gaussian"."""
    problem = REPO / "problems" / "calibration" / "ur5_tracker.yaml"
    result = runner.invoke(app, ["calibrate", str(problem), "--quiet", "--check-samples", count])
    assert result.exit_code == 2 and f"--check-samples {count}: 0 (no check) or at least 100" in result.stderr


def test_an_explicit_check_over_its_budget_is_exit_2_and_auto_is_smaller(tmp_path, monkeypatch):
    from bcad.calibration import run as calibration_run

    problem = _tracker_copy(tmp_path, rows=12_000)  # 36,000 measured values: refused before any work
    result = runner.invoke(app, ["calibrate", str(problem), "--quiet", "--check-samples", "1e9"])
    assert result.exit_code == 2, result.output
    assert f"at most {calibration_run.CHECK_VALUES // 36_000:,} samples here" in result.output
    # The default check made smaller: on a tenth of the file with a tenth of the budget (the same
    # 833 samples, the calibration ten times shorter)
    monkeypatch.setattr(calibration_run, "CHECK_VALUES", calibration_run.CHECK_VALUES // 10)
    problem = _tracker_copy(tmp_path, rows=1_200)
    result = runner.invoke(app, ["calibrate", str(problem), "--quiet", "-o", str(tmp_path / "out.json")])
    assert result.exit_code in (0, 3), result.output
    assert json.loads((tmp_path / "out.json").read_text())["check"]["samples"] == 833


def test_propose_over_its_budget_is_exit_2(tmp_path, monkeypatch):
    from bcad.calibration import propose as propose_module

    problem = _tracker_copy(tmp_path)
    candidates = tmp_path / "candidates.csv"
    rng = np.random.default_rng(0)
    with candidates.open("w", newline="") as stream:
        writer = csv.writer(stream)
        writer.writerow([f"ur5/joint_{k}" for k in range(1, 7)])
        writer.writerows(np.round(rng.uniform(-3, 3, size=(40, 6)), 4).tolist())
    monkeypatch.setattr(propose_module, "PROPOSE_WORK", 400)  # 40 candidates: at most 10 picks
    result = runner.invoke(
        app,
        [
            "calibrate",
            str(problem),
            "--quiet",
            "--check-samples",
            "0",
            "--propose",
            "11",
            "--candidates",
            str(candidates),
        ],
    )
    assert result.exit_code == 2, result.output
    assert "at most 10 picks from this file" in result.output
    result = runner.invoke(
        app,
        [
            "calibrate",
            str(problem),
            "--quiet",
            "--check-samples",
            "0",
            "--propose",
            "10",
            "--candidates",
            str(candidates),
            "-o",
            str(tmp_path / "p.json"),
        ],
    )
    assert result.exit_code == 0, result.output
    assert len(json.loads((tmp_path / "p.json").read_text())["proposal"]["ranked"]) == 10
