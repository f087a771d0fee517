"""Robots from DH rows, joint-origin errors and the calibrated URDF, against
independent computations: the plain DH product, the URDF origin composed by hand, Pinocchio."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import yaml
import yourdfpy

from bcad.calibration.urdf import calibrated_urdfs
from bcad.compiler import compile_problem
from bcad.errors import InputError
from bcad.kinematics import Samples
from bcad.kinematics.se3 import matrix_to_rpy_exact, pose_to_matrix, rpy_to_matrix
from bcad.model import load_problem

from conftest import RX90_URDF

ROWS = [
    {"a": 0.1, "alpha": 0.3, "d": 0.2, "theta": 0.4},
    {"a": 0.5, "alpha": -1.0, "d": 0.05, "theta": -0.2, "type": "prismatic", "limits": [-1, 1]},
    {"a": 0.3, "alpha": 1.2, "d": 0.1, "theta": 0.7},
]
ERRORS = {key: "normal(0, 0.01)" for key in ("a", "alpha", "d", "theta", "beta")}


def _rz(t):
    return pose_to_matrix(np.array([0, 0, 0, 0, 0, t]))


def _rx(t):
    return pose_to_matrix(np.array([0, 0, 0, t, 0, 0]))


def _ry(t):
    return pose_to_matrix(np.array([0, 0, 0, 0, t, 0]))


def _t(x, y, z):
    return pose_to_matrix(np.array([x, y, z, 0, 0, 0]))


def _dh_problem(tmp_path, convention: str, errors: dict | None = ERRORS):
    joints = {"default": {"status": "X", "dh_error": errors}} if errors else {}
    document = {
        "name": "dh",
        "frames": ["world"],
        "robots": [{"name": "r", "parent": "world", "dh": ROWS, "convention": convention, "joints": joints}],
    }
    path = tmp_path / f"{convention}.yaml"
    path.write_text(yaml.safe_dump(document))
    return compile_problem(load_problem(path))


def _errors_of(compiled, values):
    named = dict(zip(compiled.parameters.l_names, values))
    return lambda joint, link, parameter: named.get(f"r/{joint}/{link}.{parameter}", 0.0)


@pytest.mark.parametrize("convention", ["classic", "modified"])
def test_a_dh_robot_with_errors_is_the_dh_product(tmp_path, convention):
    compiled = _dh_problem(tmp_path, convention)
    rng = np.random.default_rng(1)
    for _ in range(5):
        q = rng.uniform(-1, 1, 3)
        errors = rng.normal(0, 0.01, len(compiled.parameters.l))
        T = compiled.frame_transforms(q, Samples(errors[None]), ["r/link_3"])["r/link_3"].matrices()[0]
        error = _errors_of(compiled, errors)
        expected = np.eye(4)
        for i, row in enumerate(ROWS):
            joint, prismatic = f"joint_{i + 1}", row.get("type") == "prismatic"
            d_link = "dh" if convention == "classic" and not prismatic else "zero"
            theta = row["theta"] + error(joint, "zero", "rz") + (0 if prismatic else q[i])
            d = row["d"] + error(joint, d_link, "tz") + (q[i] if prismatic else 0)
            a, alpha, beta = (
                row["a"] + error(joint, "dh", "tx"),
                row["alpha"] + error(joint, "dh", "rx"),
                error(joint, "dh", "ry"),
            )
            if convention == "classic":  # Rz(theta) Tz(d) Tx(a) Ry(beta) Rx(alpha)
                expected = expected @ _rz(theta) @ _t(0, 0, d) @ _t(a, 0, 0) @ _ry(beta) @ _rx(alpha)
            else:  # Tx(a) Ry(beta) Rx(alpha) Rz(theta) Tz(d)
                expected = expected @ _t(a, 0, 0) @ _ry(beta) @ _rx(alpha) @ _rz(theta) @ _t(0, 0, d)
        np.testing.assert_allclose(T, expected, atol=1e-12)


def test_a_zero_error_is_along_each_joints_own_variable(tmp_path):
    """``zero`` turns a revolute row about its axis and moves a prismatic one along it (d's error,
    a length); on the prismatic row it was a turn, and a length's std read as radians."""
    document = {
        "name": "dh",
        "frames": ["world"],
        "robots": [
            {
                "name": "r",
                "parent": "world",
                "dh": ROWS,
                "joints": {"default": {"status": "X", "zero": "normal(0, 0.01)"}},
            }
        ],
    }
    path = tmp_path / "zero.yaml"
    path.write_text(yaml.safe_dump(document))
    compiled = compile_problem(load_problem(path))
    assert compiled.parameters.l_names == ["r/joint_1/zero.rz", "r/joint_2/zero.tz", "r/joint_3/zero.rz"]
    errors = np.array([0.01, -0.02, 0.03])
    q = np.array([0.3, 0.4, -0.5])
    T = compiled.frame_transforms(q, Samples(errors[None]), ["r/link_3"])["r/link_3"].matrices()[0]
    expected = np.eye(4)
    for i, row in enumerate(ROWS):
        prismatic = row.get("type") == "prismatic"
        theta = row["theta"] + (0.0 if prismatic else q[i] + errors[i])
        d = row["d"] + (q[i] + errors[i] if prismatic else 0.0)
        expected = expected @ _rz(theta) @ _t(0, 0, d) @ _t(row["a"], 0, 0) @ _rx(row["alpha"])
    np.testing.assert_allclose(T, expected, atol=1e-12)
    document["robots"][0]["joints"]["joint_2"] = {"dh_error": {"d": "normal(0, 0.01)"}}
    path.write_text(yaml.safe_dump(document))
    with pytest.raises(InputError, match=r"gives its zero error twice \(zero and dh_error.d\)"):
        compile_problem(load_problem(path))


