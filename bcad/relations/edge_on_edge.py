"""``edge_on_edge`` (edge, edge): two collinear edges, same direction, that overlap."""

from __future__ import annotations

import numpy as np

from bcad.relations.geometry import OverlappingSegments
from bcad.relations.kind import RelationKind, edge_direction, edge_length, edge_sensitivity, uncertain_dimensions


def constraint(length: float, child_length: float):
    return OverlappingSegments(
        "edge_on_edge",
        ("ty", "tz", "ry", "rz"),
        np.full(2, float(length + child_length)),
        float(length),
        float(child_length),
    )


def _length_terms(parent, child, relation):
    # Each edge's length, to first order in its ends' deviations: L + u . (d end - d start).
    terms = []
    for entity, attribute in ((parent, "length"), (child, "child_length")):
        u = edge_direction(entity)
        terms += [(attribute, name, np.array(edge_sensitivity(name, u))) for name, _ in uncertain_dimensions(entity)]
    return terms


RELATION = RelationKind(
    name="edge_on_edge",
    parent="edge",
    child="edge",
    summary="ty = tz = ry = rz = 0 (collinear, same direction); the two segments overlap along x.",
    build=lambda parent, child: constraint(edge_length(parent), edge_length(child)),
    dimensions=_length_terms,
)
