"""Geometric relations compiled to equality and inequality constraints.

A relation is a link between two entity frames whose pose Q (child entity
frame in parent entity frame, after the relation's frame shifts) must satisfy
equality constraints ``E(Q) = 0`` (which parameters the relation constrains)
and inequality constraints ``C(Q) <= 0`` (Sect. 3.1 of the 2000 paper, item
2). Inequalities are signed distances in length units (positive outside),
evaluated on batches of transforms, so that the tempered relaxation of
Sect. 4.2.1 can widen them smoothly; each has a width, the scale of that
relaxation (Fig. 2). Every relation's geometry is derived in the README
("Relations"); the tests check each against a brute-force computation.

Transforms arrive as ``columns`` (``columns[j]``: column j of the rotations,
shape (3, *batch)) and ``translations`` (3, *batch).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bcad.kinematics.se3 import rpy_to_matrix
from bcad.tempering import relaxed_log_indicator


def polygon_half_planes(polygon: list[tuple[float, float]]) -> tuple[np.ndarray, np.ndarray]:
    """Outward unit normals (k, 2) and offsets (k,) of a counter-clockwise convex polygon.

    A point p is inside iff ``normals @ p - offsets <= 0`` for every edge.
    """
    vertices = np.asarray(polygon, dtype=float)
    edges = np.roll(vertices, -1, axis=0) - vertices
    normals = np.column_stack([edges[:, 1], -edges[:, 0]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    offsets = np.einsum("ij,ij->i", normals, vertices)
    return normals, offsets


def _polygon_widths(polygon, normals: np.ndarray) -> np.ndarray:
    """The polygon's width along each edge normal."""
    projections = normals @ np.asarray(polygon, dtype=float).T
    return projections.max(axis=1) - projections.min(axis=1)