@pytest.mark.parametrize("convention", ["classic", "modified"])
def test_a_dh_robot_and_its_urdf_twin_agree_to_1e_12(tmp_path, convention):
    compiled = _dh_problem(tmp_path, convention, errors=None)
    text = calibrated_urdfs(compiled, np.zeros(3), np.zeros(0))["r"]
    model = pin.buildModelFromXML(text)
    data = model.createData()
    frame = model.getFrameId("link_3")
    for q in np.random.default_rng(2).uniform(-1, 1, (10, 3)):
        pin.framesForwardKinematics(model, data, q)
        T = compiled.frame_transforms(q, Samples(np.zeros((1, 0))), ["r/link_3"])["r/link_3"].matrices()[0]
        np.testing.assert_allclose(data.oMf[frame].homogeneous, T, atol=1e-12)


def _rx90_with_origin_errors(tmp_path):
    document = {
        "name": "rx90-origins",
        "units": {"length": "mm"},
        "frames": ["world"],
        "robots": [
            {
                "name": "arm",
                "urdf": str(RX90_URDF),
                "parent": "world",
                "joints": {
                    "default": {
                        "status": "X",
                        "zero": "normal(0, 0.002)",
                        "origin_error": {
                            "tx": "normal(0, 0.5)",
                            "ty": "normal(0, 0.5)",
                            "tz": "normal(0, 0.5)",
                            "rx": "normal(0, 0.003)",
                            "ry": "normal(0, 0.003)",
                            "rz": "normal(0, 0.003)",
                        },
                    }
                },
            }
        ],
    }
    path = tmp_path / "rx90.yaml"
    path.write_text(yaml.safe_dump(document))
    return compile_problem(load_problem(path))


