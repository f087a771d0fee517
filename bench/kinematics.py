"""Benchmark: closing pose of the RX90 Face-On-Face example for N samples.

Prints, in one run:
* bcad, hot path: the closing pose for a new X on a batch of L samples whose
  per-batch caches exist (what the solver does for every individual);
* bcad, from scratch: drawing the N samples and the first evaluation,
  caches included;
* a per-sample Python loop over Pinocchio's forwardKinematics computing the
  same closing pose (an independent implementation: the two are compared);
* the ratio of the loop's time to bcad's.

Run: python bench/kinematics.py [--samples 1e5] [--loop-samples 1e5]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
from timing import as_the_command_line, best_of  # noqa: E402  (bench/ is on the path)

from bcad.compiler import compile_problem
from bcad.kinematics import Samples
from bcad.kinematics.se3 import matrix_to_pose, pose_to_matrix, rotation_about_axis
from bcad.model import load_problem

REPO = Path(__file__).resolve().parent.parent
PROBLEM = REPO / "problems" / "rx90_face_on_face.yaml"
PARAMS = ("tx", "ty", "tz", "rx", "ry", "rz")


def pinocchio_loop(problem, compiled, x: np.ndarray, l: np.ndarray) -> np.ndarray:
    """The closing pose, sample by sample, with Pinocchio for each arm's kinematics."""
    names = {name: k for k, name in enumerate(compiled.parameters.l_names)}
    model = pin.buildModelFromUrdf(str(REPO / "robots" / "rx90.urdf"))
    data = model.createData()
    flange = model.getFrameId("link_6")
    robots = {robot.name: robot for robot in problem.robots}
    links = {link.name: link for link in problem.links}
    faces = {entity.name: entity for entity in problem.entities}
    flip = np.eye(4)
    flip[:3, :3] = rotation_about_axis(0, np.pi)
    face1 = pose_to_matrix(np.array(faces["face1"].pose)) @ flip  # child face, flipped
    face2 = pose_to_matrix(np.array(faces["face2"].pose))

    def se3(nominal, prefix, sample):
        pose = np.array(nominal, dtype=float) + [sample[names[f"{prefix}.{p}"]] for p in PARAMS]
        return pin.SE3(pin.rpy.rpyToMatrix(pose[3], pose[4], pose[5]), pose[:3])

    def arm_to_face(arm, index, sample, face):
        q = x[6 * (index - 1) : 6 * index] + [sample[names[f"{arm}/joint_{j}/zero.rz"]] for j in range(1, 7)]
        pin.framesForwardKinematics(model, data, q)
        fk = data.oMf[flange]
        fk_mm = pin.SE3(fk.rotation, fk.translation * 1000.0)  # URDF metres, problem millimetres
        return (
            se3(robots[arm].pose, f"{arm}/base", sample)
            * fk_mm
            * se3(links[f"gripper{index}_mount"].pose, f"gripper{index}_mount", sample)
            * se3(links[f"part{index}_grasp"].pose, f"part{index}_grasp", sample)
            * pin.SE3(face)
        )

    out = np.empty((len(l), 6))
    for n, sample in enumerate(l):
        child = arm_to_face("arm1", 1, sample, face1)
        parent = arm_to_face("arm2", 2, sample, face2)
        out[n] = matrix_to_pose((parent.inverse() * child).homogeneous)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=float, default=1e5)
    parser.add_argument("--loop-samples", type=float, default=1e5)
    parser.add_argument("--repeats", type=int, default=10)
    args = parser.parse_args()
    n, n_loop = int(args.samples), int(args.loop_samples)
    as_the_command_line()

    problem = load_problem(PROBLEM)
    compiled = compile_problem(problem)
    rng = np.random.default_rng(0)
    x = np.array(compiled.parameters.x_nominal) + rng.uniform(-0.5, 0.5, size=12)

    def from_scratch():
        samples = Samples(compiled.parameters.sample_free_parameters(np.random.default_rng(1), n))
        return samples, compiled.closing_poses(x, samples)

    scratch = best_of(from_scratch, 3)
    samples, _ = from_scratch()
    hot = best_of(lambda: compiled.closing_poses(x + 1e-3, samples), args.repeats)

    loop_samples = samples.values[:n_loop]
    start = time.perf_counter()
    reference = pinocchio_loop(problem, compiled, x, loop_samples)
    loop = time.perf_counter() - start
    loop_per_n = loop * n / len(loop_samples)
    ours = compiled.closing_poses(x, samples)[0][: len(loop_samples)]
    deviation = np.abs(pose_to_matrix(ours) - pose_to_matrix(reference)).max()

    stats = compiled.stats
    print(
        f"problem: {PROBLEM.name}: {stats.frames} frames, {stats.links} links, X {stats.optimization_dim}, L {stats.integration_dim}"
    )
    print(f"samples N = {n}")
    print(f"bcad closing pose, new X on cached samples (hot path): {hot * 1e3:8.1f} ms")
    print(f"bcad from scratch (draw N samples + first evaluation):  {scratch * 1e3:8.1f} ms")
    label = f"{len(loop_samples)} samples" + ("" if len(loop_samples) == n else f", scaled to {n}")
    print(f"Pinocchio per-sample Python loop ({label}): {loop_per_n * 1e3:8.1f} ms")
    print(f"speed-up, hot path:     {loop_per_n / hot:8.1f}x")
    print(f"speed-up, from scratch: {loop_per_n / scratch:8.1f}x")
    print(f"max |T_bcad - T_pinocchio| over {len(loop_samples)} samples: {deviation:.2e}")


if __name__ == "__main__":
    main()
