"""``sphere_on_face`` (face, sphere): a sphere resting on a face, its contact point inside the polygon."""

from __future__ import annotations

import numpy as np

from bcad.kinematics.se3 import translation
from bcad.relations.geometry import polygon_contact
from bcad.relations.kind import RelationKind


def constraint(parent_polygon):
    """Q is the centre in the face's frame lifted by the radius (:func:`_lift_face`)."""
    return polygon_contact("sphere_on_face", ("tz",), [[0.0, 0.0, 0.0]], parent_polygon)


def _lift_face(parent, child, parent_frame, child_frame):
    # The face's frame lifted by the radius along its normal: the centre's plane (tz = 0 on contact).
    return parent_frame @ translation(np.array([0.0, 0.0, float(child.radius)])), child_frame


RELATION = RelationKind(
    name="sphere_on_face",
    parent="face",
    child="sphere",
    summary="Q is the centre in the face's frame lifted by the radius; tz = 0; the contact point inside the polygon.",
    build=lambda parent, child: constraint(parent.polygon()),
    frames=_lift_face,
)
