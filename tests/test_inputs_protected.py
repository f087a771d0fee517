"""No writer replaces a file the run read: plot, --urdf, --samples-out, -o and
batch refuse an output that reaches the problem's URDF, a xacro include, its measurement
CSV or a mesh, through a symbolic or a hard link, before or instead of writing; the input
stays byte for byte."""

from __future__ import annotations

import json
import os
import shutil
import textwrap

import pytest
from typer.testing import CliRunner

from bcad.cli import app

from conftest import ONE_LINK_GRAPH, REPO

runner = CliRunner()

ONE_JOINT_URDF = """<?xml version="1.0"?>
<robot name="one">
  <link name="base"/><link name="tip"/>
  <joint name="j" type="revolute"><parent link="base"/><child link="tip"/>
    <origin xyz="0 0 1" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
</robot>
"""


def _robot_problem(folder, urdf_name: str = "one.urdf") -> os.PathLike:
    """The closed-form one-link problem plus a one-joint robot read from ``urdf_name``."""
    problem = folder / "problem.yaml"
    problem.write_text(
        textwrap.dedent(ONE_LINK_GRAPH).lstrip("\n")
        + f"robots:\n  - {{name: r, urdf: {urdf_name}, parent: a}}\n"
        + "solver: {search_starts: 2, posterior_samples: 2000}\n"
    )
    return problem


def _calibration_copy(folder):
    """rx90_sphere_touches (URDF + measurement CSV) copied, so that a failure cannot touch the repository."""
    (folder / "robots").mkdir()
    (folder / "problems" / "calibration").mkdir(parents=True)
    shutil.copy(REPO / "robots" / "rx90.urdf", folder / "robots")
    for name in ("rx90_sphere_touches.yaml", "rx90_sphere_touches.csv"):
        shutil.copy(REPO / "problems" / "calibration" / name, folder / "problems" / "calibration")
    problem = folder / "problems" / "calibration" / "rx90_sphere_touches.yaml"
    return problem, folder / "robots" / "rx90.urdf", problem.with_suffix(".csv")


def _link(path, target, hard: bool):
    (os.link if hard else os.symlink)(target, path)
    return path


@pytest.mark.parametrize("hard", [False, True], ids=["symlink", "hardlink"])
@pytest.mark.parametrize("which", ["urdf", "csv"])
def test_plot_never_writes_over_the_urdf_or_the_measurements(tmp_path, which, hard):
    problem, urdf, csv = _calibration_copy(tmp_path)
    source = urdf if which == "urdf" else csv
    before = source.read_bytes()
    picture = _link(tmp_path / "picture.png", source, hard)
    result = runner.invoke(app, ["plot", str(problem), "--what", "graph", "-o", str(picture)])
    assert result.exit_code == 2, result.output
    assert "refusing to overwrite the input file" in result.output and source.name in result.output
    assert source.read_bytes() == before


def test_calibrate_urdf_and_output_never_write_over_the_measurements(tmp_path):
    problem, urdf, csv = _calibration_copy(tmp_path)
    before = {path: path.read_bytes() for path in (urdf, csv)}
    for option, target in (("--urdf", csv), ("-o", urdf)):
        link = _link(tmp_path / f"out{option}", target, hard=False)
        result = runner.invoke(app, ["calibrate", str(problem), "--check-samples", "0", "--quiet", option, str(link)])
        assert result.exit_code == 2, result.output
        assert "refusing to overwrite the input file" in result.output
    assert {path: path.read_bytes() for path in (urdf, csv)} == before


def test_samples_out_and_output_never_write_over_the_robot(tmp_path):
    (tmp_path / "one.urdf").write_text(ONE_JOINT_URDF)
    problem = _robot_problem(tmp_path)
    urdf = tmp_path / "one.urdf"
    for option in ("--samples-out", "-o"):
        link = _link(tmp_path / f"link{option}.npz", urdf, hard=False)
        result = runner.invoke(app, ["solve", str(problem), "--quiet", "--seed", "1", option, str(link)])
        assert result.exit_code == 2, result.output
        assert "refusing to overwrite the input file" in result.output and "one.urdf" in result.output
        assert urdf.read_text() == ONE_JOINT_URDF
    # The same command with a fresh path works: the refusal is about the link, not the option.
    result = runner.invoke(app, ["solve", str(problem), "--quiet", "--samples-out", str(tmp_path / "s.npz")])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "s.npz").stat().st_size > 0


