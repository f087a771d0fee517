"""Benchmark of hand-eye calibration: bcad beside OpenCV's methods on synthetic eye-in-hand scenes.

    python bench/cameras.py [--seeds 10] [--views 5 10 20] [--noise 0.1 0.5 1] [--robot exact errors]

The scene is problems/calibration/ur5_eye_in_hand.yaml's (ur5_camera_truth.py: a UR5 with a
camera on its flange, a checkerboard of 8 x 6 inner corners on the table, views near a pose
looking down at it, each seeing every corner). Per setting (views, pixel noise, robot) and seed:

* ``exact``: the robot is its nominal DH table; ``errors``: each DH parameter is off by
  N(0, 0.2 mm) or N(0, 0.0002 rad), which the controller does not know, and with ``--encoder``
  each view's joints are off their readings by that std (degrees);
* bcad: ``bcad calibrate`` on the example problem (intrinsics, distortion, hand-eye and board
  together; with ``errors``, also the DH errors as L with the tolerance as prior, and with
  ``--encoder`` each view's joint errors as L, ``joint_noise``), without the
  importance check (it does not change the estimate);
* plain least squares: the same fit trusting the nominal robot's poses (``errors`` only: with
  ``exact`` it is bcad's own fit);
* OpenCV (a benchmark-only dependency): ``calibrateCamera`` (plumb_bob, k3 fixed at 0, as the
  truth), then ``calibrateHandEye`` with Tsai, Park, Horaud, Andreff and Daniilidis, and
  ``calibrateRobotWorldHandEye`` with Shah and Li, on the nominal robot's flange poses.

Printed per setting and method: the hand-eye rotation error (degrees) and translation error
(mm), median and 95th percentile over the seeds; for bcad and plain least squares the mean
NEES / 6 of the hand-eye (1 when its covariance is honest) and how often its 95 % ellipsoid
holds the truth. A method that returns no number on a seed counts as an infinite error there.
``--spread`` sets how far the views turn (the joints' std about the pose looking down).
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
EXAMPLE = REPO / "problems" / "calibration"
sys.path.insert(0, str(EXAMPLE))

import ur5_camera_truth as truth  # noqa: E402
from ur5_truth import NOMINAL, flange  # noqa: E402

from bcad.calibration.solve import calibrate  # noqa: E402
from bcad.compiler import compile_problem  # noqa: E402
from bcad.model import load_problem  # noqa: E402

MOUNT_NOMINAL = np.array([30.0, -20.0, 50.0, 0.0, 0.0, 1.5708])
MOUNT = [f"camera_mount.{p}" for p in ("tx", "ty", "tz", "rx", "ry", "rz")]
DH_ERRORS = (
    "      default:\n        status: X\n        dh_error: {theta: 'normal(0, 0.0002)', d: 'normal(0, 0.2)', "
    "a: 'normal(0, 0.2)', alpha: 'normal(0, 0.0002)'}\n"
)
#: the 95 % point of the chi-square distribution with 6 degrees of freedom
CHI2_6_95 = 12.5916


def errors_of(estimate: np.ndarray) -> tuple[float, float]:
    """Rotation (degrees) and translation (mm) errors of a hand-eye matrix against the truth."""
    true = truth.pose_matrix(truth.MOUNT_TRUE)
    relative = estimate[:3, :3].T @ true[:3, :3]
    angle = np.degrees(np.arccos(np.clip((np.trace(relative) - 1.0) / 2.0, -1.0, 1.0)))
    return float(angle), float(np.linalg.norm(estimate[:3, 3] - true[:3, 3]))


def scene(
    rng: np.random.Generator, views: int, noise: float, dh: dict, spread: float, encoder: float = 0.0
) -> tuple[np.ndarray, list[np.ndarray]]:
    """Views' joint readings and their pixels: the robot is where its readings say, off by
    ``encoder`` (rad, std) per joint and view."""
    q = truth.views(rng, views, spread)
    return q, [
        truth.pixels(row + rng.normal(0.0, encoder, 6) if encoder else row, dh=dh)
        + rng.normal(0.0, noise, (truth.ROWS * truth.COLUMNS, 2))
        for row in q
    ]


def bcad_fit(folder: Path, q: np.ndarray, pixels: list[np.ndarray], noise: float, carry: bool, encoder: float = 0.0):
    """bcad's hand-eye matrix, its error vector (estimate - truth, parameters) and covariance;
    ``carry``: the DH errors as L, and with ``encoder`` each view's joint errors (joint_noise)."""
    text = (
        (EXAMPLE / "ur5_eye_in_hand.yaml").read_text().replace("noise: normal(0, 0.5)", f"noise: normal(0, {noise:g})")
    )
    if carry:
        text = text.replace("      default: {status: X}\n", DH_ERRORS)
        if encoder:
            text = text.replace(
                "    data: ur5_camera_views.csv",
                f"    joint_noise: normal(0, {float(encoder)!r})\n    data: ur5_camera_views.csv",
            )
    (folder / "cell.yaml").write_text(text)
    lines = [",".join(truth.JOINTS + ["point", "u", "v"])]
    for row, uv in zip(q, pixels):
        lines += [
            ",".join([f"{v:.10f}" for v in row] + [str(i), f"{uv[i, 0]:.6f}", f"{uv[i, 1]:.6f}"])
            for i in range(len(uv))
        ]
    (folder / "ur5_camera_views.csv").write_text("\n".join(lines) + "\n")
    cal = calibrate(compile_problem(load_problem(folder / "cell.yaml")), check_samples=0)
    names = list(cal.names)
    index = [names.index(name) for name in MOUNT]
    pose = MOUNT_NOMINAL + cal.estimate[index]
    error = pose - truth.MOUNT_TRUE
    return truth.pose_matrix(pose), error, cal.covariance[np.ix_(index, index)]


