"""``point_on_face`` (face, point): a point on a face's plane, inside its polygon."""

from __future__ import annotations

from bcad.relations.geometry import polygon_contact
from bcad.relations.kind import RelationKind


def constraint(parent_polygon):
    return polygon_contact("point_on_face", ("tz",), [[0.0, 0.0, 0.0]], parent_polygon)


RELATION = RelationKind(
    name="point_on_face",
    parent="face",
    child="point",
    summary="tz = 0; the point lies inside the face (one inequality per face edge).",
    build=lambda parent, child: constraint(parent.polygon()),
)
