"""``point_on_cylinder`` (cylinder, point): a point on a cylinder's lateral surface, between
its end discs, in cylindrical coordinates."""

from __future__ import annotations

import numpy as np

from bcad.relations.geometry import PointOnCylinder
from bcad.relations.kind import RelationKind, cylinder_terms, nominal_value


def constraint(radius: float, length: float, surface: str = ""):
    return PointOnCylinder(
        "point_on_cylinder",
        ("tz",),
        np.full(2, float(length)),
        radius=float(radius),
        surface=surface,
        length=float(length),
    )


RELATION = RelationKind(
    name="point_on_cylinder",
    parent="cylinder",
    child="point",
    summary="the pose is in cylindrical coordinates (R theta, height along the axis, distance to "
    "the lateral surface); tz = 0; the point between the end discs. Closing links only.",
    build=lambda parent, child: constraint(nominal_value(parent.radius), parent.nominal_length, parent.name),
    dimensions=lambda parent, child, relation: cylinder_terms(parent, "length"),
    takes_uncertain_radius=True,
)
