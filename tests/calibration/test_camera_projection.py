"""The camera model against OpenCV's projectPoints (an independent implementation of the same
conventions), on random cameras, distortions and points."""

from __future__ import annotations

import numpy as np
import pytest

from bcad.kinematics.camera import camera_parameters, checkerboard_points, project

cv2 = pytest.importorskip("cv2")


def _random_camera(rng, model):
    intrinsics = [rng.uniform(300, 1500), rng.uniform(300, 1500), rng.uniform(200, 700), rng.uniform(150, 500)]
    coefficients = [
        rng.normal(0, 0.2),
        rng.normal(0, 0.05),
        rng.normal(0, 0.002),
        rng.normal(0, 0.002),
        rng.normal(0, 0.02),
    ]
    if model == "rational_polynomial":
        coefficients += [rng.normal(0, 0.1), rng.normal(0, 0.02), rng.normal(0, 0.01)]
    return np.array(intrinsics + coefficients)


@pytest.mark.parametrize("model", ["plumb_bob", "rational_polynomial"])
def test_pixels_are_opencvs_project_points(model):
    rng = np.random.default_rng(7)
    for _ in range(20):
        parameters = _random_camera(rng, model)
        points = np.column_stack([rng.uniform(-0.4, 0.4, 50), rng.uniform(-0.3, 0.3, 50), rng.uniform(0.5, 2.0, 50)])
        matrix = np.array([[parameters[0], 0, parameters[2]], [0, parameters[1], parameters[3]], [0, 0, 1.0]])
        expected, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), matrix, parameters[4:])
        np.testing.assert_allclose(project(points, parameters, model), expected[:, 0], rtol=0, atol=1e-9)


def test_parameters_broadcast_over_samples_and_points_behind_the_lens_are_nan():
    rng = np.random.default_rng(1)
    cameras = np.stack([_random_camera(rng, "plumb_bob") for _ in range(3)])  # (3, 9)
    points = np.array([[0.1, -0.2, 1.0], [0.0, 0.0, -1.0], [0.3, 0.1, 0.0]])
    pixels = project(points[None], cameras[:, None], "plumb_bob")  # (3 samples, 3 points, 2)
    assert pixels.shape == (3, 3, 2)
    for s in range(3):
        np.testing.assert_allclose(pixels[s, 0], project(points[0], cameras[s]))
    assert np.isnan(pixels[:, 1:]).all()
    assert camera_parameters("plumb_bob") == ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")


def test_checkerboard_corners_are_opencvs_object_points():
    """Ids run along a row first: OpenCV's pattern size (columns, rows) and its object points."""
    points = checkerboard_points(rows=4, columns=6, square=0.025)
    expected = np.zeros((24, 3))
    expected[:, :2] = np.mgrid[0:6, 0:4].T.reshape(-1, 2) * 0.025
    np.testing.assert_allclose(points, expected)
