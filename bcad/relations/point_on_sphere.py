"""``point_on_sphere`` (sphere, point): a point on a sphere's surface, in spherical coordinates."""

from __future__ import annotations

import numpy as np

from bcad.relations.geometry import PointOnSphere
from bcad.relations.kind import RelationKind, nominal_value


def constraint(radius: float, surface: str = ""):
    return PointOnSphere("point_on_sphere", ("tz",), np.zeros(0), radius=float(radius), surface=surface)


RELATION = RelationKind(
    name="point_on_sphere",
    parent="sphere",
    child="point",
    summary="the pose is in spherical coordinates (R longitude, R latitude, distance to the "
    "surface); tz = 0. Closing links only.",
    build=lambda parent, child: constraint(nominal_value(parent.radius), parent.name),
    takes_uncertain_radius=True,
)
