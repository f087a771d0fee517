"""``cylinder_in_cylinder`` (hole, peg): a peg in a hole (:class:`~bcad.relations.geometry.PegInHole`)."""

from __future__ import annotations

import numpy as np

from bcad.relations.geometry import PegInHole
from bcad.relations.kind import RelationKind, cylinder_terms, fitting_radius


def constraint(hole_radius: float, depth: float, peg_radius: float):
    clearance = float(hole_radius - peg_radius)
    widths = np.array([2.0 * clearance, 2.0 * clearance, depth, depth, 1.0])
    return PegInHole("cylinder_in_cylinder", (), widths, float(hole_radius), float(peg_radius), float(depth))


RELATION = RelationKind(
    name="cylinder_in_cylinder",
    parent="cylinder",
    child="cylinder",
    summary="the parent is the hole, the child the peg: the peg's surface inside the hole up to its "
    "mouth (on its end's rim and on its section by the mouth's plane), its rim above the bottom, its end "
    "below the mouth, its axis pointing out.",
    build=lambda parent, child: constraint(
        parent.radius, parent.nominal_length, fitting_radius("cylinder_in_cylinder", parent, child)
    ),
    dimensions=lambda parent, child, relation: cylinder_terms(parent, "depth"),
)
