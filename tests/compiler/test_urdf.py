"""bcad's URDF reader against yourdfpy's on the same file."""

from __future__ import annotations

import numpy as np
import pytest
import yourdfpy

from bcad.compiler.urdf import read_urdf
from bcad.errors import InputError

from conftest import RX90_URDF


def test_reader_agrees_with_yourdfpy():
    ours = read_urdf(RX90_URDF)
    theirs = yourdfpy.URDF.load(str(RX90_URDF), build_scene_graph=False, load_meshes=False).robot
    assert ours.links == [link.name for link in theirs.links]
    assert len(ours.joints) == len(theirs.joints) == 6
    for mine, reference in zip(ours.joints, theirs.joints):
        assert (mine.name, mine.type, mine.parent, mine.child) == (
            reference.name,
            reference.type,
            reference.parent,
            reference.child,
        )
        np.testing.assert_allclose(mine.origin, reference.origin, atol=1e-15)
        np.testing.assert_allclose(mine.axis, reference.axis)
        assert (mine.lower, mine.upper) == (reference.limit.lower, reference.limit.upper)


def test_rx90_limits_are_the_published_ones():
    degrees = {j.name: (np.degrees(j.lower), np.degrees(j.upper)) for j in read_urdf(RX90_URDF).joints}
    expected = {
        "joint_1": (-160, 160),
        "joint_2": (-137.5, 137.5),
        "joint_3": (-142.5, 142.5),
        "joint_4": (-270, 270),
        "joint_5": (-105, 120),
        "joint_6": (-270, 270),
    }
    for name, (low, high) in expected.items():
        assert degrees[name] == pytest.approx((low, high), abs=1e-9)


def test_errors_name_the_urdf_line(tmp_path):
    path = tmp_path / "bad.urdf"
    path.write_text(
        '<robot name="x">\n<link name="a"/>\n<joint name="j" type="fixed">\n<parent link="a"/>\n<child link="zz"/>\n</joint>\n</robot>\n'
    )
    with pytest.raises(InputError) as error:
        read_urdf(path)
    assert error.value.line == 5 and "unknown link 'zz'" in error.value.message


PLACED_URDF = """<?xml version="1.0"?>
<robot name="r">
  <!-- <link name="old"/> <origin xyz="0 0 0"/> -->
  <link name="a"/> <link name="b"/>
  <joint name="j" type="revolute"><parent link="a"/><child link="b"/><origin xyz="0 0 0"/>
    <origin_note/><axis
        xyz="{axis}"/><limit lower="{lower}" upper="1"/></joint>
</robot>
"""


@pytest.mark.parametrize(
    ("axis", "lower", "extra", "place", "fragment"),
    [
        ("0 0 nan", "-1", "", (7, 9), '<axis xyz="0 0 nan">: every number must be finite'),
        ("0 0 0", "-1", "", (7, 9), "joint 'j' has a zero axis"),
        ("0 0 1", "x", "", (7, 29), 'limit lower="x" is not a number'),
        ("0 0 1", "2", "", (7, 29), "limit lower=2 must be below upper=1"),
        ("0 0 1", "-1", '<link name="c"/>', (8, 1), "link 'c' is no joint's child, nor is 'a'"),
        ("0 0 1", "-1", '<joint name="k" type="fixed"><parent link="q"/></joint>', (8, 1), "a <joint> needs"),
        (
            "0 0 1",
            "-1",
            '<link name="c"/><joint name="k" type="fixed"><parent link="c"/><child link="a"/></joint>'
            '<joint name="m" type="fixed"><parent link="b"/><child link="c"/></joint>',
            (5, 3),
            "the joints 'j', 'm', 'k' form a cycle",
        ),
    ],
)
def test_errors_name_the_urdf_line_and_column(tmp_path, axis, lower, extra, place, fragment):
    """URDF errors named a line (or nothing, for a second root or a cycle): each names the line and
    column of the attribute at fault, else of its element's start tag, found on the line lxml
    gives (where a start tag spanning lines ends) past a comment and an element of the same name."""
    path = tmp_path / "r.urdf"
    path.write_text(PLACED_URDF.format(axis=axis, lower=lower).replace("</robot>", extra + "\n</robot>"))
    with pytest.raises(InputError) as error:
        read_urdf(path).root()
    assert (error.value.line, error.value.column) == place and fragment in error.value.message, error.value


