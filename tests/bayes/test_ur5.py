"""The UR5 (robots/ur5.urdf) against Pinocchio, and the probe-on-a-face example."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from bcad.bayes.run import solve_document as solve
from bcad.compiler import compile_problem
from bcad.kinematics import Samples
from bcad.kinematics.se3 import pose_to_matrix
from bcad.model import load_problem

from conftest import REPO

UR5_URDF = REPO / "robots" / "ur5.urdf"
UR5_PROBE = REPO / "problems" / "ur5_probe_face.yaml"
BASE_POSE = [0.2, -0.1, 0.03, 0.02, -0.01, 0.4]
JOINTS = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"]


def test_ur5_frames_match_pinocchio(write_problem):
    problem = load_problem(
        write_problem(f"""
        name: ur5-check
        frames: [world]
        robots:
          - name: ur5
            urdf: {UR5_URDF}
            parent: world
            pose: {BASE_POSE}
            joints:
              default: {{status: X, zero: 'normal(0, 0.01)'}}
        links:
          - {{name: probe, parent: world, child: ur5/tool0, close: true, status: LLLFFF,
              distributions: {{tx: 'normal(0, 1)', ty: 'normal(0, 1)', tz: 'normal(0, 1)'}}}}
        """)
    )
    compiled = compile_problem(problem)
    # Shoulder lift, elbow and wrists 1 and 3 turn about y: their parameter is ry.
    axes = ["rz", "ry", "ry", "ry", "rz", "ry"]
    assert compiled.parameters.x_names == [f"ur5/{joint}.{axis}" for joint, axis in zip(JOINTS, axes)]
    rng = np.random.default_rng(3)
    q = rng.uniform(-3.0, 3.0, size=(32, 6))
    zero = rng.normal(0.0, 0.01, size=(32, 6))
    frames = compiled.frame_transforms(q, Samples(zero))
    model = pin.buildModelFromUrdf(str(UR5_URDF))
    data = model.createData()
    base = pose_to_matrix(np.array(BASE_POSE))
    for link in ["shoulder_link", "forearm_link", "wrist_3_link", "tool0", "ee_link"]:
        frame_id = model.getFrameId(link)
        expected = np.empty((len(q), 4, 4))
        for n, configuration in enumerate(q + zero):
            pin.forwardKinematics(model, data, configuration)
            pin.updateFramePlacements(model, data)
            expected[n] = base @ data.oMf[frame_id].homogeneous
        np.testing.assert_allclose(frames[f"ur5/{link}"].matrices(), expected, atol=1e-9)


def test_ur5_probe_statistics():
    stats = compile_problem(load_problem(UR5_PROBE)).stats.as_dict()
    assert stats == {
        "frames": 20,
        "links": 20,
        "cycles": 1,
        "optimization_dim": 6,
        "integration_dim": 15,
        "inequality_constraints": 4,
    }


@pytest.mark.parametrize("seed", [0, 5])
def test_ur5_probe_tip_lands_on_the_face(seed):
    result = solve(compile_problem(load_problem(UR5_PROBE)), backend="bayes", seed=seed)
    assert result["warnings"] == []
    touch = result["posterior"]["links"]["touch"]
    tx, ty, tz = touch["mean"][:3]
    # On the face (tz ~ N(0, 0.05 mm): within 3 of its std) and inside its 100 x 100 mm square.
    assert abs(tz) < 0.15 and abs(touch["weighted"]["mean"][2]) < 0.15
    assert max(abs(tx), abs(ty)) < 50.0
    assert touch["satisfied"] > 0.99
    objective = result["objective"]
    assert objective["log_value_se"] < 0.01 and objective["effective_samples"] > 20000
    assert objective["log_value"] > result["diagnostics"]["nominal_comparison"]["log_objective"]


def test_ur5_clearance_chain_with_y_axes_matches_brute_force(tmp_path):
    """Joints about y (the UR5's 2, 3, 4, 6) get a joint frame turned so that z is their axis.
    With only rot_z clearances the first-order rotation error is sum_j d_j a_j (a_j the joint
    axes, d_j in [-c, c]): its maximum is at a vertex of the box, found here by brute force
    over the 64 sign vectors with Pinocchio's axes."""
    import itertools
    import json

    from typer.testing import CliRunner

    from bcad.cli import app

    q = [0.3, -1.1, 1.4, -0.6, 1.2, 0.4]
    path = tmp_path / "chain.yaml"
    path.write_text(
        f"name: ur5-clearance\nchain: {{urdf: {UR5_URDF}, q: {q}, tip: tool0}}\nclearance: {{rot_z: 1.0e-3}}\n"
    )
    result = CliRunner().invoke(app, ["maxerror", str(path), "--json"])
    assert result.exit_code == 0, result.output
    found = json.loads(result.stdout)["rotation"]
    model = pin.buildModelFromUrdf(str(UR5_URDF))
    data = model.createData()
    pin.forwardKinematics(model, data, np.array(q))
    columns = {"JointModelRX": 0, "JointModelRY": 1, "JointModelRZ": 2}
    axes = np.array([data.oMi[j].rotation[:, columns[model.joints[j].shortname()]] for j in range(1, model.njoints)])
    best = max(np.linalg.norm(np.array(signs) @ axes) * 1e-3 for signs in itertools.product((-1, 1), repeat=6))
    assert found["max"] <= best * (1 + 1e-12) and best <= found["upper_bound"] * (1 + 1e-12)
    assert found["max"] == pytest.approx(best, rel=1e-9)
