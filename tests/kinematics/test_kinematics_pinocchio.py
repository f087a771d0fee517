"""Batched kinematics against Pinocchio's forward kinematics on the same URDF."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from bcad.compiler import compile_problem
from bcad.kinematics import Samples
from bcad.kinematics.se3 import pose_to_matrix
from bcad.model import load_problem

from conftest import RX90_URDF

BASE_POSE = [0.1, -0.2, 0.05, 0.01, -0.02, 0.3]


def _problem(write_problem, length_unit: str = "m"):
    scale = 1000.0 if length_unit == "mm" else 1.0
    pose = [v * scale for v in BASE_POSE[:3]] + BASE_POSE[3:]
    return load_problem(
        write_problem(
            f"""
            name: pinocchio-check
            units: {{length: {length_unit}}}
            frames: [world]
            robots:
              - name: arm
                urdf: {RX90_URDF}
                parent: world
                pose: {pose}
                joints:
                  default:
                    status: X
                    zero: normal(0, 0.05)
            links:
              - name: probe
                parent: world
                child: arm/link_6
                close: true
                status: LLLLLL
                distributions:
                  tx: normal(0, 1)
                  ty: normal(0, 1)
                  tz: normal(0, 1)
                  rx: normal(0, 1)
                  ry: normal(0, 1)
                  rz: normal(0, 1)
            """,
            name=f"pinocchio_{length_unit}.yaml",
        )
    )


def _pinocchio_placements(q: np.ndarray, frame: str) -> np.ndarray:
    model = pin.buildModelFromUrdf(str(RX90_URDF))
    data = model.createData()
    frame_id = model.getFrameId(frame)
    base = pose_to_matrix(np.array(BASE_POSE))
    out = np.empty((len(q), 4, 4))
    for n, configuration in enumerate(q):
        pin.forwardKinematics(model, data, configuration)
        pin.updateFramePlacements(model, data)
        out[n] = base @ data.oMf[frame_id].homogeneous
    return out


@pytest.fixture
def configurations():
    rng = np.random.default_rng(7)
    n = 64
    q = rng.uniform(-2.0, 2.0, size=(n, 6))
    zero = rng.normal(0.0, 0.05, size=(n, 6))
    return q, zero


def test_every_link_frame_matches_pinocchio(write_problem, configurations):
    compiled = compile_problem(_problem(write_problem))
    q, zero = configurations
    assert compiled.parameters.x_names == [f"arm/joint_{k}.rz" for k in range(1, 7)]
    assert compiled.parameters.l_names == [f"arm/joint_{k}/zero.rz" for k in range(1, 7)]
    frames = compiled.frame_transforms(q, Samples(zero))
    for link in ["link_1", "link_3", "link_5", "link_6"]:
        expected = _pinocchio_placements(q + zero, link)
        np.testing.assert_allclose(frames[f"arm/{link}"].matrices(), expected, atol=1e-12)


def test_closing_pose_of_a_link_parallel_to_the_robot_is_its_forward_kinematics(write_problem, configurations):
    compiled = compile_problem(_problem(write_problem))
    assert compiled.stats.cycles == 1
    assert [compiled.graph.links[i].name for i in compiled.graph.closing_links] == ["probe"]
    q, zero = configurations
    expected = _pinocchio_placements(q + zero, "link_6")
    # Scalar X (one configuration, many L samples): the solver's hot path.
    for n in range(0, len(q), 16):
        poses = compiled.closing_poses(q[n], Samples(zero))[0]
        got = pose_to_matrix(poses)
        want = _pinocchio_placements(np.repeat(q[n : n + 1], len(zero), axis=0) + zero, "link_6")
        np.testing.assert_allclose(got, want, atol=1e-12)
    per_sample = pose_to_matrix(compiled.closing_poses(q, Samples(zero))[0])
    np.testing.assert_allclose(per_sample, expected, atol=1e-12)


def test_millimetre_problem_scales_urdf_lengths(write_problem, configurations):
    metres = compile_problem(_problem(write_problem, "m"))
    millimetres = compile_problem(_problem(write_problem, "mm"))
    q, zero = configurations
    in_m = metres.closing_poses(q, Samples(zero))[0]
    in_mm = millimetres.closing_poses(q, Samples(zero))[0]
    np.testing.assert_allclose(in_mm[:, :3], 1000.0 * in_m[:, :3], atol=1e-9)
    np.testing.assert_allclose(in_mm[:, 3:], in_m[:, 3:], atol=1e-12)