def test_the_robots_urdf_structure_errors_are_placed_by_the_command(tmp_path):
    from typer.testing import CliRunner

    from bcad.cli import app

    (tmp_path / "r.urdf").write_text(
        PLACED_URDF.format(axis="0 0 1", lower="-1").replace("</robot>", '<link name="c"/>\n</robot>')
    )
    path = tmp_path / "p.yaml"
    path.write_text("name: p\nframes: [w]\nrobots:\n  - {name: arm, urdf: r.urdf, parent: w}\n")
    result = CliRunner().invoke(app, ["validate", str(path)])
    assert result.exit_code == 2 and f"{tmp_path / 'r.urdf'}:8:1: link 'c' is no joint's child" in result.stderr


MIMIC_URDF = """<robot name="gripperish"><link name="a"/><link name="b"/><link name="c"/>
<joint name="j1" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/><limit lower="-3" upper="3"/></joint>
<joint name="j2" type="revolute"><parent link="b"/><child link="c"/><origin xyz="1 0 0"/><axis xyz="0 0 -1"/>
<limit lower="-3" upper="3"/><mimic joint="j1" multiplier="2" offset="0.1"/></joint>
</robot>
"""


def test_mimic_joints_follow_their_master(tmp_path):
    """q2 = 2 q1 + 0.1 about -z: the tool's pose against the closed form, zero errors included
    (each an error of its own link's parameter: rz = -q for an axis 0 0 -1)."""
    import math

    import numpy as np

    from bcad.compiler import compile_problem
    from bcad.kinematics import Samples
    from bcad.model import load_problem

    (tmp_path / "mimic.urdf").write_text(MIMIC_URDF)
    path = tmp_path / "mimic.yaml"
    path.write_text(
        "name: mimic\nframes: [w, t]\nrobots:\n  - {name: arm, urdf: mimic.urdf, parent: w, joints: {default: {status: X, zero: 'normal(0, 0.01)'}}}\n"
        "links:\n  - {name: tool, parent: arm/c, child: t, pose: [0.5, 0, 0, 0, 0, 0]}\n"
        "  - {name: target, parent: w, child: t, close: true, status: LLFFFF, pose: [1, 0.5, 0, 0, 0, 0], distributions: {tx: 'normal(0, 0.01)', ty: 'normal(0, 0.01)'}}\n"
    )
    compiled = compile_problem(load_problem(path))
    assert compiled.parameters.x_names == ["arm/j1.rz"]  # the mimic joint is no unknown of its own
    for q1, z1, z2 in [(0.3, 0.0, 0.0), (0.3, 0.01, -0.02), (-0.7, -0.03, 0.02)]:
        pose = compiled.closing_poses(np.array([q1]), Samples(np.array([[z1, z2]])))[0][0]
        a1, a2 = q1 + z1, -(2 * q1 + 0.1) + z2
        expected = [math.cos(a1) + 0.5 * math.cos(a1 + a2), math.sin(a1) + 0.5 * math.sin(a1 + a2), a1 + a2]
        np.testing.assert_allclose(pose[[0, 1, 5]], expected, atol=1e-12)


def test_a_mimic_joint_cannot_be_an_unknown(tmp_path):
    from typer.testing import CliRunner

    from bcad.cli import app

    (tmp_path / "mimic.urdf").write_text(MIMIC_URDF)
    path = tmp_path / "mimic.yaml"
    path.write_text(
        "name: mimic\nframes: [w]\nrobots:\n  - {name: arm, urdf: mimic.urdf, parent: w, joints: {j2: {status: X}}}\n"
    )
    result = CliRunner().invoke(app, ["validate", str(path)])
    assert result.exit_code == 2 and "mimics 'j1'" in result.stderr
