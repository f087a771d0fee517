"""`--confine DIR` (and BCAD_CONFINE, and bcad.confined): a run reads files only from DIR, links
resolved, and refuses xacro files, on every path a problem or an option can name."""

from __future__ import annotations

import json
import os
import shutil
import textwrap

import pytest
from test_inputs_protected import ONE_JOINT_URDF
from typer.testing import CliRunner

import bcad
from bcad.batch import plan_tasks
from bcad.cli import app
from bcad.model.source import CONFINE_VARIABLE, check_confined

from conftest import ONE_LINK_GRAPH, REPO, run_bcad

runner = CliRunner()


@pytest.fixture
def jail(tmp_path):
    folder = tmp_path / "jail"
    folder.mkdir()
    (tmp_path / "outside.urdf").write_text(ONE_JOINT_URDF)
    (folder / "one.urdf").write_text(ONE_JOINT_URDF)
    return folder


def _problem(folder, urdf: str, extra: str = "", name: str = "problem.yaml"):
    path = folder / name
    path.write_text(
        textwrap.dedent(ONE_LINK_GRAPH).lstrip("\n")
        + f"robots:\n  - {{name: r, urdf: {urdf}, parent: a}}\n"
        + "solver: {search_starts: 2, posterior_samples: 2000}\n"
        + extra
    )
    return path


def test_a_problem_inside_reads_a_robot_inside(jail):
    problem = _problem(jail, "one.urdf")
    assert runner.invoke(app, ["--confine", str(jail), "validate", str(problem)]).exit_code == 0


@pytest.mark.parametrize("urdf", ["../outside.urdf", "link.urdf"])
def test_a_robot_outside_or_linked_outside_is_refused(jail, urdf):
    (jail / "link.urdf").symlink_to(jail.parent / "outside.urdf")
    problem = _problem(jail, urdf)
    assert runner.invoke(app, ["validate", str(problem)]).exit_code == 0  # unconfined: read
    result = runner.invoke(app, ["--confine", str(jail), "validate", str(problem)])
    assert result.exit_code == 2 and "is outside" in result.output and "the folder this run may read" in result.output


def test_a_xacro_file_is_refused_even_inside(jail):
    (jail / "arm.urdf.xacro").write_text(ONE_JOINT_URDF)
    problem = _problem(jail, "arm.urdf.xacro")
    result = runner.invoke(app, ["--confine", str(jail), "validate", str(problem)])
    assert result.exit_code == 2 and "a xacro file, which a confined run refuses" in result.output, result.output


def test_results_and_calibrations_outside_are_refused(jail):
    problem = _problem(jail, "one.urdf")
    outside = jail.parent / "result.json"
    outside.write_text(json.dumps({"solution": {"unknown.tx": 2.0}}))
    result = runner.invoke(app, ["--confine", str(jail), "posterior", str(problem), "--at", str(outside)])
    assert result.exit_code == 2 and "is outside" in result.output
    calibration = jail.parent / "calibration.json"
    calibration.write_text(json.dumps({"parameters": {"free.tx": {"map": 0.0, "laplace_std": 0.3}}}))
    result = runner.invoke(
        app, ["--confine", str(jail), "solve", str(problem), "--quiet", "--calibration", str(calibration)]
    )
    assert result.exit_code == 2 and "is outside" in result.output


def test_measurement_data_linked_outside_is_refused(jail):
    source = REPO / "problems" / "calibration"
    shutil.copy(source / "ur5_tracker.yaml", jail / "tracker.yaml")  # a DH robot: no URDF
    shutil.copy(source / "ur5_tracker.csv", jail.parent / "tracker.csv")
    (jail / "ur5_tracker.csv").symlink_to(jail.parent / "tracker.csv")
    result = runner.invoke(app, ["--confine", str(jail), "calibrate", str(jail / "tracker.yaml"), "--quiet"])
    assert result.exit_code == 2 and "ur5_tracker.csv: is outside" in result.output, result.output


def test_batch_confines_each_task_and_carries_the_folder_to_its_workers(jail):
    inside = _problem(jail, "one.urdf", name="inside.yaml")
    outside = _problem(jail.parent, "outside.urdf", name="outside.yaml")
    result = runner.invoke(
        app,
        [
            "--confine",
            str(jail),
            "batch",
            str(inside),
            str(outside),
            "--out",
            str(jail.parent / "out"),
            "--quiet",
            "--jobs",
            "1",
        ],
    )
    lines = {
        json.loads(line)["file"]: json.loads(line)
        for line in (jail.parent / "out" / "summary.jsonl").read_text().splitlines()
    }
    assert result.exit_code == 1 and lines["inside.yaml"]["status"] == "ok"
    assert (
        lines["outside.yaml"]["error"]["type"] == "invalid_input"
        and "is outside" in lines["outside.yaml"]["error"]["message"]
    )
    with bcad.confined(jail):  # a Dask worker has none of this process's environment: the task says it
        tasks = plan_tasks([inside], jail.parent / "out", 0, [])
    assert tasks[0].confine == os.path.realpath(jail)


def test_the_api_and_the_environment_variable_confine_too(jail):
    outside = _problem(jail.parent, "outside.urdf", name="outside.yaml")
    with bcad.confined(jail), pytest.raises(bcad.InputError, match="is outside"):
        bcad.load(outside)
    assert bcad.load(outside).name == "one-link"  # the block ended: unconfined again
    run = run_bcad("validate", outside, env_extra={CONFINE_VARIABLE: str(jail)})
    assert run.returncode == 2 and "is outside" in run.stderr
    with bcad.confined(jail):
        with pytest.raises(bcad.InputError, match="a mesh must lie there"):
            check_confined(jail.parent / "part.stl", "a mesh")
        check_confined(jail / "part.stl", "a mesh")


def test_a_confined_command_leaves_the_process_unconfined(jail):
    outside = _problem(jail.parent, "outside.urdf", name="outside.yaml")
    assert runner.invoke(app, ["--confine", str(jail), "validate", str(outside)]).exit_code == 2
    assert runner.invoke(app, ["validate", str(outside)]).exit_code == 0


def test_confine_needs_a_folder(tmp_path):
    result = runner.invoke(app, ["--confine", str(tmp_path / "missing"), "validate", str(tmp_path / "p.yaml")])
    assert result.exit_code == 2 and "is not a folder" in " ".join(result.output.replace("│", " ").split())