def _radial(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.sqrt(x * x + y * y)


@dataclass(frozen=True)
class RelationConstraint:
    """Constraints of one relation on its link's pose Q: the parameters its equalities set to 0
    (``constrained``) and ``widths.size`` inequalities (subclasses' :meth:`inequalities_from`)."""

    kind: str
    constrained: tuple[str, ...]
    widths: np.ndarray  # (count,): each inequality's tempering scale

    @property
    def inequality_count(self) -> int:
        return int(self.widths.size)

    #: the relation's pose is in spherical coordinates (:func:`spherical_coordinates`), not Cartesian
    spherical = False

    def inequalities_from(self, columns, translations: np.ndarray) -> np.ndarray:
        """Signed distances C(Q), shape (count, *batch); inside when all <= 0."""
        return np.zeros((0,) + translations.shape[1:])

    def inequalities(self, poses: np.ndarray) -> np.ndarray:
        """Signed distances for poses (N, 6) (in the relation's coordinates), shape (N, count)."""
        poses = np.atleast_2d(poses)
        translations = poses[:, :3].T
        if self.spherical:
            translations = cartesian_from_spherical(translations, self.radius)
        R = rpy_to_matrix(poses[:, 3:])
        columns = np.transpose(R, (2, 1, 0))
        return self.inequalities_from(columns, translations).T

    def log_satisfaction(self, columns, translations: np.ndarray, temperature: float) -> np.ndarray:
        """log p(H | Q): 0 or -inf at T = 0, relaxed as in Sect. 4.2.1 for T > 0; shape (*batch)."""
        if self.inequality_count == 0:
            return np.zeros(translations.shape[1:])
        distances = self.inequalities_from(columns, translations)
        widths = self.widths.reshape((-1,) + (1,) * (distances.ndim - 1))
        return relaxed_log_indicator(distances, widths, temperature).sum(axis=0)


@dataclass(frozen=True)
class PolygonContact(RelationConstraint):
    """Points of the child (``points``, in its frame) inside the parent face's polygon, projected
    on its plane: one inequality per point and edge, ``normals @ xy - offsets``."""

    points: np.ndarray = None  # (p, 3)
    normals: np.ndarray = None  # (k, 2)
    offsets: np.ndarray = None  # (k,)

    def inequalities_from(self, columns, translations):
        batch = translations.shape[1:]
        out = np.empty((len(self.points), len(self.offsets)) + batch)
        for index, point in enumerate(self.points):
            xy = translations[:2] + sum(columns[j][:2] * point[j] for j in range(3) if point[j] != 0.0)
            out[index] = np.tensordot(self.normals, xy, axes=(1, 0)) - self.offsets.reshape((-1,) + (1,) * len(batch))
        return out.reshape((-1,) + batch)


@dataclass(frozen=True)
class DiscOnFace(PolygonContact):
    """A disc of ``radius`` centred on the child frame's origin, normal to its z axis, inside the
    parent polygon: along each edge normal n (in the plane), the disc's projection reaches
    n . c + radius sqrt(1 - (n . a)^2), c its centre and a its axis (the support function of a
    disc; exact at any tilt)."""

    radius: float = 0.0

    def inequalities_from(self, columns, translations):
        batch = translations.shape[1:]
        axis = columns[2]
        shape = (-1,) + (1,) * len(batch)
        along = np.tensordot(self.normals, axis[:2], axes=(1, 0))  # n . a, (k, *batch)
        reach = self.radius * np.sqrt(np.maximum(1.0 - along * along, 0.0))
        return np.tensordot(self.normals, translations[:2], axes=(1, 0)) - self.offsets.reshape(shape) + reach


@dataclass(frozen=True)
class OnSegment(RelationConstraint):
    """The child's origin between the parent edge's ends: -tx <= 0 and tx - length <= 0."""

    length: float = 0.0

    def inequalities_from(self, columns, translations):
        return np.stack([-translations[0], translations[0] - self.length])


@dataclass(frozen=True)
class OverlappingSegments(RelationConstraint):
    """The child edge (from its origin along its x axis, ``child_length``) overlaps the parent
    edge [0, ``length``] along x: its start before the parent's end, its end after the parent's start."""

    length: float = 0.0
    child_length: float = 0.0

    def inequalities_from(self, columns, translations):
        start = translations[0]
        end = start + self.child_length * columns[0][0]
        return np.stack([start - self.length, -end])


@dataclass(frozen=True)
class WithinBall(RelationConstraint):
    """The child's origin within ``clearance`` of the parent's: |t| - clearance <= 0."""

    clearance: float = 0.0

    def inequalities_from(self, columns, translations):
        return (np.sqrt(np.sum(translations * translations, axis=0)) - self.clearance)[None]


@dataclass(frozen=True)
class WithinCylinder(RelationConstraint):
    """The child's origin within ``radial`` of the parent cylinder's axis and between ``low`` and
    ``high`` along it: sqrt(tx^2 + ty^2) - radial, low - tz, tz - high."""

    radial: float = 0.0
    low: float = 0.0
    high: float = 0.0

    def inequalities_from(self, columns, translations):
        return np.stack([_radial(translations[0], translations[1]) - self.radial, self.low - translations[2],
                         translations[2] - self.high])


@dataclass(frozen=True)
class PegInHole(RelationConstraint):
    """A peg (child cylinder: origin at the end that goes in first, z along its axis, out of the
    hole) in a hole (parent cylinder: origin at its bottom, z out of it, ``depth`` its length),
    with radial clearance c = R_hole - R_peg:

    * the peg's end within c of the hole's axis: sqrt(tx^2 + ty^2) - c <= 0;
    * the peg's axis where it crosses the hole's mouth (z = depth) within c too: with a the
      peg's axis, that point is t + s a, s = (depth - tz) / a_z, so the tilt is limited to about
      2c over the engaged length depth - tz (a first-order model of the peg's surface: exact
      for the axis, off by R_peg theta^2 / 2 for the rim at tilt theta);
    * the peg's end above the bottom and below the mouth: -tz <= 0, tz - depth <= 0;
    * the peg pointing out of the hole: -a_z <= 0.
    """

    clearance: float = 0.0
    depth: float = 0.0

    def inequalities_from(self, columns, translations):
        axis = columns[2]
        a_z = axis[2]
        safe = np.where(a_z > 1e-9, a_z, 1e-9)
        s = (self.depth - translations[2]) / safe
        mouth_x = translations[0] + s * axis[0]
        mouth_y = translations[1] + s * axis[1]
        mouth = np.where(a_z > 1e-9, _radial(mouth_x, mouth_y), np.inf)
        # A peg that does not point out of the hole: its mouth test reads as far outside, finitely.
        mouth = np.minimum(mouth, 1e6 * max(self.clearance, self.depth)) - self.clearance
        return np.stack([_radial(translations[0], translations[1]) - self.clearance, mouth, -translations[2],
                         translations[2] - self.depth, -a_z])


@dataclass(frozen=True)
class PointOnSphere(RelationConstraint):
    """A point on a sphere of ``radius``: the relation's pose is in spherical coordinates
    (:func:`spherical_coordinates`), whose tz is the distance to the surface."""

    radius: float = 0.0
    spherical = True


def spherical_coordinates(translations: np.ndarray, radius: float) -> np.ndarray:
    """(tx, ty, tz) of a point in a sphere's frame -> (radius longitude, radius latitude, rho - radius):
    arc lengths on the sphere (longitude in (-pi, pi], latitude in [-pi/2, pi/2]) and the distance
    to the surface, all lengths."""
    x, y, z = translations
    rho = np.sqrt(x * x + y * y + z * z)
    longitude = np.arctan2(y, x)
    latitude = np.arctan2(z, np.sqrt(x * x + y * y))
    return np.stack([radius * longitude, radius * latitude, rho - radius])


def cartesian_from_spherical(coordinates: np.ndarray, radius: float) -> np.ndarray:
    """Inverse of :func:`spherical_coordinates`."""
    longitude, latitude = coordinates[0] / radius, coordinates[1] / radius
    rho = coordinates[2] + radius
    return np.stack([rho * np.cos(latitude) * np.cos(longitude), rho * np.cos(latitude) * np.sin(longitude), rho * np.sin(latitude)])


# --- the relations of the problem language ---------------------------------------------------


def _polygon(kind, constrained, points, polygon) -> PolygonContact:
    normals, offsets = polygon_half_planes(polygon)
    widths = np.tile(_polygon_widths(polygon, normals), len(points))
    return PolygonContact(kind, constrained, widths, np.asarray(points, dtype=float), normals, offsets)


def face_on_face(parent_polygon, child_polygon) -> RelationConstraint:
    # The child face frame is flipped (Rx(pi)) so that coplanar, opposed faces
    # have Q = (tx, ty, 0, 0, 0, rz); a vertex (x, y) becomes (x, -y, 0).
    points = [[x, -y, 0.0] for x, y in child_polygon]
    return _polygon("face_on_face", ("tz", "rx", "ry"), points, parent_polygon)


def point_on_face(parent_polygon) -> RelationConstraint:
    return _polygon("point_on_face", ("tz",), [[0.0, 0.0, 0.0]], parent_polygon)


def edge_on_face(parent_polygon, edge_length: float) -> RelationConstraint:
    # The edge runs along the child frame's x axis from 0 to its length.
    return _polygon("edge_on_face", ("tz", "ry"), [[0.0, 0.0, 0.0], [edge_length, 0.0, 0.0]], parent_polygon)


def point_on_point() -> RelationConstraint:
    return RelationConstraint("point_on_point", ("tx", "ty", "tz"), np.zeros(0))


def sphere_on_face(parent_polygon) -> RelationConstraint:
    # The compiler lifts the face's frame by the radius along its normal: Q is the centre there.
    return _polygon("sphere_on_face", ("tz",), [[0.0, 0.0, 0.0]], parent_polygon)


def cylinder_on_face(parent_polygon, radius: float) -> RelationConstraint:
    normals, offsets = polygon_half_planes(parent_polygon)
    return DiscOnFace("cylinder_on_face", ("tz", "rx", "ry"), _polygon_widths(parent_polygon, normals),
                      np.zeros((1, 3)), normals, offsets, float(radius))


def point_on_edge(length: float) -> RelationConstraint:
    return OnSegment("point_on_edge", ("ty", "tz"), np.full(2, float(length)), float(length))


def edge_on_edge(length: float, child_length: float) -> RelationConstraint:
    return OverlappingSegments("edge_on_edge", ("ty", "tz", "ry", "rz"), np.full(2, float(length + child_length)),
                               float(length), float(child_length))


def point_on_sphere(radius: float) -> RelationConstraint:
    return PointOnSphere("point_on_sphere", ("tz",), np.zeros(0), float(radius))


def sphere_in_sphere(socket_radius: float, ball_radius: float) -> RelationConstraint:
    clearance = float(socket_radius - ball_radius)
    return WithinBall("sphere_in_sphere", (), np.array([2.0 * clearance]), clearance)


def in_cylinder(kind: str, radius: float, length: float, inner_radius: float = 0.0) -> RelationConstraint:
    """point_in_cylinder (inner_radius 0) and sphere_in_cylinder: the centre within R - r of the
    axis and between r and L - r along it."""
    radial = float(radius - inner_radius)
    low, high = float(inner_radius), float(length - inner_radius)
    return WithinCylinder(kind, (), np.array([2.0 * radial, high - low, high - low]), radial, low, high)


def cylinder_in_cylinder(hole_radius: float, depth: float, peg_radius: float) -> RelationConstraint:
    clearance = float(hole_radius - peg_radius)
    widths = np.array([2.0 * clearance, 2.0 * clearance, depth, depth, 1.0])
    return PegInHole("cylinder_in_cylinder", (), widths, clearance, float(depth))

