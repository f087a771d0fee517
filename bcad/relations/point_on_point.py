"""``point_on_point`` (point, point): two points that coincide."""

from __future__ import annotations

import numpy as np

from bcad.relations.geometry import RelationConstraint
from bcad.relations.kind import RelationKind


def constraint():
    return RelationConstraint("point_on_point", ("tx", "ty", "tz"), np.zeros(0))


RELATION = RelationKind(
    name="point_on_point",
    parent="point",
    child="point",
    summary="tx = ty = tz = 0.",
    build=lambda parent, child: constraint(),
)