def opencv_fits(cv2, q: np.ndarray, pixels: list[np.ndarray]) -> dict[str, np.ndarray]:
    """Each OpenCV method's hand-eye matrix (camera in the flange's frame, mm)."""
    objects = [truth.corners().astype(np.float32)] * len(q)
    images = [uv.astype(np.float32).reshape(-1, 1, 2) for uv in pixels]
    _, K, D, rvecs, tvecs = cv2.calibrateCamera(objects, images, truth.IMAGE_SIZE, None, None, flags=cv2.CALIB_FIX_K3)
    flanges = [flange(row, NOMINAL) for row in q]
    R_g2b = [T[:3, :3] for T in flanges]
    t_g2b = [T[:3, 3:] for T in flanges]
    R_t2c = [cv2.Rodrigues(r)[0] for r in rvecs]
    t_t2c = [np.asarray(t).reshape(3, 1) for t in tvecs]
    found = {}
    for name in ("TSAI", "PARK", "HORAUD", "ANDREFF", "DANIILIDIS"):
        R, t = cv2.calibrateHandEye(R_g2b, t_g2b, R_t2c, t_t2c, method=getattr(cv2, f"CALIB_HAND_EYE_{name}"))
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, t.ravel()
        found[name.title()] = T
    R_b2g = [T[:3, :3].T for T in flanges]
    t_b2g = [-(T[:3, :3].T @ T[:3, 3:]) for T in flanges]
    for name in ("SHAH", "LI"):
        _, _, R_g2c, t_g2c = cv2.calibrateRobotWorldHandEye(
            R_t2c, t_t2c, R_b2g, t_b2g, method=getattr(cv2, f"CALIB_ROBOT_WORLD_HAND_EYE_{name}")
        )
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R_g2c.T, -(R_g2c.T @ t_g2c).ravel()
        found[name.title()] = T
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--views", type=int, nargs="+", default=[5, 10, 20])
    parser.add_argument("--noise", type=float, nargs="+", default=[0.1, 0.5, 1.0])
    parser.add_argument("--robot", nargs="+", default=["exact", "errors"], choices=["exact", "errors"])
    parser.add_argument("--spread", type=float, default=0.45, help="the joints' std about the pose looking down (rad)")
    parser.add_argument(
        "--encoder",
        type=float,
        default=0.0,
        help="with --robot errors: the encoders' noise (degrees), given to bcad as joint_noise",
    )
    args = parser.parse_args()
    try:
        import cv2
    except ImportError:
        cv2 = None
        print("OpenCV is not installed (pip install opencv-python-headless): bcad alone")
    print(
        f"{'robot':7} {'views':>5} {'px':>4}  {'method':12} {'rot med':>8} {'rot p95':>8} {'mm med':>7} {'mm p95':>7}"
        f" {'NEES/6':>7} {'in 95%':>7}"
    )
    with tempfile.TemporaryDirectory() as scratch:
        for robot in args.robot:
            for views in args.views:
                for noise in args.noise:
                    rows: dict[str, list] = {}
                    for seed in range(args.seeds):
                        rng = np.random.default_rng([views, int(noise * 1000), seed, robot == "errors"])
                        dh = (
                            NOMINAL
                            if robot == "exact"
                            else {
                                key: np.array(value, float) + rng.normal(0.0, 0.2 if key in ("a", "d") else 0.0002, 6)
                                for key, value in NOMINAL.items()
                            }
                        )
                        encoder = np.radians(args.encoder) if robot == "errors" else 0.0
                        q, pixels = scene(rng, views, noise, dh, args.spread, encoder)
                        fits = [("bcad", robot == "errors")] + ([("least squares", False)] if robot == "errors" else [])
                        for name, carry in fits:
                            folder = Path(scratch) / f"{name}-{seed}"
                            folder.mkdir(exist_ok=True)
                            T, error, covariance = bcad_fit(folder, q, pixels, noise, carry, encoder)
                            nees = float(error @ np.linalg.solve(covariance, error))
                            rows.setdefault(name, []).append((*errors_of(T), nees / 6.0, nees <= CHI2_6_95))
                            shutil.rmtree(folder)
                        if cv2 is not None:
                            for name, T in opencv_fits(cv2, q, pixels).items():
                                rows.setdefault(name, []).append((*errors_of(T), None, None))
                    for name, found in rows.items():
                        rotation, translation = np.array([r[0] for r in found]), np.array([r[1] for r in found])
                        failed = int(np.sum(~np.isfinite(rotation) | ~np.isfinite(translation)))
                        if failed:  # a method that returned no number on some seeds: counted as the worst
                            rotation = np.where(np.isfinite(rotation), rotation, np.inf)
                            translation = np.where(np.isfinite(translation), translation, np.inf)
                        honest = (
                            f"{statistics.mean(r[2] for r in found):7.2f} {np.mean([r[3] for r in found]):7.0%}"
                            if found[0][2] is not None
                            else f"{'':7} {'':7}"
                        )
                        print(
                            f"{robot:7} {views:5d} {noise:4g}  {name:12} {np.median(rotation):8.4f} "
                            f"{np.percentile(rotation, 95):8.4f} {np.median(translation):7.3f} "
                            f"{np.percentile(translation, 95):7.3f} {honest}"
                            + (f"  (no answer on {failed} seeds)" if failed else ""),
                            flush=True,
                        )


if __name__ == "__main__":
    main()
