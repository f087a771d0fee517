"""``sphere_in_cylinder`` (cylinder, sphere): a ball inside a cylinder."""

from __future__ import annotations

from bcad.relations.geometry import within_cylinder
from bcad.relations.kind import RelationError, RelationKind, cylinder_terms, fitting_radius


def constraint(radius: float, length: float, sphere_radius: float):
    return within_cylinder("sphere_in_cylinder", radius, length, sphere_radius)


def _build(parent, child):
    inner = fitting_radius("sphere_in_cylinder", parent, child)
    if not 2.0 * inner < parent.nominal_length:
        raise RelationError(
            "child",
            f"sphere_in_cylinder: the sphere's diameter {2 * inner:g} must be less than the cylinder's "
            f"length {parent.nominal_length:g}",
        )
    return constraint(parent.radius, parent.nominal_length, inner)


RELATION = RelationKind(
    name="sphere_in_cylinder",
    parent="cylinder",
    child="sphere",
    summary="the centre within R - r of the axis and between r and L - r along it.",
    build=_build,
    dimensions=lambda parent, child, relation: cylinder_terms(parent, "high"),
)
