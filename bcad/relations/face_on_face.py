"""``face_on_face`` (face, face): two faces coplanar and opposed, the child's vertices inside
the parent's polygon."""

from __future__ import annotations

import math

import numpy as np

from bcad.kinematics.se3 import rotation_about_axis
from bcad.relations.geometry import polygon_contact
from bcad.relations.kind import RelationKind, uncertain_dimensions, vertex_of


def constraint(parent_polygon, child_polygon):
    """The child face frame is flipped (Rx(pi)) so that coplanar, opposed faces have
    Q = (tx, ty, 0, 0, 0, rz); a child vertex (x, y) becomes (x, -y, 0)."""
    points = [[x, -y, 0.0] for x, y in child_polygon]
    return polygon_contact("face_on_face", ("tz", "rx", "ry"), points, parent_polygon)


def _child_corner_terms(parent, child, relation):
    # The child's corners (x, -y, 0): a size change moves them outwards, a vertex's coordinate its corner.
    terms = []
    for name, _ in uncertain_dimensions(child):
        coefficients = np.zeros_like(relation.points)
        if ".vertices[" in name:
            i, k = vertex_of(name)
            coefficients[child.polygon_index(i), k] = 1.0 if k == 0 else -1.0
        else:
            axis = int(name[-2])
            coefficients[:, axis] = 0.5 * np.sign(relation.points[:, axis])
        terms.append(("points", name, coefficients))
    return terms


def _flip_child(parent, child, parent_frame, child_frame):
    flip = np.eye(4)
    flip[:3, :3] = rotation_about_axis(0, math.pi)
    return parent_frame, child_frame @ flip


RELATION = RelationKind(
    name="face_on_face",
    parent="face",
    child="face",
    summary="tz = rx = ry = 0 (the child face's frame flipped so that its z axis points into its "
    "part); every vertex of the child face lies inside the parent face (one inequality per vertex "
    "and parent edge).",
    build=lambda parent, child: constraint(parent.polygon(), child.polygon()),
    dimensions=_child_corner_terms,
    frames=_flip_child,
)
