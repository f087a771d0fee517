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
    half-planes. Point-on-point has no polygon and no inequalities.
    """

    kind: str
    constrained: tuple[str, ...]
    child_points: np.ndarray
    normals: np.ndarray
    offsets: np.ndarray

    @property
    def inequality_count(self) -> int:
        return len(self.child_points) * len(self.offsets)

    def inequalities(self, poses: np.ndarray) -> np.ndarray:
        """Signed distances C(Q), shape (N, inequality_count); inside when all <= 0.

        Child points are mapped by Q and projected on the parent face's plane.
        """
        poses = np.atleast_2d(poses)
        if self.inequality_count == 0:
            return np.zeros((poses.shape[0], 0))
        R = rpy_to_matrix(poses[:, 3:])
        points = np.einsum("nij,pj->npi", R[:, :2, :], self.child_points) + poses[:, None, :2]
        distances = np.einsum("npi,ki->npk", points, self.normals) - self.offsets
        return distances.reshape(poses.shape[0], -1)


def face_on_face(parent_polygon, child_polygon) -> RelationConstraint:
    # The child face frame is flipped (Rx(pi)) so that coplanar, opposed faces
    # have Q = (tx, ty, 0, 0, 0, rz); a vertex (x, y) becomes (x, -y, 0).
    normals, offsets = polygon_half_planes(parent_polygon)
    points = np.array([[x, -y, 0.0] for x, y in child_polygon])
    return RelationConstraint("face_on_face", ("tz", "rx", "ry"), points, normals, offsets)


def point_on_face(parent_polygon) -> RelationConstraint:
    normals, offsets = polygon_half_planes(parent_polygon)
    return RelationConstraint("point_on_face", ("tz",), np.zeros((1, 3)), normals, offsets)


def edge_on_face(parent_polygon, edge_length: float) -> RelationConstraint:
    # The edge runs along the child frame's x axis from 0 to its length.
    normals, offsets = polygon_half_planes(parent_polygon)
    points = np.array([[0.0, 0.0, 0.0], [edge_length, 0.0, 0.0]])
    return RelationConstraint("edge_on_face", ("tz", "ry"), points, normals, offsets)


def point_on_point() -> RelationConstraint:
    return RelationConstraint("point_on_point", ("tx", "ty", "tz"), np.zeros((0, 3)), np.zeros((0, 2)), np.zeros(0))
