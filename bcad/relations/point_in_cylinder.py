"""``point_in_cylinder`` (cylinder, point): a point inside a cylinder."""

from __future__ import annotations

from bcad.relations.geometry import within_cylinder
from bcad.relations.kind import RelationKind, cylinder_terms


def constraint(radius: float, length: float):
    return within_cylinder("point_in_cylinder", radius, length)


RELATION = RelationKind(
    name="point_in_cylinder",
    parent="cylinder",
    child="point",
    summary="the point within R of the axis and between the end discs.",
    build=lambda parent, child: constraint(parent.radius, parent.nominal_length),
    dimensions=lambda parent, child, relation: cylinder_terms(parent, "high"),
)