def test_origin_errors_compose_after_the_urdf_origin_and_the_urdf_written_reproduces_them(tmp_path):
    compiled = _rx90_with_origin_errors(tmp_path)
    rng = np.random.default_rng(3)
    l = rng.normal(0, 1, len(compiled.parameters.l)) * np.array(
        [0.5 if name.rsplit(".", 1)[1] in ("tx", "ty", "tz") else 0.003 for name in compiled.parameters.l_names]
    )
    named = dict(zip(compiled.parameters.l_names, l))
    urdf = yourdfpy.URDF.load(str(RX90_URDF), build_scene_graph=False, load_meshes=False)
    q = rng.uniform(-1, 1, 6)
    # By hand: per joint, origin (mm) . T(origin error) . Rz(zero) . Rz(q) (every RX90 axis is +z).
    expected = np.eye(4)
    for k, joint in enumerate(j for j in urdf.robot.joints if j.type == "revolute"):
        origin = joint.origin.copy()
        origin[:3, 3] *= 1000.0
        error = np.array([named[f"arm/{joint.name}/origin.{p}"] for p in ("tx", "ty", "tz", "rx", "ry", "rz")])
        expected = expected @ origin @ pose_to_matrix(error) @ _rz(named[f"arm/{joint.name}/zero.rz"] + q[k])
    T = compiled.frame_transforms(q, Samples(l[None]), ["arm/link_6"])
    root = compiled.frame_transforms(q, Samples(l[None]), ["arm/base_link"])["arm/base_link"].matrices()[0]
    np.testing.assert_allclose(np.linalg.inv(root) @ T["arm/link_6"].matrices()[0], expected, atol=1e-9)

    # The calibrated URDF: Pinocchio and yourdfpy load it, and its kinematics are the model's to 1e-9 mm.
    text = calibrated_urdfs(compiled, np.zeros(6), l)["arm"]
    written = tmp_path / "calibrated.urdf"
    written.write_text(text)
    assert len(yourdfpy.URDF.load(str(written), build_scene_graph=False, load_meshes=False).actuated_joint_names) == 6
    model = pin.buildModelFromUrdf(str(written))
    data = model.createData()
    frame = model.getFrameId("link_6")
    for q in rng.uniform(-2, 2, (10, 6)):
        pin.framesForwardKinematics(model, data, q)
        M = data.oMf[frame].homogeneous.copy()
        M[:3, 3] *= 1000.0
        ours = (
            np.linalg.inv(root)
            @ compiled.frame_transforms(q, Samples(l[None]), ["arm/link_6"])["arm/link_6"].matrices()[0]
        )
        np.testing.assert_allclose(M, ours, atol=1e-9)


def test_rpy_of_a_matrix_rebuilds_it_at_gimbal_lock():
    rng = np.random.default_rng(4)
    for ry in (np.pi / 2, -np.pi / 2, np.pi / 2 - 1e-9, np.pi / 2 - 1e-5, 0.3):
        for _ in range(20):
            R = rpy_to_matrix(np.array([rng.uniform(-3, 3), ry, rng.uniform(-3, 3)]))
            np.testing.assert_allclose(rpy_to_matrix(matrix_to_rpy_exact(R)), R, atol=1e-15)


def test_dh_and_origin_errors_in_the_wrong_robot_are_located(tmp_path):
    from typer.testing import CliRunner

    from bcad.cli import app

    document = {
        "name": "bad",
        "frames": ["world"],
        "robots": [
            {
                "name": "arm",
                "urdf": str(RX90_URDF),
                "parent": "world",
                "joints": {"joint_2": {"dh_error": {"a": "normal(0, 1)"}}},
            }
        ],
    }
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(document))
    result = CliRunner().invoke(app, ["validate", str(path)])
    assert (
        result.exit_code == 2
        and "dh_error is for robots given by dh: rows" in result.stderr
        and f"{path}:" in result.stderr
    )
    document = {
        "name": "bad",
        "frames": ["world"],
        "robots": [
            {
                "name": "r",
                "parent": "world",
                "dh": ROWS,
                "joints": {"joint_1": {"origin_error": {"tx": "normal(0, 1)"}}},
            }
        ],
    }
    path.write_text(yaml.safe_dump(document))
    result = CliRunner().invoke(app, ["validate", str(path)])
    assert result.exit_code == 2 and "origin_error is for URDF joints" in result.stderr
    document = {
        "name": "bad",
        "frames": ["world"],
        "robots": [{"name": "r", "parent": "world", "dh": ROWS, "urdf": str(RX90_URDF)}],
    }
    path.write_text(yaml.safe_dump(document))
    result = CliRunner().invoke(app, ["validate", str(path)])
    assert result.exit_code == 2 and "exactly one of urdf" in result.stderr


