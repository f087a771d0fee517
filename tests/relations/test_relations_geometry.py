"""The relations against brute-force geometry: for random poses, the signed distances
bcad computes agree with dense samples of the entities (rims, surfaces, segments), and the
tempered satisfaction tends to the indicator as T -> 0."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bcad import relations
from bcad.kinematics.se3 import pose_to_matrix
from bcad.relations import geometry

RNG = np.random.default_rng(11)
SQUARE = [(-1.0, -0.5), (1.0, -0.5), (1.0, 0.5), (-1.0, 0.5)]
PENTAGON = [(math.cos(a), math.sin(a)) for a in np.linspace(0, 2 * math.pi, 6)[:-1]]


def _poses(count: int, translation: float, rotation: float, centre=(0.0, 0.0, 0.0)) -> np.ndarray:
    poses = np.zeros((count, 6))
    poses[:, :3] = np.asarray(centre) + RNG.uniform(-translation, translation, (count, 3))
    poses[:, 3:] = RNG.uniform(-rotation, rotation, (count, 3))
    return poses


def _inside_convex(polygon, points: np.ndarray) -> np.ndarray:
    """Brute force: a point is inside a counter-clockwise polygon when every edge's cross product is >= 0."""
    vertices = np.asarray(polygon)
    inside = np.ones(len(points), dtype=bool)
    for a, b in zip(vertices, np.roll(vertices, -1, axis=0)):
        cross = (b[0] - a[0]) * (points[:, 1] - a[1]) - (b[1] - a[1]) * (points[:, 0] - a[0])
        inside &= cross >= 0
    return inside


def _signed_distance_outside_polygon(polygon, points: np.ndarray) -> np.ndarray:
    """Brute force: for each edge, the largest signed distance of the points beyond its line."""
    vertices = np.asarray(polygon)
    out = []
    for a, b in zip(vertices, np.roll(vertices, -1, axis=0)):
        edge = b - a
        normal = np.array([edge[1], -edge[0]]) / np.linalg.norm(edge)
        out.append(np.max((points - a) @ normal))
    return np.array(out)


def _transformed(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    T = pose_to_matrix(pose)
    return points @ T[:3, :3].T + T[:3, 3]


def _check_booleans(constraint, poses, brute_inside, margin=1e-6):
    values = constraint.inequalities(poses)
    worst = values.max(axis=1)
    clear = np.abs(worst) > margin
    assert clear.sum() > 0.5 * len(poses)
    assert np.array_equal((worst <= 0)[clear], brute_inside[clear])
    both = (worst <= 0).sum(), (~(worst <= 0)).sum()
    assert min(both) > 0.05 * len(poses), "the poses should straddle the boundary"


def test_point_on_edge():
    c = relations.point_on_edge.constraint(2.0)
    assert c.constrained == ("ty", "tz")
    poses = _poses(400, 1.5, 1.0, centre=(1.0, 0.0, 0.0))
    segment = np.column_stack([np.linspace(0, 2, 20001), np.zeros(20001), np.zeros(20001)])
    inside = []
    for pose in poses:
        p = pose[:3]
        line = math.hypot(p[1], p[2])
        nearest = np.min(np.linalg.norm(segment - p, axis=1))
        inside.append(nearest <= line + 1e-6)  # the nearest point of the segment is the line's
    _check_booleans(c, poses, np.array(inside), margin=1e-3)
    np.testing.assert_allclose(c.inequalities(poses), np.column_stack([-poses[:, 0], poses[:, 0] - 2.0]))


def test_edge_on_edge():
    c = relations.edge_on_edge.constraint(2.0, 1.0)
    assert c.constrained == ("ty", "tz", "ry", "rz")
    poses = _poses(400, 2.0, 0.5, centre=(0.5, 0.0, 0.0))
    inside = []
    for pose in poses:
        child = _transformed(pose, np.column_stack([np.linspace(0, 1, 4001), np.zeros(4001), np.zeros(4001)]))
        inside.append(np.any((child[:, 0] >= 0) & (child[:, 0] <= 2.0)))  # the projections on x overlap
    _check_booleans(c, poses, np.array(inside), margin=1e-3)


def test_sphere_on_face():
    c = relations.sphere_on_face.constraint(PENTAGON)
    poses = _poses(400, 1.2, 3.0)
    _check_booleans(c, poses, _inside_convex(PENTAGON, poses[:, :2]))


def test_cylinder_on_face_is_the_rim_inside_the_polygon():
    radius = 0.3
    c = relations.cylinder_on_face.constraint(SQUARE, radius)
    assert c.constrained == ("tz", "rx", "ry")
    poses = _poses(300, 0.9, 0.6)
    angles = np.linspace(0, 2 * math.pi, 3601)
    rim = radius * np.column_stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)])
    values = c.inequalities(poses)
    for pose, value in zip(poses, values):
        projected = _transformed(pose, rim)[:, :2]
        # Per edge, the support function is the rim's farthest reach beyond it (dense rim: 1e-6 R).
        np.testing.assert_allclose(value, _signed_distance_outside_polygon(SQUARE, projected), atol=1e-6)
    inside = np.array([_inside_convex(SQUARE, _transformed(p, rim)[:, :2]).all() for p in poses])
    _check_booleans(c, poses, inside)


