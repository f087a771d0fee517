"""The "true" eye-in-hand cell of the camera calibration example and its detections.

A UR5 (its nominal DH table: the robot is taken as exact here) carries a camera on its flange
and looks at a checkerboard lying on the table. The truth: the camera's mount on the flange
(link_6), its intrinsics and plumb_bob distortion, and the board's placement. Each view is a
joint configuration near a pose looking down at the board; a view is kept when every inner
corner lands inside the image. The pixels are the pinhole model with Brown-Conrady distortion
written out here (x = X/Z, y = Y/Z, r^2 = x^2 + y^2, radial 1 + k1 r^2 + k2 r^4 + k3 r^6, the
tangential terms p1, p2: OpenCV's projectPoints), plus Gaussian noise.

    python problems/calibration/ur5_camera_truth.py   # rewrites ur5_camera_views.csv (seed 2000)
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ur5_truth import JOINTS, NOMINAL, _rx, _ry, _rz, _translation, flange  # noqa: E402

#: the camera's optical frame on the flange (mm, rad: tx ty tz rx ry rz, R = Rz Ry Rx), true
MOUNT_TRUE = np.array([32.0, -18.0, 55.0, 0.012, -0.008, 1.5708 + 0.02])
#: fx, fy, cx, cy (px), then k1, k2, p1, p2, k3
CAMERA_TRUE = np.array([1105.0, 1098.0, 652.0, 508.0, -0.12, 0.09, 0.0008, -0.0005, 0.0])
IMAGE_SIZE = (1280, 1024)
ROWS, COLUMNS, SQUARE = 6, 8, 25.0  # inner corners, mm
#: where the robot looks down from, and how far the board lies below the camera there
HOME = np.array([0.0, -1.75, 1.9, -1.72, -1.5708, 0.0])
DEPTH = 420.0
NOISE = 0.5  # px


def pose_matrix(pose: np.ndarray) -> np.ndarray:
    tx, ty, tz, rx, ry, rz = pose
    return _translation(tx, ty, tz) @ _rz(rz) @ _ry(ry) @ _rx(rx)


def corners() -> np.ndarray:
    r, c = np.divmod(np.arange(ROWS * COLUMNS), COLUMNS)
    return np.stack([c * SQUARE, r * SQUARE, np.zeros(ROWS * COLUMNS)], axis=1)


def camera_in_world(q: np.ndarray, dh: dict = NOMINAL) -> np.ndarray:
    return flange(q, dh) @ pose_matrix(MOUNT_TRUE)


def board_in_world() -> np.ndarray:
    """The board centred under the camera at HOME, DEPTH in front of it, turned a little."""
    centre = _translation(-(COLUMNS - 1) * SQUARE / 2, -(ROWS - 1) * SQUARE / 2, 0.0)
    return camera_in_world(HOME) @ _translation(0.0, 0.0, DEPTH) @ _rz(0.1) @ _rx(0.05) @ centre


def pixels(q: np.ndarray, camera: np.ndarray = CAMERA_TRUE, dh: dict = NOMINAL) -> np.ndarray:
    """The board's corners in the image of view q (points, 2), noise-free, seen by a robot whose
    DH table is ``dh`` (the board placed as the nominal robot sees it)."""
    board = np.linalg.inv(camera_in_world(q, dh)) @ board_in_world()
    p = (board @ np.column_stack([corners(), np.ones(ROWS * COLUMNS)]).T)[:3]
    in_front = p[2] > 0  # a point behind the lens is not seen (its x/z, y/z would land in the image mirrored)
    x, y = np.where(in_front, p[0] / p[2], np.nan), np.where(in_front, p[1] / p[2], np.nan)
    fx, fy, cx, cy, k1, k2, p1, p2, k3 = camera
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.column_stack([fx * xd + cx, fy * yd + cy])


def views(rng: np.random.Generator, count: int, spread: float = 0.25) -> np.ndarray:
    """Joint configurations near HOME whose image holds every corner, in front of the lens, with a
    margin of 20 px."""
    found = []
    while len(found) < count:
        q = HOME + rng.normal(0.0, spread, 6)
        uv = pixels(q)
        if np.all((uv > 20) & (uv < np.array(IMAGE_SIZE) - 20)):
            found.append(q)
    return np.array(found)


def turning_views(rng: np.random.Generator, count: int) -> np.ndarray:
    """A degenerate set: only joints 1 and 6 move, so every view turns the camera about a vertical
    axis (the camera's height over the board, and with it its mount's z and the focal lengths, is
    seen only through the prior)."""
    found = []
    while len(found) < count:
        q = HOME.copy()
        q[0] += rng.uniform(-0.15, 0.15)
        q[5] += rng.uniform(-1.0, 1.0)
        uv = pixels(q)
        if np.all((uv > 20) & (uv < np.array(IMAGE_SIZE) - 20)):
            found.append(q)
    return np.array(found)


def write_csv(
    path: Path, count: int = 15, seed: int = 2000, noise: float = NOISE, degenerate: bool = False, dh: dict = NOMINAL
) -> None:
    """The detections of ``count`` views (``degenerate``: :func:`turning_views`) by a robot whose DH
    table is ``dh`` (default: exact, the nominal one)."""
    rng = np.random.default_rng(seed)
    lines = [",".join(JOINTS + ["point", "u", "v"])]
    for q in (turning_views if degenerate else views)(rng, count):
        uv = pixels(q, dh=dh) + rng.normal(0.0, noise, (ROWS * COLUMNS, 2))
        lines += [
            ",".join([f"{v:.10f}" for v in q] + [str(i), f"{uv[i, 0]:.6f}", f"{uv[i, 1]:.6f}"])
            for i in range(ROWS * COLUMNS)
        ]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


if __name__ == "__main__":
    write_csv(Path(__file__).with_name("ur5_camera_views.csv"))
