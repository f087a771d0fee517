"""Inequality constraints of relations, checked against closed-form geometry."""

from __future__ import annotations

import numpy as np

from bcad.relations import edge_on_face, face_on_face, point_on_face
from bcad.relations.geometry import polygon_half_planes

SQUARE = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]


def test_half_planes_of_a_square_are_its_signed_edge_distances():
    normals, offsets = polygon_half_planes(SQUARE)
    p = np.array([0.25, -0.5])
    # Distances to the edges y=-1, x=1, y=1, x=-1, negative inside.
    np.testing.assert_allclose(normals @ p - offsets, [-0.5, -0.75, -1.5, -1.25])


def test_point_on_face_is_satisfied_exactly_inside_the_polygon():
    relation = point_on_face.constraint(SQUARE)
    rng = np.random.default_rng(0)
    poses = np.zeros((2000, 6))
    poses[:, :2] = rng.uniform(-2, 2, size=(2000, 2))
    poses[:, 3:] = rng.normal(size=(2000, 3))  # a point's orientation does not matter
    inside = np.all(relation.inequalities(poses) <= 0, axis=1)
    expected = np.all(np.abs(poses[:, :2]) <= 1, axis=1)
    np.testing.assert_array_equal(inside, expected)
    assert relation.constrained == ("tz",)


def test_face_on_face_requires_the_child_face_inside_the_parent():
    small = [(-0.25, -0.25), (0.25, -0.25), (0.25, 0.25), (-0.25, 0.25)]
    relation = face_on_face.constraint(SQUARE, small)
    assert relation.inequality_count == 16
    assert relation.constrained == ("tz", "rx", "ry")
    # Centred: every vertex is 0.75 from the nearest parent edge.
    values = relation.inequalities(np.zeros((1, 6)))
    assert values.max() == -0.75
    # Rotated by 45 degrees about the normal the half-diagonal is 0.25*sqrt(2).
    rz = np.array([[0, 0, 0, 0, 0, np.pi / 4]])
    np.testing.assert_allclose(relation.inequalities(rz).max(), 0.25 * np.sqrt(2) - 1.0)
    # Slid by tx = 0.8: the far vertices are 0.05 outside the edge x = 1.
    slid = np.array([[0.8, 0, 0, 0, 0, 0]])
    np.testing.assert_allclose(relation.inequalities(slid).max(), 0.05)


def test_edge_on_face_checks_both_ends():
    relation = edge_on_face.constraint(SQUARE, edge_length=1.5)
    along_x = np.array([[-0.5, 0, 0, 0, 0, 0]])
    assert np.all(relation.inequalities(along_x) <= 0)
    too_far = np.array([[0.0, 0, 0, 0, 0, 0]])  # the end at x = 1.5 is outside
    np.testing.assert_allclose(relation.inequalities(too_far).max(), 0.5)