def test_a_xacro_include_is_an_input_too(tmp_path):
    pytest.importorskip("xacrodoc")
    (tmp_path / "arm.xacro").write_text(
        '<?xml version="1.0"?>\n<robot name="one" xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
        '  <xacro:include filename="parts.xacro"/>\n  <xacro:parts/>\n</robot>\n'
    )
    parts = tmp_path / "parts.xacro"
    body = ONE_JOINT_URDF.split("\n", 2)[2].rsplit("</robot>", 1)[0]
    parts.write_text(
        '<?xml version="1.0"?>\n<robot xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
        f'<xacro:macro name="parts">{body}</xacro:macro>\n</robot>\n'
    )
    before = parts.read_text()
    problem = _robot_problem(tmp_path, "arm.xacro")
    assert runner.invoke(app, ["validate", str(problem)]).exit_code == 0  # the include is expanded
    link = _link(tmp_path / "picture.png", parts, hard=False)
    result = runner.invoke(app, ["plot", str(problem), "--what", "graph", "-o", str(link)])
    assert result.exit_code == 2, result.output
    assert "parts.xacro" in result.output and parts.read_text() == before


def test_batch_keeps_a_robot_that_a_result_path_links_to(tmp_path):
    (tmp_path / "one.urdf").write_text(ONE_JOINT_URDF)
    problem = _robot_problem(tmp_path)
    urdf = tmp_path / "one.urdf"
    out = tmp_path / "out"
    out.mkdir()
    _link(out / "problem.json", urdf, hard=False)  # where the problem's result would go
    result = runner.invoke(app, ["batch", str(problem), "--out", str(out), "--quiet", "--jobs", "1"])
    assert result.exit_code == 1, result.output  # the task failed: its result had nowhere safe to go
    assert urdf.read_text() == ONE_JOINT_URDF
    summary = [json.loads(line) for line in (out / "summary.jsonl").read_text().splitlines()]
    assert summary[0]["status"] == "error" and "refusing to overwrite the input file" in summary[0]["error"]["message"]
    assert "_inputs" not in summary[0]


def test_plot_arms_never_writes_over_a_mesh(tmp_path):
    pytest.importorskip("trimesh")
    mesh = tmp_path / "tip.stl"
    mesh.write_text(
        "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\n"
        "endfacet\nendsolid t\n"
    )
    (tmp_path / "one.urdf").write_text(
        ONE_JOINT_URDF.replace(
            '<link name="tip"/>',
            '<link name="tip"><visual><geometry><mesh filename="tip.stl"/></geometry></visual></link>',
        )
    )
    problem = _robot_problem(tmp_path)
    before = mesh.read_bytes()
    link = _link(tmp_path / "arms.png", mesh, hard=False)
    result = runner.invoke(app, ["plot", str(problem), "--what", "arms", "-o", str(link)])
    assert result.exit_code == 2, result.output
    assert "tip.stl" in result.output and mesh.read_bytes() == before


@pytest.mark.parametrize("attribute", ['scale="1 1"', 'scale="a b c"'])
def test_a_malformed_mesh_scale_is_exit_2_with_its_line(tmp_path, attribute):
    pytest.importorskip("trimesh")
    (tmp_path / "tip.stl").write_text(
        "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
        "vertex 0 1 0\nendloop\nendfacet\nendsolid t\n"
    )
    (tmp_path / "one.urdf").write_text(
        ONE_JOINT_URDF.replace(
            '<link name="tip"/>',
            f'<link name="tip"><visual><geometry><mesh filename="tip.stl" {attribute}/></geometry></visual></link>',
        )
    )
    problem = _robot_problem(tmp_path)
    result = runner.invoke(app, ["plot", str(problem), "--what", "arms", "-o", str(tmp_path / "a.png")])
    assert result.exit_code == 2, result.output
    assert "one.urdf" in result.output and "needs 3 numbers" in result.output


@pytest.mark.parametrize("included", ["/dev/zero", "missing.xacro"])
def test_a_xacro_include_of_a_device_or_a_missing_file_is_exit_2(tmp_path, included):
    pytest.importorskip("xacrodoc")
    (tmp_path / "arm.xacro").write_text(
        '<?xml version="1.0"?>\n<robot name="one" xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
        f'  <xacro:include filename="{included}"/>\n  <link name="base"/>\n</robot>\n'
    )
    problem = _robot_problem(tmp_path, "arm.xacro")
    result = runner.invoke(app, ["validate", str(problem)])
    assert result.exit_code == 2, result.output
    assert ("not a regular file" if included.startswith("/dev") else "no such file") in result.output