TILTED = """<?xml version="1.0"?>
<robot name="tilted">
  <link name="base"/><link name="a"/><link name="b"/><link name="c"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="a"/>
    <origin xyz="0.1 0.2 0.3" rpy="0.1 -0.2 0.3"/><axis xyz="0.6 0 0.8"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="prismatic"><parent link="a"/><child link="b"/>
    <origin xyz="0.0 0.5 0.1" rpy="0 0 0"/><axis xyz="1 1 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="b"/><child link="c"/>
    <origin xyz="0.3 0 0" rpy="0.5 0.4 0.3"/><axis xyz="0 -0.28 0.96"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
</robot>
"""


@pytest.mark.parametrize("with_errors", [False, True])
def test_joint_axes_in_any_direction_match_pinocchio(tmp_path, with_errors):
    (tmp_path / "tilted.urdf").write_text(TILTED)
    joints = {"default": {"status": "X", "zero": "normal(0, 0.01)"}} if with_errors else {}
    document = {
        "name": "tilted",
        "frames": ["world"],
        "robots": [{"name": "r", "urdf": "tilted.urdf", "parent": "world", "joints": joints}],
    }
    path = tmp_path / "tilted.yaml"
    path.write_text(yaml.safe_dump(document))
    compiled = compile_problem(load_problem(path))
    model = pin.buildModelFromXML(TILTED)
    data = model.createData()
    frame = model.getFrameId("c")
    rng = np.random.default_rng(5)
    zeros = rng.normal(0, 0.01, 3) if with_errors else np.zeros(0)
    for q in rng.uniform(-1, 1, (10, 3)):
        # The zero error adds to the joint's value, about (or along) the same axis.
        pin.framesForwardKinematics(
            model,
            data,
            q
            + (np.array([zeros[0], 0.0, zeros[2]]) if with_errors else 0.0)
            + (np.array([0.0, zeros[1], 0.0]) if with_errors else 0.0),
        )
        T = compiled.frame_transforms(q, Samples(zeros[None]), ["r/c"])["r/c"].matrices()[0]
        np.testing.assert_allclose(T, data.oMf[frame].homogeneous, atol=1e-12)
    if with_errors:  # and the calibrated URDF keeps the axes and folds the zeros in
        text = calibrated_urdfs(compiled, np.zeros(3), zeros)["r"]
        written = pin.buildModelFromXML(text)
        written_data = written.createData()
        q = rng.uniform(-1, 1, 3)
        pin.framesForwardKinematics(written, written_data, q)
        T = compiled.frame_transforms(q, Samples(zeros[None]), ["r/c"])["r/c"].matrices()[0]
        np.testing.assert_allclose(written_data.oMf[written.getFrameId("c")].homogeneous, T, atol=1e-9)


XACRO = """<?xml version="1.0"?>
<robot name="two" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:arg name="reach" default="0.5"/>
  <xacro:property name="reach" value="$(arg reach)"/>
  <xacro:macro name="segment" params="name parent child x">
    <joint name="${name}" type="revolute"><parent link="${parent}"/><child link="${child}"/>
      <origin xyz="${x} 0 0.1" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  </xacro:macro>
  <link name="base"/><link name="upper"/><link name="fore"/>
  <xacro:segment name="shoulder" parent="base" child="upper" x="0"/>
  <xacro:segment name="elbow" parent="upper" child="fore" x="${reach}"/>
</robot>
"""


