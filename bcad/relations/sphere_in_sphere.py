"""``sphere_in_sphere`` (sphere, sphere): a ball in a socket."""

from __future__ import annotations

import numpy as np

from bcad.relations.geometry import WithinBall
from bcad.relations.kind import RelationKind, fitting_radius


def constraint(socket_radius: float, ball_radius: float):
    clearance = float(socket_radius - ball_radius)
    return WithinBall("sphere_in_sphere", (), np.array([2.0 * clearance]), clearance)


RELATION = RelationKind(
    name="sphere_in_sphere",
    parent="sphere",
    child="sphere",
    summary="the centre distance at most R - r.",
    build=lambda parent, child: constraint(parent.radius, fitting_radius("sphere_in_sphere", parent, child)),
)
