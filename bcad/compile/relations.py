"""Geometric relations compiled to equality and inequality constraints.

A relation is a link between two entity frames whose pose Q (child entity
frame in parent entity frame) must satisfy equality constraints ``E(Q) = 0``
(which parameters the relation constrains) and inequality constraints
``C(Q) <= 0`` (Sect. 3.1 of the 2000 paper, item 2). Inequalities are signed
distances in length units (positive outside), evaluated on batches of poses,
so that the tempered relaxation of Sect. 4.2.1 can widen them smoothly.
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


@dataclass(frozen=True)
class RelationConstraint:
    """Constraints of one relation on its link's pose Q.

    ``constrained`` names the parameters the equalities set to zero;
    ``child_points`` (p, 3) are points of the child entity (in its entity
    frame) that must lie inside the parent face's polygon, given by its
    half-planes (unit ``normals``, ``offsets``) and its ``widths`` along each
    normal (the scale of the tempered relaxation, Fig. 2). Point-on-point has
    no polygon and no inequalities.
    """

    kind: str
    constrained: tuple[str, ...]
    child_points: np.ndarray
    normals: np.ndarray
    offsets: np.ndarray
    widths: np.ndarray

    @property
    def inequality_count(self) -> int:
        return len(self.child_points) * len(self.offsets)

    def inequalities_from(self, columns: np.ndarray, translations: np.ndarray) -> np.ndarray:
        """Signed distances C(Q) for a batch of transforms, shape (points, edges, *batch).

        ``columns[j]`` is column j of the rotations (3, *batch); child points are
        mapped by Q and projected on the parent face's plane.
        """
        batch = translations.shape[1:]
        out = np.empty((len(self.child_points), len(self.offsets)) + batch)
        for index, point in enumerate(self.child_points):
            xy = translations[:2] + sum(columns[j][:2] * point[j] for j in range(3) if point[j] != 0.0)
            out[index] = np.tensordot(self.normals, xy, axes=(1, 0)) - self.offsets.reshape((-1,) + (1,) * len(batch))
        return out

    def inequalities(self, poses: np.ndarray) -> np.ndarray:
        """Signed distances C(Q) for poses (N, 6), shape (N, inequality_count); inside when all <= 0."""
        poses = np.atleast_2d(poses)
        R = rpy_to_matrix(poses[:, 3:])
        columns = np.transpose(R, (2, 1, 0))
        values = self.inequalities_from(columns, poses[:, :3].T)
        return np.moveaxis(values, -1, 0).reshape(poses.shape[0], -1)

    def log_satisfaction(self, columns: np.ndarray, translations: np.ndarray, temperature: float) -> np.ndarray:
        """log p(H | Q): 0 or -inf at T = 0, relaxed as in Sect. 4.2.1 for T > 0; shape (*batch)."""
        if self.inequality_count == 0:
            return np.zeros(translations.shape[1:])
        distances = self.inequalities_from(columns, translations)
        widths = self.widths.reshape((1, -1) + (1,) * (distances.ndim - 2))
        return relaxed_log_indicator(distances, widths, temperature).sum(axis=(0, 1))


def _relation(kind, constrained, points, polygon) -> RelationConstraint:
    if polygon is None:
        empty = np.zeros(0)
        return RelationConstraint(kind, constrained, np.zeros((0, 3)), np.zeros((0, 2)), empty, empty)
    normals, offsets = polygon_half_planes(polygon)
    projections = normals @ np.asarray(polygon, dtype=float).T
    widths = projections.max(axis=1) - projections.min(axis=1)
    return RelationConstraint(kind, constrained, np.asarray(points, dtype=float), normals, offsets, widths)


def face_on_face(parent_polygon, child_polygon) -> RelationConstraint:
    # The child face frame is flipped (Rx(pi)) so that coplanar, opposed faces
    # have Q = (tx, ty, 0, 0, 0, rz); a vertex (x, y) becomes (x, -y, 0).
    points = [[x, -y, 0.0] for x, y in child_polygon]
    return _relation("face_on_face", ("tz", "rx", "ry"), points, parent_polygon)


def point_on_face(parent_polygon) -> RelationConstraint:
    return _relation("point_on_face", ("tz",), [[0.0, 0.0, 0.0]], parent_polygon)


def edge_on_face(parent_polygon, edge_length: float) -> RelationConstraint:
    # The edge runs along the child frame's x axis from 0 to its length.
    return _relation("edge_on_face", ("tz", "ry"), [[0.0, 0.0, 0.0], [edge_length, 0.0, 0.0]], parent_polygon)


def point_on_point() -> RelationConstraint:
    return _relation("point_on_point", ("tx", "ty", "tz"), None, None)