@pytest.mark.parametrize("reach", ["0.7", 0.7])  # a YAML string or number, as the limits say
def test_a_xacro_robot_is_expanded_with_its_args(tmp_path, reach):
    pytest.importorskip("xacrodoc")
    (tmp_path / "two.urdf.xacro").write_text(XACRO)
    document = {
        "name": "xacro",
        "frames": ["world"],
        "robots": [{"name": "r", "urdf": "two.urdf.xacro", "parent": "world", "xacro_args": {"reach": reach}}],
    }
    path = tmp_path / "x.yaml"
    path.write_text(yaml.safe_dump(document))
    compiled = compile_problem(load_problem(path))
    q = np.array([0.3, -0.8])
    T = compiled.frame_transforms(q, Samples(np.zeros((1, 0))), ["r/fore"])["r/fore"].matrices()[0]
    # By hand: Tz(0.1) Rz(0.3) . T(0.7, 0, 0.1) Rz(-0.8)
    expected = _t(0, 0, 0.1) @ _rz(0.3) @ _t(0.7, 0, 0.1) @ _rz(-0.8)
    np.testing.assert_allclose(T, expected, atol=1e-12)


def test_a_xacro_robot_without_xacrodoc_says_how_to_install_it(tmp_path, monkeypatch):
    import sys

    from typer.testing import CliRunner

    from bcad.cli import app

    (tmp_path / "two.urdf.xacro").write_text(XACRO)
    document = {
        "name": "xacro",
        "frames": ["world"],
        "robots": [{"name": "r", "urdf": "two.urdf.xacro", "parent": "world"}],
    }
    path = tmp_path / "x.yaml"
    path.write_text(yaml.safe_dump(document))
    monkeypatch.setitem(sys.modules, "xacrodoc", None)  # import xacrodoc now raises ImportError
    result = CliRunner().invoke(app, ["validate", str(path)])
    assert result.exit_code == 2 and "pip install 'bcad[xacro]'" in result.stderr


@pytest.mark.parametrize("name", ["3r", "7r"])
def test_a_clearance_chains_rows_describe_the_same_robot(tmp_path, name):
    """One DH table for both parts of bcad: a clearance chain's rows, as a problem's DH robot at
    q = 0, put the end effector where the DH product of those rows does."""
    from bcad.model.clearance import load_chain_problem

    from conftest import REPO

    chain = load_chain_problem(REPO / "problems" / "clearance" / f"{name}.yaml")
    rows = [row.model_dump(exclude_none=True) for row in chain.chain.dh]
    document = {"name": name, "frames": ["world"], "robots": [{"name": "r", "parent": "world", "dh": rows}]}
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(document))
    compiled = compile_problem(load_problem(path))
    tip = f"r/link_{len(rows)}"
    T = compiled.frame_transforms(np.zeros(len(rows)), Samples(np.zeros((1, 0))), [tip])[tip].matrices()[0]
    expected = np.eye(4)
    for row in chain.chain.dh:
        expected = expected @ _rz(row.theta) @ _t(0, 0, row.d) @ _t(row.a, 0, 0) @ _rx(row.alpha)
    np.testing.assert_allclose(T, expected, atol=1e-12)


@pytest.mark.parametrize(
    "value",
    [
        "__import__('os').system('touch PWNED')",
        "1.0; import os",
        "0.5 * 2",
        "a b",
        "x.__class__",
        "'quoted'",
        "${1}",
        "$(arg other)",
    ],
)
def test_a_xacro_argument_is_a_literal_and_runs_nothing(tmp_path, value):
    """A xacro argument is substituted into the file's expressions, which xacro evaluates
    as Python; a problem file (or a sweep's value) must never run anything, so only numbers and
    plain words pass the schema, before xacro is ever called (exit 2, the file and line)."""
    from typer.testing import CliRunner

    from bcad.cli import app

    (tmp_path / "two.urdf.xacro").write_text(XACRO.replace('value="$(arg reach)"', 'value="${$(arg reach) * 1.0}"'))
    document = {
        "name": "xacro",
        "frames": ["world"],
        "robots": [{"name": "r", "urdf": "two.urdf.xacro", "parent": "world", "xacro_args": {"reach": value}}],
    }
    path = tmp_path / "x.yaml"
    path.write_text(yaml.safe_dump(document))
    result = CliRunner().invoke(app, ["validate", str(path)], catch_exceptions=False)
    assert result.exit_code == 2 and "a xacro argument is a literal" in result.stderr and "x.yaml:" in result.stderr
    assert not (tmp_path / "PWNED").exists() and not any(p.name == "PWNED" for p in tmp_path.parent.iterdir())


