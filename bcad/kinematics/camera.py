"""Pinhole cameras with OpenCV's distortion models, vectorised over points and parameter samples.

Conventions (OpenCV's ``projectPoints``, ROS's optical frame): a point (X, Y, Z) in the camera's
optical frame (x right, y down, z forward, out of the lens) is seen at the normalised image
point x = X / Z, y = Y / Z, distorted by

    r^2 = x^2 + y^2,
    radial = (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6),
    x' = x radial + 2 p1 x y + p2 (r^2 + 2 x^2),
    y' = y radial + p1 (r^2 + 2 y^2) + 2 p2 x y,

and lands at the pixel u = fx x' + cx, v = fy y' + cy (u to the right, v down, the centre of the
top-left pixel at (0, 0)). ``plumb_bob`` (Brown-Conrady) has k1, k2, p1, p2, k3 (k4 = k5 = k6 = 0),
``rational_polynomial`` all eight: ROS camera_info's ``distortion_model`` names, with the
coefficients in OpenCV's (and camera_info's ``D``) order.
"""

from __future__ import annotations

import numpy as np

#: the intrinsic parameters, in the order of a camera's parameter vector
INTRINSICS = ("fx", "fy", "cx", "cy")
#: the distortion coefficients of each model, in OpenCV's order
DISTORTION = {
    "plumb_bob": ("k1", "k2", "p1", "p2", "k3"),
    "rational_polynomial": ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
}
#: a point nearer the lens plane than this (in the camera's length units) is not seen
MIN_DEPTH = 1e-9


def camera_parameters(model: str) -> tuple[str, ...]:
    """The names of a camera's parameter vector: the intrinsics, then the model's coefficients."""
    return INTRINSICS + DISTORTION[model]


def project(points: np.ndarray, parameters: np.ndarray, model: str = "plumb_bob") -> np.ndarray:
    """Pixels (..., 2) of points (..., 3) in the optical frame, through the camera ``parameters``
    (..., 4 + coefficients) of :func:`camera_parameters`'s order (broadcast against the points'
    leading axes). A point at or behind the lens plane (Z <= MIN_DEPTH) projects to NaN."""
    points = np.asarray(points, dtype=float)
    parameters = np.asarray(parameters, dtype=float)
    names = camera_parameters(model)
    if parameters.shape[-1] != len(names):
        raise ValueError(f"{len(names)} camera parameters expected ({', '.join(names)}), got {parameters.shape[-1]}")
    fx, fy, cx, cy = (parameters[..., k] for k in range(4))
    k1, k2, p1, p2, k3 = (parameters[..., 4 + k] for k in range(5))
    depth = points[..., 2]
    seen = depth > MIN_DEPTH
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.where(seen, points[..., 0] / np.where(seen, depth, 1.0), np.nan)
        y = np.where(seen, points[..., 1] / np.where(seen, depth, 1.0), np.nan)
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    if model == "rational_polynomial":
        k4, k5, k6 = (parameters[..., 9 + k] for k in range(3))
        radial = radial / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xy = x * y
    distorted_x = x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * x * x)
    distorted_y = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * xy
    return np.stack([fx * distorted_x + cx, fy * distorted_y + cy], axis=-1)


def checkerboard_points(rows: int, columns: int, square: float) -> np.ndarray:
    """The inner corners of a checkerboard in its own frame (rows x columns, 3): corner id
    i = r columns + c at (c square, r square, 0), OpenCV's object points for
    ``findChessboardCorners`` with pattern size (columns, rows)."""
    r, c = np.divmod(np.arange(rows * columns), columns)
    return np.stack([c * square, r * square, np.zeros(rows * columns)], axis=1).astype(float)
