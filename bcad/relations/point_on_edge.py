"""``point_on_edge`` (edge, point): a point on an edge, between its ends."""

from __future__ import annotations

import numpy as np

from bcad.relations.geometry import OnSegment
from bcad.relations.kind import RelationKind, edge_direction, edge_length, edge_sensitivity, uncertain_dimensions


def constraint(length: float):
    return OnSegment("point_on_edge", ("ty", "tz"), np.full(2, float(length)), float(length))


def _length_terms(parent, child, relation):
    # The edge's length, to first order in its ends' deviations: L + u . (d end - d start).
    u = edge_direction(parent)
    return [("length", name, np.array(edge_sensitivity(name, u))) for name, _ in uncertain_dimensions(parent)]


RELATION = RelationKind(
    name="point_on_edge",
    parent="edge",
    child="point",
    summary="ty = tz = 0; 0 <= tx <= the edge's length.",
    build=lambda parent, child: constraint(edge_length(parent)),
    dimensions=_length_terms,
)