def test_sphere_in_sphere():
    c = relations.sphere_in_sphere.constraint(1.0, 0.9)
    assert c.constrained == ()
    poses = _poses(400, 0.12, 3.0)
    u = RNG.normal(size=(4000, 3))
    surface = 0.9 * u / np.linalg.norm(u, axis=1, keepdims=True)
    reach = np.array([np.max(np.linalg.norm(surface + p[:3], axis=1)) for p in poses])
    np.testing.assert_allclose(c.inequalities(poses)[:, 0], reach - 1.0, atol=2e-3)
    _check_booleans(c, poses, reach <= 1.0, margin=3e-3)


@pytest.mark.parametrize("inner", [0.0, 0.2])
def test_point_and_sphere_in_cylinder(inner):
    c = (
        relations.point_in_cylinder.constraint(0.5, 2.0)
        if inner == 0.0
        else relations.sphere_in_cylinder.constraint(0.5, 2.0, inner)
    )
    poses = _poses(500, 0.6, 3.0, centre=(0.0, 0.0, 1.0))
    poses[:, 2] = RNG.uniform(-0.3, 2.3, len(poses))
    if inner == 0.0:
        points = [p[None, :3] for p in poses]
    else:
        u = RNG.normal(size=(3000, 3))
        sphere = inner * u / np.linalg.norm(u, axis=1, keepdims=True)
        points = [sphere + p[:3] for p in poses]
    inside = np.array([np.all((np.hypot(q[:, 0], q[:, 1]) <= 0.5) & (q[:, 2] >= 0) & (q[:, 2] <= 2.0)) for q in points])
    _check_booleans(c, poses, inside, margin=5e-3 if inner else 1e-9)


def test_peg_in_hole_against_the_peg_surface():
    """Brute force on the peg's surface: points of its side (72 lines x 400 steps) from its end up
    to the hole's mouth plane all within R_hole of the hole's axis, the end's rim above the bottom,
    the end below the mouth."""
    hole_radius, depth, peg_radius = 5.0, 20.0, 4.95
    c = relations.cylinder_in_cylinder.constraint(hole_radius, depth, peg_radius)
    poses = _poses(500, 0.06, 0.01, centre=(0.0, 0.0, 10.0))
    poses[:, 2] = RNG.uniform(-0.5, 20.5, len(poses))
    phi = np.linspace(0, 2 * math.pi, 720, endpoint=False)
    worst_gap = []
    inside = []
    values = c.inequalities(poses)
    for pose, value in zip(poses, values):
        T = pose_to_matrix(pose)
        end, u1, u2, axis = T[:3, 3], T[:3, 0], T[:3, 1], T[:3, 2]
        rim = end + peg_radius * (np.cos(phi)[:, None] * u1 + np.sin(phi)[:, None] * u2)
        if axis[2] <= 0:
            inside.append(False)
            continue
        lengths = (depth - rim[:, 2]) / axis[2]  # along each surface line, up to the mouth plane
        s = np.linspace(0.0, 1.0, 400)[:, None] * np.maximum(lengths, 0.0)[None, :]
        surface = rim[None] + s[..., None] * axis
        radial = np.hypot(surface[..., 0], surface[..., 1])
        inside.append(bool(radial.max() <= hole_radius and rim[:, 2].min() >= 0.0 and end[2] <= depth))
        if end[2] <= depth and lengths.min() > 0:
            # The analytic maximum over the surface is that of its two boundary curves.
            worst_gap.append(max(value[0], value[1]) + hole_radius - radial.max())
    _check_booleans(c, poses, np.array(inside), margin=1e-4)
    assert np.max(np.abs(worst_gap)) < 1e-4  # the brute force's own resolution: 720 lines


