"""A joint's bounds and fixed value stay within its limits (a URDF's <limit>, a DH row's
``limits``): bounds or a value beyond them are refused at their place (exit 2); the same limits
written in other units (+-180 deg against +-3.14159 rad) are held to them."""

from __future__ import annotations

import math

import pytest

from bcad.compiler import compile_problem
from bcad.errors import InputError
from bcad.model import load_problem

from conftest import REPO

SLIDER = """
name: slider
frames: [w, tip, target]
robots:
  - name: arm
    parent: w
    dh:
      - {{a: 0.3, alpha: 0, d: 0, theta: 0, limits: [-3, 3]}}
      - {{a: 0, alpha: 0, d: 0, theta: 0, type: prismatic, limits: [0, 0.2]}}
    joints:
      default: {{status: X, zero: 'normal(0, 0.001)'}}
      joint_2: {setting}
links:
  - {{name: t, parent: arm/link_2, child: tip}}
  - {{name: g, parent: w, child: target, pose: [0.3, 0, 0.1, 0, 0, 0]}}
  - {{name: c, parent: target, child: tip, close: true, status: LLLFFF,
     distributions: {{tx: 'normal(0, 0.01)', ty: 'normal(0, 0.01)', tz: 'normal(0, 0.01)'}}}}
"""


def _compiled(write_problem, setting: str):
    return compile_problem(load_problem(write_problem(SLIDER.format(setting=setting))))


@pytest.mark.parametrize(
    "setting, message",
    [
        ("{bounds: [-1, 1]}", "joint 'joint_2': bounds [-1, 1] m reach beyond its limits [0, 0.2] m"),
        ("{status: F, value: 0.5}", "joint 'joint_2': value 0.5 m is beyond its limits [0, 0.2] m"),
    ],
)
def test_bounds_or_a_value_beyond_a_dh_rows_limits_are_refused_at_their_place(write_problem, setting, message):
    with pytest.raises(InputError) as refused:
        _compiled(write_problem, setting)
    assert message in refused.value.message
    text = SLIDER.format(setting=setting)
    line = 1 + text.lstrip("\n")[: text.lstrip("\n").index("      joint_2:")].count("\n")  # the setting's line
    assert refused.value.line == line


def test_bounds_within_the_limits_are_kept(write_problem):
    compiled = _compiled(write_problem, "{bounds: [0.05, 0.15]}")
    names = compiled.parameters.x_names
    assert compiled.parameters.x_bounds[names.index("arm/joint_2.tz")] == pytest.approx((0.05, 0.15))


def test_a_urdfs_limits_in_degrees_are_held_to_them(write_problem):
    """The RX90's joint_3 limits are +-142.5 deg (2.48709 rad in its URDF): bounds of +-142.50001
    deg, the same limits as rounded in another unit, are held to them; +-150 deg are refused."""
    limit = 2.4870941840919194
    text = (
        (REPO / "problems" / "relations" / "rx90_peg_in_hole.yaml")
        .read_text()
        .replace("../../robots/", f"{REPO}/robots/")
    )
    # in degrees (the other joints' bounds and values, read as degrees, stay within their limits)
    text = text.replace("units: {length: mm, angle: rad}", "units: {length: mm, angle: deg}")
    held = text.replace("joint_3: {bounds: [0.8, 2.48],", "joint_3: {bounds: [-142.50001, 142.50001],")
    assert held != text and math.radians(142.50001) > limit
    compiled = compile_problem(load_problem(write_problem(held)))
    names = compiled.parameters.x_names
    low, high = compiled.parameters.x_bounds[names.index("arm/joint_3.rz")]
    assert (low, high) == pytest.approx((-limit, limit), abs=1e-9) and high <= limit
    with pytest.raises(InputError, match="reach beyond its limits"):
        compile_problem(load_problem(write_problem(held.replace("[-142.50001, 142.50001]", "[-150, 150]"))))


CELL = """
name: planar-2r-cfg
units: {length: mm, angle: rad}
frames: [table, base, part]
links:
  - {name: base_placement, parent: table, child: base, status: XXFFFF, bounds: {tx: [-200, 200], ty: [-200, 200]}}
  - {name: part_placement, parent: table, child: part}
robots:
  - name: arm
    parent: base
    dh:
      - {a: 1000, alpha: 0, d: 0, theta: 0, limits: [-3.1, 3.1]}
      - {a: 800, alpha: 0, d: 0, theta: 0, limits: [-3.1, 3.1]}
    joints:
      default: {status: X}
      joint_1: {zero: 'normal(0, 0.002)'}
entities:
  - {name: p1, type: point, frame: part, at: [1200, 300, 0]}
  - {name: p2, type: point, frame: part, at: [900, -600, 0]}
  - {name: tip, type: point, frame: arm/link_2, at: [0, 0, 0]}
relations:
  - {name: reach_p1, type: point_on_point, parent: p1, child: tip, status: LLFFFF,
     distributions: {tx: 'normal(0, 0.5)', ty: 'normal(0, 0.5)'}}
  - {name: reach_p2, type: point_on_point, parent: p2, child: tip, status: LLFFFF,
     distributions: {tx: 'normal(0, 0.5)', ty: 'normal(0, 0.5)'}}
configurations:
  - {name: c1, joints: {arm: {}}, relations: [reach_p1]}
  - {name: c2, joints: {arm: SETTING}, relations: [reach_p2]}
"""


@pytest.mark.parametrize(
    "setting, message",
    [
        ("{joint_1: {status: F, value: 10}}", "joint 'arm/joint_1': value 10 rad is beyond its limits [-3.1, 3.1] rad"),
        ("{joint_1: {bounds: [-10, 10]}}", "joint 'arm/joint_1': bounds [-10, 10] rad reach beyond its limits"),
        (
            "{joint_1: {bounds: [-1, 1], prior: 'uniform(2, 3)'}}",
            "the prior on joint 'arm/joint_1' (its support [2, 3])",
        ),
    ],
)
def test_a_configurations_joint_settings_stay_within_the_joints_limits(write_problem, setting, message):
    """A configuration's own bounds, value or prior for a joint are held to the joint's limits as the
    robot's own settings are (they reached past them, and the solve ran the arm there)."""
    with pytest.raises(InputError) as refused:
        compile_problem(load_problem(write_problem(CELL.replace("SETTING", setting))))
    assert message in refused.value.message
    text = CELL.replace("SETTING", setting).lstrip("\n")
    assert refused.value.line == 1 + text[: text.index("  - {name: c2")].count("\n")


def test_a_configurations_bounds_within_the_limits_are_kept(write_problem):
    compiled = compile_problem(load_problem(write_problem(CELL.replace("SETTING", "{joint_1: {bounds: [-1, 1]}}"))))
    names = compiled.parameters.x_names
    assert compiled.parameters.x_bounds[names.index("arm/joint_1@c2.rz")] == pytest.approx((-1.0, 1.0))
