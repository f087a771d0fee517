"""``cylinder_on_face`` (face, cylinder): a cylinder standing on a face, its base disc inside the polygon."""

from __future__ import annotations

from bcad.relations.geometry import disc_on_face
from bcad.relations.kind import RelationKind


def constraint(parent_polygon, radius: float):
    return disc_on_face("cylinder_on_face", parent_polygon, radius)


RELATION = RelationKind(
    name="cylinder_on_face",
    parent="face",
    child="cylinder",
    summary="tz = rx = ry = 0 (the base disc on the face, the axis along its normal); the disc inside the polygon.",
    build=lambda parent, child: constraint(parent.polygon(), child.radius),
)