@pytest.mark.parametrize(
    ("kind", "shortfall"), [("first-harmonic-dominant", 1e-12), ("through-the-axis", 1e-12), ("two-maxima", 1e-3)]
)
def test_the_largest_radial_distance_of_an_ellipse_is_the_brute_force_maximum(kind, shortfall):
    """max over phi of |A + r (cos phi B + sin phi C)| against 20001 angles: never above their best
    by more than the grid's resolution, nor below it by more than ``shortfall`` of it. Exact where
    the first harmonic dominates (a peg's slightly tilted rim, off the hole's axis) and on the
    axis; with two maxima either side of the first harmonic's (its amplitude just below 4 times
    the second's, phi shifted off the grid), within the 5e-4 the docstring states."""
    rng = np.random.default_rng(0)
    count, radius = 2000, 4.95
    if kind == "two-maxima":
        k = rng.uniform(0.8, 0.99, count)  # an ellipse's axes r and k r
        second = radius**2 * (1 - k**2) / 2
        first = second * rng.uniform(3.6, 4.0, count)
        A = np.stack([np.zeros(count), -first / (2 * radius * k)])  # the first harmonic against the second
        shift, turn = rng.uniform(-math.pi, math.pi, (2, count))
        B0, C0 = np.stack([np.ones(count), np.zeros(count)]), np.stack([np.zeros(count), k])
        B, C = np.cos(shift) * B0 + np.sin(shift) * C0, -np.sin(shift) * B0 + np.cos(shift) * C0
        cos, sin = np.cos(turn), np.sin(turn)
        A, B, C = (np.stack([cos * V[0] - sin * V[1], sin * V[0] + cos * V[1]]) for V in (A, B, C))
    elif kind == "first-harmonic-dominant":
        turn, squash = rng.uniform(-math.pi, math.pi, count), rng.normal(0.0, 0.01, (2, count))
        B = np.stack([np.cos(turn), np.sin(turn)]) * (1 - squash[0] ** 2)
        C = np.stack([-np.sin(turn), np.cos(turn)]) * (1 - squash[1] ** 2)
        A = rng.normal(0.0, 0.05, (2, count))
        first = 2 * radius * np.hypot(np.sum(A * B, axis=0), np.sum(A * C, axis=0))
        second = radius**2 * np.hypot((np.sum(B * B, axis=0) - np.sum(C * C, axis=0)) / 2, np.sum(B * C, axis=0))
        assert np.mean(first > 5 * second) > 0.95
    else:
        B, C = rng.normal(size=(2, count)), rng.normal(size=(2, count))
        A = np.zeros((2, count))
    found = geometry.max_radial_on_circle(A, B, C, radius)
    phi = np.linspace(0.0, 2.0 * math.pi, 20001)[None, :, None]
    brute = np.empty(count)
    for start in range(0, count, 250):
        part = slice(start, start + 250)
        points = A[:, None, part] + radius * (np.cos(phi) * B[:, None, part] + np.sin(phi) * C[:, None, part])
        brute[part] = np.hypot(points[0], points[1]).max(axis=0)
    assert np.min((found - brute) / brute) > -shortfall
    assert np.max((found - brute) / brute) < 1e-7  # 20001 angles: 1.6e-4 rad apart


def test_point_on_sphere_coordinates_round_trip_and_measure_the_surface_distance():
    t = RNG.normal(size=(3, 500)) * 3
    coordinates = geometry.spherical_coordinates(t, 2.0)
    np.testing.assert_allclose(coordinates[2], np.linalg.norm(t, axis=0) - 2.0, atol=1e-12)
    np.testing.assert_allclose(geometry.cartesian_from_spherical(coordinates, 2.0), t, atol=1e-12)


@pytest.mark.parametrize(
    "constraint",
    [
        relations.point_on_edge.constraint(2.0),
        relations.edge_on_edge.constraint(2.0, 1.0),
        relations.sphere_on_face.constraint(PENTAGON),
        relations.cylinder_on_face.constraint(SQUARE, 0.3),
        relations.sphere_in_sphere.constraint(1.0, 0.9),
        relations.sphere_in_cylinder.constraint(0.5, 2.0, 0.2),
        relations.cylinder_in_cylinder.constraint(5.0, 20.0, 4.95),
    ],
    ids=lambda c: c.kind,
)
def test_tempering_tends_to_the_indicator(constraint):
    poses = _poses(300, 1.0, 0.3, centre=(0.5, 0.0, 0.5))
    from bcad.kinematics.se3 import rpy_to_matrix

    columns = np.transpose(rpy_to_matrix(poses[:, 3:]), (2, 1, 0))
    satisfied = np.all(constraint.inequalities(poses) <= 0, axis=1)
    exact = constraint.log_satisfaction(columns, poses[:, :3].T, 0.0)
    assert np.array_equal(np.isfinite(exact), satisfied) and np.all(exact[satisfied] == 0.0)
    previous = None
    for temperature in (1.0, 1e-2, 1e-4, 1e-8):
        relaxed = constraint.log_satisfaction(columns, poses[:, :3].T, temperature)
        assert np.all(relaxed[satisfied] == 0.0) and np.all(relaxed[~satisfied] < 0.0)
        if previous is not None:
            assert np.all(relaxed <= previous)  # colder is stricter
        previous = relaxed
    # Sect. 4.2.1: outside, -(d / w)^2 / T summed over the violated inequalities, which -> -inf as T -> 0.
    excess = np.maximum(constraint.inequalities(poses), 0.0) / constraint.widths
    np.testing.assert_allclose(previous, -np.sum(excess**2, axis=1) / 1e-8, rtol=1e-9)
