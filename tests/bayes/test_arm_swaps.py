"""The hop that exchanges the joint values of two arms of one model."""

from __future__ import annotations

import shutil

import numpy as np
import yaml

from bcad.bayes.arm_swaps import arm_swaps
from bcad.compiler import compile_problem
from bcad.model import load_problem
from bcad.model.problem import load

from conftest import RX90_EXAMPLE, RX90_URDF


def test_two_arms_of_one_model_in_one_cycle_exchange_their_joints_name_for_name():
    """The two RX90s: one permutation, an involution that maps each of arm1's joints to arm2's
    joint of the same name and back, and leaves nothing else in place of another."""
    compiled = compile_problem(load_problem(RX90_EXAMPLE))
    names = compiled.parameters.x_names
    (swap,) = arm_swaps(compiled)
    np.testing.assert_array_equal(swap[swap], np.arange(len(names)))
    for column, other in enumerate(swap):
        robot, joint = names[column].split("/", 1)
        assert robot in ("arm1", "arm2") and names[other] == f"{'arm2' if robot == 'arm1' else 'arm1'}/{joint}"


def test_arms_of_different_models_or_bounds_are_not_exchanged(tmp_path):
    """The same cell with arm2 read from a copy of the URDF (another model, for all bcad can
    tell), or with one of arm2's joints bounded more narrowly: no exchange."""
    document = yaml.safe_load(RX90_EXAMPLE.read_text(encoding="utf-8"))
    copy = tmp_path / "rx90_copy.urdf"
    shutil.copy(RX90_URDF, copy)
    for robot in document["robots"]:
        robot["urdf"] = str(RX90_URDF)
    other_file = {**document, "robots": [document["robots"][0], {**document["robots"][1], "urdf": str(copy)}]}
    narrower = yaml.safe_load(yaml.safe_dump(document))
    joints = narrower["robots"][1].setdefault("joints", {})
    joints["joint_3"] = {**joints.get("default", {}), "bounds": [-1.0, 1.0]}
    assert arm_swaps(compile_problem(load(document)))  # both from one file: exchanged
    for variant in (other_file, narrower):
        assert arm_swaps(compile_problem(load(variant))) == []
