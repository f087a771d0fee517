"""What a kind of relation declares, and the entity dimensions every kind reads.

A kind (one module of :mod:`bcad.relations`) names the entities it joins, says in one line what
it constrains, builds its :class:`~bcad.relations.geometry.RelationConstraint` from the two
entities, and may say how the entities' uncertain dimensions move that constraint and how its
entity frames are placed. Entities are the problem language's (``bcad.model.entities``), read
by their attributes: this layer sits below the schema, which lists the kinds it accepts from here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bcad.relations.geometry import RelationConstraint


class RelationError(ValueError):
    """A relation that cannot be built from its entities: ``role`` (parent or child) is where the
    problem is, ``message`` what is wrong and what was expected."""

    def __init__(self, role: str, message: str):
        super().__init__(message)
        self.role = role
        self.message = message


def is_uncertain(value) -> bool:
    """Whether a dimension is a distribution rather than a number."""
    return not isinstance(value, (int, float))


def nominal_value(value) -> float:
    """A dimension's value, or its distribution's mean."""
    return float(value) if not is_uncertain(value) else float(value.moments()[0][0])


def edge_length(edge) -> float:
    """An edge entity's nominal length."""
    return float(np.linalg.norm(np.subtract(edge.nominal_end, edge.nominal_start)))


def edge_direction(edge) -> np.ndarray:
    """The unit vector from an edge's nominal start to its nominal end (host frame)."""
    d = np.subtract(edge.nominal_end, edge.nominal_start)
    return d / np.linalg.norm(d)


def edge_sensitivity(name: str, u: np.ndarray) -> float:
    """d length / d coordinate for ``EDGE.start[k]`` (-u_k) or ``EDGE.end[k]`` (+u_k), u the
    edge's direction."""
    k = int(name[-2])
    return float(u[k]) if ".end[" in name else -float(u[k])


def vertex_of(name: str) -> tuple[int, int]:
    """(vertex, coordinate) of a parameter named ``FACE.vertices[i][k]``."""
    i, k = name.rsplit(".vertices[", 1)[1][:-1].split("][")
    return int(i), int(k)


def uncertain_dimensions(entity) -> list[tuple[str, object]]:
    """(L parameter name, distribution) of a face's uncertain size or vertices, a cylinder's
    uncertain length and an edge's uncertain ends."""
    found = []
    if entity.type == "face" and entity.size is not None:
        found += [(f"{entity.name}.size[{k}]", value) for k, value in enumerate(entity.size) if is_uncertain(value)]
    if entity.type == "face" and entity.vertices is not None:
        found += [
            (f"{entity.name}.vertices[{i}][{k}]", value)
            for i, vertex in enumerate(entity.vertices)
            for k, value in enumerate(vertex)
            if is_uncertain(value)
        ]
    if entity.type == "cylinder" and is_uncertain(entity.length):
        found.append((f"{entity.name}.length", entity.length))
    if entity.type == "edge":
        found += [
            (f"{entity.name}.{key}[{k}]", value)
            for key in ("start", "end")
            for k, value in enumerate(getattr(entity, key))
            if is_uncertain(value)
        ]
    return found


#: a term of a constraint's ``uncertain``: (attribute, L parameter name, coefficients)
DimensionTerm = tuple[str, str, np.ndarray]


def parent_face_terms(parent, constraint: RelationConstraint) -> list[DimensionTerm]:
    """How a parent face's uncertain size or vertices move a polygon constraint's half-planes."""
    terms: list[DimensionTerm] = []
    if parent.type != "face" or getattr(constraint, "normals", None) is None:
        return terms
    if parent.size is not None:
        # A parent rectangle's edge k lies at offset n_k . v: a size change of delta along axis a
        # moves the edges whose normal is along a by delta / 2 (outwards: more room).
        rows = len(constraint.offsets)
        for name, _ in uncertain_dimensions(parent):
            axis = int(name[-2])
            terms.append(("offsets", name, 0.5 * np.abs(constraint.normals[:, axis]).reshape(rows)))
    if parent.vertices is not None:
        # A vertex's coordinate moves the polygon: its half-planes are rebuilt per sample.
        for name, _ in uncertain_dimensions(parent):
            i, k = vertex_of(name)
            coefficients = np.zeros((len(parent.vertices), 2))
            coefficients[parent.polygon_index(i), k] = 1.0
            terms.append(("polygon", name, coefficients))
    return terms


def cylinder_terms(parent, attribute: str) -> list[DimensionTerm]:
    """A parent cylinder's uncertain length moving the constraint's ``attribute`` one for one."""
    if parent.type != "cylinder":
        return []
    return [(attribute, name, np.array(1.0)) for name, _ in uncertain_dimensions(parent)]


def _no_terms(parent, child, constraint) -> list[DimensionTerm]:
    return []


def _frames_unchanged(parent, child, parent_frame: np.ndarray, child_frame: np.ndarray):
    return parent_frame, child_frame


@dataclass(frozen=True)
class RelationKind:
    """One kind of relation of the problem language.

    Args:
        name: the key users write (``type: face_on_face``).
        parent: the entity type of the relation's parent (``face``, ``point``, ...).
        child: the entity type of its child.
        summary: what it constrains, one line for the language reference (equalities, then the
            inequalities in words).
        build: the constraint from the two entities; raises :class:`RelationError`.
        dimensions: the terms (beyond a parent face's, :func:`parent_face_terms`) by which the
            entities' uncertain dimensions move the constraint, named by L parameter.
        frames: the entity frames the relation's link joins, from each entity's frame in its
            host (4x4 each): a kind whose pose is not simply child in parent adjusts them.
        takes_uncertain_radius: whether an entity's radius may be a distribution (read per
            sample); other kinds refuse one, as they use the radius as a constant of their geometry.
    """

    name: str
    parent: str
    child: str
    summary: str
    build: Callable[[object, object], RelationConstraint]
    dimensions: Callable[[object, object, RelationConstraint], list[DimensionTerm]] = _no_terms
    frames: Callable = _frames_unchanged
    takes_uncertain_radius: bool = False


def fitting_radius(kind: str, parent, child) -> float:
    """The radius of a child held inside its parent, checked to fit (the clearance is the
    difference of the radii)."""
    inner = float(child.radius)
    if not inner < parent.radius:
        raise RelationError(
            "child",
            f"{kind}: the child's radius {inner:g} must be less than the parent's {parent.radius:g} "
            "(the clearance is their difference)",
        )
    return inner
