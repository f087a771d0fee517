"""SE(3) conventions of bcad, written down once.

* A pose is a 6-vector ``(tx, ty, tz, rx, ry, rz)``; its homogeneous matrix is
  ``T = [[R, t], [0, 1]]`` with ``t = (tx, ty, tz)`` and URDF's rpy rotation
  ``R = Rz(rz) Ry(ry) Rx(rx)``.
* ``T_ab`` maps coordinates in frame b to frame a; chains compose left to
  right, ``T_ac = T_ab T_bc`` (Eq. 1 of the 2000 paper).

All functions take arrays with any leading batch shape.
"""

from __future__ import annotations

import numpy as np

from bcad.numerics.angles import wrap_angle  # noqa: F401 (re-exported: the kinematics' convention)


def rotation_about_axis(axis: int, angle: np.ndarray | float) -> np.ndarray:
    """Rotation matrix about coordinate axis 0 (x), 1 (y) or 2 (z), shape (..., 3, 3)."""
    angle = np.asarray(angle, dtype=float)
    c, s = np.cos(angle), np.sin(angle)
    i, j = (axis + 1) % 3, (axis + 2) % 3
    R = np.zeros(angle.shape + (3, 3))
    R[..., axis, axis] = 1.0
    R[..., i, i] = c
    R[..., j, j] = c
    R[..., j, i] = s
    R[..., i, j] = -s
    return R


def rpy_to_matrix(rpy: np.ndarray) -> np.ndarray:
    """R = Rz(rz) Ry(ry) Rx(rx) for ``rpy = (rx, ry, rz)``, shape (..., 3, 3)."""
    rpy = np.asarray(rpy, dtype=float)
    return np.ascontiguousarray(np.moveaxis(rpy_entries(rpy), (0, 1), (-2, -1)))


def rpy_entries(rpy: np.ndarray) -> np.ndarray:
    """The entries of R = Rz(rz) Ry(ry) Rx(rx), shape (3, 3, ...): ``[i, j]`` is R_ij over the
    batch (the product written out, a third of the work of three stacked 3 x 3 products)::

        R = [[cz cy,  cz sy sx - sz cx,  cz sy cx + sz sx],
             [sz cy,  sz sy sx + cz cx,  sz sy cx - cz sx],
             [  -sy,             cy sx,             cy cx]]
    """
    rpy = np.asarray(rpy, dtype=float)
    cx, cy, cz = np.cos(rpy[..., 0]), np.cos(rpy[..., 1]), np.cos(rpy[..., 2])
    sx, sy, sz = np.sin(rpy[..., 0]), np.sin(rpy[..., 1]), np.sin(rpy[..., 2])
    czsy, szsy = cz * sy, sz * sy
    R = np.empty((3, 3) + cx.shape)
    R[0, 0], R[0, 1], R[0, 2] = cz * cy, czsy * sx - sz * cx, czsy * cx + sz * sx
    R[1, 0], R[1, 1], R[1, 2] = sz * cy, szsy * sx + cz * cx, szsy * cx - cz * sx
    R[2, 0], R[2, 1], R[2, 2] = -sy, cy * sx, cy * cx
    return R


def matrix_to_rpy(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rpy_to_matrix`, with ry in [-pi/2, pi/2], shape (..., 3)."""
    R = np.asarray(R, dtype=float)
    rx = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    ry = np.arctan2(-R[..., 2, 0], np.hypot(R[..., 0, 0], R[..., 1, 0]))
    rz = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return np.stack([rx, ry, rz], axis=-1)


def matrix_to_rpy_exact(R: np.ndarray) -> np.ndarray:
    """rpy of one rotation that reproduces it to rounding, gimbal lock included.

    :func:`matrix_to_rpy` takes rx and rz from entries that vanish as cos(ry)
    does, so near ry = +-pi/2 they lose digits (and the matrix they rebuild is
    off by up to ~1e-16 / cos(ry)). Here rz comes from those entries (any rz
    will do at the lock) and rx from what Rz(rz) Ry(ry) leaves:
    Rx(rx) = Ry(ry)^T Rz(rz)^T R, which absorbs rz's error.
    """
    R = np.asarray(R, dtype=float)
    ry = float(np.arctan2(-R[2, 0], np.hypot(R[0, 0], R[1, 0])))
    rz = float(np.arctan2(R[1, 0], R[0, 0])) if np.hypot(R[0, 0], R[1, 0]) > 1e-300 else 0.0
    rest = rotation_about_axis(1, ry).T @ rotation_about_axis(2, rz).T @ R
    rx = float(np.arctan2(rest[2, 1] - rest[1, 2], rest[1, 1] + rest[2, 2]))
    return np.array([rx, ry, rz])


def pose_to_matrix(pose: np.ndarray) -> np.ndarray:
    """Homogeneous matrix of a pose 6-vector, shape (..., 4, 4)."""
    pose = np.asarray(pose, dtype=float)
    T = np.zeros(pose.shape[:-1] + (4, 4))
    T[..., :3, :3] = rpy_to_matrix(pose[..., 3:])
    T[..., :3, 3] = pose[..., :3]
    T[..., 3, 3] = 1.0
    return T


def matrix_to_pose(T: np.ndarray) -> np.ndarray:
    """Pose 6-vector of a homogeneous matrix, shape (..., 6)."""
    T = np.asarray(T, dtype=float)
    return np.concatenate([T[..., :3, 3], matrix_to_rpy(T[..., :3, :3])], axis=-1)


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform, shape (..., 4, 4)."""
    T = np.asarray(T, dtype=float)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out = np.zeros_like(T)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def translation(vector: np.ndarray) -> np.ndarray:
    """Pure translation matrix."""
    T = np.eye(4)
    T[:3, 3] = vector
    return T
