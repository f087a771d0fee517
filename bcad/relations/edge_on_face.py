"""``edge_on_face`` (face, edge): an edge lying on a face, both its ends inside the polygon."""

from __future__ import annotations

import numpy as np

from bcad.relations.geometry import polygon_contact
from bcad.relations.kind import RelationKind, edge_direction, edge_length, edge_sensitivity, uncertain_dimensions


def constraint(parent_polygon, edge_length: float):
    """The edge runs along the child frame's x axis from 0 to its length."""
    return polygon_contact("edge_on_face", ("tz", "ry"), [[0.0, 0.0, 0.0], [edge_length, 0.0, 0.0]], parent_polygon)


def _edge_end_terms(parent, child, relation):
    # The edge's far end, to first order in its ends' deviations: L + u . (d end - d start).
    u = edge_direction(child)
    terms = []
    for name, _ in uncertain_dimensions(child):
        coefficients = np.zeros_like(relation.points)
        coefficients[1, 0] = edge_sensitivity(name, u)
        terms.append(("points", name, coefficients))
    return terms


RELATION = RelationKind(
    name="edge_on_face",
    parent="face",
    child="edge",
    summary="tz = ry = 0; both ends of the edge lie inside the face.",
    build=lambda parent, child: constraint(parent.polygon(), edge_length(child)),
    dimensions=_edge_end_terms,
)