def test_a_xacro_argument_that_is_a_number_is_a_bounded_one(tmp_path):
    """A YAML number is passed on as Python writes it, within the bound a quoted one has."""
    from bcad.model.problem import Robot

    robot = {"name": "r", "urdf": "two.urdf.xacro", "parent": "world"}
    assert Robot.model_validate({**robot, "xacro_args": {"reach": 0.7, "n": 2}}).xacro_args == {
        "reach": "0.7",
        "n": "2",
    }
    for number in (10**30, 10**400, 10**5000):  # (10**400 has no float, 10**5000 no repr)
        with pytest.raises(ValueError, match="expected a finite number of at most"):
            Robot.model_validate({**robot, "xacro_args": {"reach": number}})


@pytest.mark.parametrize(
    "value",
    ["1e400", "-1e30", "inf", "-Infinity", "nan", "1_000_000_000_000_000", "0x" + "f" * 300, "0b" + "1" * 60, "1j"],
)
def test_a_quoted_xacro_number_is_bounded_as_a_yaml_one(value):
    """A word Python reads as a number is that number in xacro's expressions: bounded too."""
    from bcad.model.problem import _xacro_literal

    with pytest.raises(ValueError, match="expected a finite number of at most"):
        _xacro_literal("reach", value)


@pytest.mark.parametrize("value", ["0.7", "-1e-3", "ur5e", "true", "meshes/arm-v2.stl", "0x1f", "2nd_arm", "0o17"])
def test_plain_xacro_arguments_pass(value):
    from bcad.model.problem import _xacro_literal

    _xacro_literal("reach", value)


@pytest.mark.parametrize(
    "body",
    [
        '<xacro:property name="big" value="${10**10**8}"/><link name="base" type="${big}"/>',
        '<xacro:macro name="m0"><link name="l"/></xacro:macro>'
        + "".join(f'<xacro:macro name="m{k}"><xacro:m{k - 1}/><xacro:m{k - 1}/></xacro:macro>' for k in range(1, 27))
        + "<xacro:m26/>",
    ],
)
def test_a_xacro_file_that_grows_without_bound_is_stopped(tmp_path, monkeypatch, body):
    """Its expressions are Python and its macros may double: the expansion runs in a child
    process bounded in time (here 2 s) and memory, and ends in exit 2 with the file named."""
    pytest.importorskip("xacrodoc")
    import time

    from typer.testing import CliRunner

    import bcad.compiler.urdf as urdf
    from bcad.cli import app

    monkeypatch.setattr(urdf, "XACRO_SECONDS", 2)
    (tmp_path / "bomb.urdf.xacro").write_text(
        f'<?xml version="1.0"?>\n<robot name="b" xmlns:xacro="http://www.ros.org/wiki/xacro">{body}</robot>\n'
    )
    path = tmp_path / "x.yaml"
    path.write_text(
        yaml.safe_dump(
            {"name": "x", "frames": ["a"], "robots": [{"name": "r", "urdf": "bomb.urdf.xacro", "parent": "a"}]}
        )
    )
    started = time.perf_counter()
    result = CliRunner().invoke(app, ["validate", str(path)])
    assert result.exit_code == 2 and "bomb.urdf.xacro: the xacro file did not expand within 2 s" in result.stderr, (
        result.output
    )
    assert time.perf_counter() - started < 10
