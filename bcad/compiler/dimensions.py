"""Entity dimensions that are not exactly known: a radius or a position given as a distribution.

A sphere's or cylinder's ``radius: normal(12.7, 0.01)`` is an L parameter named
``ENTITY.radius``: its nominal value is the distribution's mean and its deviation from it is
the distribution shifted by that mean, as every L in bcad is a deviation from nominal. It is
integrated by solve and identified by calibrate like any other L. It enters where the radius
is read off a computed pose: the curvilinear coordinates of ``point_on_sphere`` and
``point_on_cylinder`` and of a measurement read in a sphere or a cylinder
(:class:`bcad.relations.geometry.SurfaceCoordinates`). The relations that use a radius as a
constant of their geometry (a sphere on a face, a ball in a socket, a peg in a hole) need it
exactly known.

A face's ``size`` (each of its two numbers) and a cylinder's ``length`` may be distributions
too: L parameters ``ENTITY.size[0]``, ``ENTITY.size[1]`` and ``ENTITY.length``
(:func:`add_uncertain_dimensions`). They enter the relations' inequalities, per sample
(:meth:`bcad.relations.geometry.RelationConstraint.bind`, built by :func:`with_dimensions`): a
face's size moves its edges (a parent face's half-planes, a child face's corners), a cylinder's
length its far end. Nothing a sensor reads depends on them, so calibration holds them at their
prior (it says so).

A point's ``at`` and a sphere's ``center`` may give each coordinate as a distribution
(``at: [0, 'normal(50, 0.1)', 0]``): the entity then hangs on a frame of its own,
``HOST/ENTITY.at``, reached from its host frame by a link ``ENTITY.at`` whose uncertain
translations are L parameters ``ENTITY.at[1]`` (deviations from their means), so that relations
and measurements integrate and identify them like any link's L.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from bcad.compiler.graph import GraphLink
from bcad.compiler.parameters import DistributionGroup, Parameter, ParameterTable
from bcad.model.distributions import Normal, TruncatedNormal, Uniform
from bcad.model.entities import nominal
from bcad.model.pose import PARAMETERS
from bcad.model.problem import Problem
from bcad.relations import RELATIONS, RelationKind
from bcad.relations.kind import (
    edge_length,
    is_uncertain,
    parent_face_terms,
    uncertain_dimensions,
    vertex_of,
)

#: a normal radius must stay this many standard deviations above 0
MARGIN = 6.0
#: vertices at most of a face whose vertices are uncertain: each batch of samples holds its polygon,
#: half-planes and offsets per sample (16 x 2 x 65,536 doubles: 17 MB each)
MAX_UNCERTAIN_POLYGON = 16
#: the relations that take an uncertain radius (measurements read in a sphere or a cylinder do too)
TAKES_UNCERTAIN_RADIUS = tuple(name for name, kind in RELATIONS.items() if kind.takes_uncertain_radius)


def nominal_radius(entity) -> float:
    """The radius, or its distribution's mean."""
    return nominal(entity.radius)


def deviation(distribution, nominal: float):
    """The distribution of the radius's deviation from ``nominal``, or None if it may reach 0."""
    if isinstance(distribution, Normal):
        return (
            Normal(mean=distribution.mean - nominal, std=distribution.std)
            if distribution.mean > MARGIN * distribution.std
            else None
        )
    if isinstance(distribution, Uniform):
        return (
            Uniform(low=distribution.low - nominal, high=distribution.high - nominal) if distribution.low > 0 else None
        )
    if isinstance(distribution, TruncatedNormal):
        if not distribution.low > 0:
            return None
        return TruncatedNormal(
            mean=distribution.mean - nominal,
            std=distribution.std,
            low=distribution.low - nominal,
            high=distribution.high - nominal,
        )
    return None


def add_uncertain_radii(table: ParameterTable, problem: Problem) -> dict[str, int]:
    """An L column ``ENTITY.radius`` for every entity whose radius is a distribution (module
    docstring), appended to the table; entity name -> its column."""
    doc = problem.source
    columns: dict[str, int] = {}
    for index, entity in enumerate(problem.entities):
        radius = getattr(entity, "radius", None)
        if radius is None or not is_uncertain(radius):
            continue
        if radius.dimension != 1:
            raise doc.error(
                ("entities", index, "radius"),
                f"the radius of '{entity.name}' is {radius.shorthand()}; a radius takes a distribution of one "
                "number: normal, uniform or truncnormal",
            )
        shifted = deviation(radius, nominal_radius(entity))
        if shifted is None:
            raise doc.error(
                ("entities", index, "radius"),
                f"the radius of '{entity.name}' is {radius.shorthand()}, which may reach 0; expected a normal "
                f"whose mean is over {MARGIN:g} std, or a uniform or truncnormal above 0",
            )
        columns[entity.name] = len(table.l)
        table.l.append(Parameter(f"{entity.name}.radius", -1, -1))
        table.l_groups.append(DistributionGroup(shifted, (columns[entity.name],)))
    return columns


def add_uncertain_dimensions(table: ParameterTable, problem: Problem) -> dict[str, int]:
    """An L column for every uncertain face size and cylinder length (module docstring), appended
    to the table; parameter name -> its column."""
    doc = problem.source
    columns: dict[str, int] = {}
    for index, entity in enumerate(problem.entities):
        if (
            entity.type == "face"
            and entity.vertices is not None
            and len(entity.vertices) > MAX_UNCERTAIN_POLYGON
            and uncertain_dimensions(entity)
        ):
            raise doc.error(
                ("entities", index, "vertices"),
                f"'{entity.name}' has {len(entity.vertices)} vertices and uncertain "
                f"ones; a face whose vertices are uncertain has at most {MAX_UNCERTAIN_POLYGON} (each sample "
                "carries its own polygon)",
            )
        for name, distribution in uncertain_dimensions(entity):
            key = name.split(".", 1)[1]
            vertex = key.startswith(("vertices", "start", "end"))  # a coordinate: any sign
            if key.startswith("vertices"):
                i, k = (int(part) for part in key[len("vertices[") : -1].split("]["))
                loc = ("entities", index, "vertices", i, k)
            elif vertex:
                loc = ("entities", index, key.split("[")[0], int(key[-2]))
            else:
                loc = ("entities", index) + (("size", int(key[5])) if key.startswith("size") else ("length",))
            if distribution.dimension != 1:
                raise doc.error(
                    loc,
                    f"'{name}' is {distribution.shorthand()}; a dimension takes a distribution of one number: "
                    "normal, uniform or truncnormal",
                )
            mean = float(distribution.moments()[0][0])
            # a vertex's coordinate may take any sign; a size or a length must stay above 0
            moved = shifted(distribution, mean) if vertex else deviation(distribution, mean)
            if moved is None:
                raise doc.error(
                    loc,
                    f"'{name}' is {distribution.shorthand()}, which may reach 0; expected a normal whose "
                    f"mean is over {MARGIN:g} std, or a uniform or truncnormal above 0",
                )
            columns[name] = len(table.l)
            table.l.append(Parameter(name, -1, -1))
            table.l_groups.append(DistributionGroup(moved, (columns[name],)))
    return columns


def edge_transform(edge, frame_of_edge: np.ndarray, columns: dict[str, int]):
    """The transform of an uncertain edge's position link: its nominal frame (``frame_of_edge``,
    the entity frame: origin at the start, x along the edge) as the link's origin, then the
    deviations, to first order in the ends' deviations ds and de (host frame; R the nominal
    rotation, D the nominal length): the origin moves by R^T ds, the x axis turns by
    omega = e_x x R^T (de - ds) / D (in the edge frame, where the rotation's parameters start at
    0, so none is near gimbal lock)."""
    from bcad.kinematics.chain import AffineParameter, LinkTransform, Term

    R = frame_of_edge[:3, :3]
    length = edge_length(edge)
    terms: list[list] = [[] for _ in range(6)]
    for name, _ in uncertain_dimensions(edge):
        column, k = columns[name], int(name[-2])
        host = np.zeros(3)
        host[k] = 1.0
        local = R.T @ host  # this coordinate's unit deviation in the edge frame
        sign = 1.0 if ".end[" in name else -1.0
        turn = np.cross([1.0, 0.0, 0.0], sign * local) / length
        if ".start[" in name:
            for axis in range(3):
                if local[axis] != 0.0:
                    terms[axis].append(Term("l", column, float(local[axis])))
        for axis in range(3):
            if turn[axis] != 0.0:
                terms[3 + axis].append(Term("l", column, float(turn[axis])))
    return LinkTransform(tuple(AffineParameter(0.0, tuple(t)) for t in terms), frame_of_edge, np.eye(4))


def with_dimensions(kind: RelationKind, parent, child, constraint):
    """The relation's constraint with its ``uncertain`` terms (attribute, L parameter name,
    coefficients), where its entities have uncertain dimensions: how each moves its geometry
    (named by parameter: the compiler resolves them to L columns)."""
    terms = parent_face_terms(parent, constraint) + kind.dimensions(parent, child, constraint)
    if not terms:
        return constraint
    if any(term[0] == "polygon" for term in terms):
        constraint = replace(constraint, polygon=np.asarray(parent.polygon(), dtype=float))
    return replace(constraint, uncertain=tuple(terms))


def face_edge(entity, edge: int, columns: dict[str, int]) -> tuple[np.ndarray, list]:
    """Edge ``edge`` of a face's polygon (counter-clockwise from its first vertex; a ``size``
    rectangle's edges 0-3 run along -y, +x, +y, -x of the face): the edge frame in the face
    frame, at the edge's midpoint with x along the edge, y pointing into the face and z the face's
    normal, so that a probe touching the side at the edge reads ty = 0; and how the uncertain
    dimensions move it, as the terms (pose parameter, L column, coefficient) of the first step
    of a chain read in it, the inverse of the move: a size change of delta moves the edge out by
    delta / 2 (exactly); the edge's two vertices moving by da and db shift its midpoint by
    (da + db) / 2 and turn it by along x (db - da) / length (to first order)."""
    polygon = np.asarray(entity.polygon(), dtype=float)
    start, end = polygon[edge], polygon[(edge + 1) % len(polygon)]
    length = float(np.linalg.norm(end - start))
    along = (end - start) / length
    inward = np.array([-along[1], along[0]])  # counter-clockwise polygon: the interior is on the left
    transform = np.eye(4)
    transform[:2, 0], transform[:2, 1], transform[:2, 3] = along, inward, 0.5 * (start + end)
    moves = []
    for name, _ in uncertain_dimensions(entity):
        if name not in columns:
            continue
        if ".size[" in name:
            axis = int(name[-2])
            if abs(inward[axis]) > 0.5:
                moves.append((1, columns[name], 0.5))  # the inverse of moving out by delta / 2 along -y
            continue
        i, k = vertex_of(name)
        at = entity.polygon_index(i)
        if at not in (edge, (edge + 1) % len(polygon)):
            continue
        unit = np.zeros(2)
        unit[k] = 1.0
        shift = 0.5 * unit  # of the midpoint, in the face's coordinates
        turn = (1.0 if at != edge else -1.0) * float(along[0] * unit[1] - along[1] * unit[0]) / length
        moves += [
            (0, columns[name], -float(along @ shift)),
            (1, columns[name], -float(inward @ shift)),
            (5, columns[name], -turn),
        ]
    return transform, moves


def cylinder_top(entity, columns: dict[str, int]) -> tuple[np.ndarray, list]:
    """A cylinder's top frame in its frame: at the far end disc's centre, axes as the cylinder's,
    so that a probe touching the end face reads tz = 0; with its length uncertain, the first
    chain step's term (tz, L column, -1) (the inverse of moving the end out by delta)."""
    transform = np.eye(4)
    transform[2, 3] = entity.nominal_length
    name = f"{entity.name}.length"
    return transform, ([(2, columns[name], -1.0)] if name in columns else [])


#: the key of an entity's position, by entity type
POSITION_KEYS = {"point": "at", "sphere": "center"}


def shifted(distribution, by: float):
    """The distribution of a coordinate's deviation from ``by`` (its nominal value), or None for a
    distribution bcad cannot shift (one of more than one number)."""
    if isinstance(distribution, Normal):
        return Normal(mean=distribution.mean - by, std=distribution.std)
    if isinstance(distribution, Uniform):
        return Uniform(low=distribution.low - by, high=distribution.high - by)
    if isinstance(distribution, TruncatedNormal):
        return TruncatedNormal(
            mean=distribution.mean - by, std=distribution.std, low=distribution.low - by, high=distribution.high - by
        )
    return None


def nominal_position(entity) -> np.ndarray | None:
    """A point's ``at`` or a sphere's ``center`` with each distribution at its mean; None for
    the other entities."""
    key = POSITION_KEYS.get(entity.type)
    if key is None:
        return None
    return np.array([nominal(v) for v in getattr(entity, key)])


def position_is_uncertain(entity) -> bool:
    if entity.type == "edge":
        return bool(uncertain_dimensions(entity))
    key = POSITION_KEYS.get(entity.type)
    return key is not None and any(is_uncertain(v) for v in getattr(entity, key))


def position_frame(entity) -> str:
    """The frame of an entity whose position is uncertain: at its position in its host frame."""
    return f"{entity.frame}/{entity.name}.{POSITION_KEYS.get(entity.type, 'start')}"


def edge_link(entity, index: int, frame_of_edge: np.ndarray) -> GraphLink:
    """For an edge whose ends are uncertain, the link from its host frame to
    :func:`position_frame`, constant here at its nominal frame; the compiler gives it the
    transform of :func:`edge_transform` once the ends' L columns exist."""
    link = GraphLink(
        f"{entity.name}.start",
        entity.frame,
        position_frame(entity),
        np.zeros(6),
        "FFFFFF",
        rank="link",
        loc=("entities", index, "start"),
    )
    link.origin = frame_of_edge
    return link


def position_link(entity, index: int, doc) -> GraphLink:
    """For an entity whose position is uncertain, the link from its host frame to
    :func:`position_frame`: a translation to the nominal position whose uncertain coordinates are
    L (their deviations from their means), named ``ENTITY.at[k]`` (or ``center[k]``). Relations and
    measurements then hang on that frame, the entity's constant part being the identity."""
    key = POSITION_KEYS[entity.type]
    nominal = nominal_position(entity)
    link = GraphLink(
        f"{entity.name}.{key}",
        entity.frame,
        position_frame(entity),
        np.concatenate([nominal, np.zeros(3)]),
        "FFFFFF",
        rank="link",
        loc=("entities", index, key),
    )
    status = list(link.status)
    for k, value in enumerate(getattr(entity, key)):
        if not is_uncertain(value):
            continue
        deviation = shifted(value, nominal[k]) if value.dimension == 1 else None
        if deviation is None:
            raise doc.error(
                ("entities", index, key, k),
                f"coordinate {k} of '{entity.name}' is {value.shorthand()}; a "
                "coordinate takes a distribution of one number: normal, uniform or truncnormal",
            )
        status[k] = "L"
        link.distributions[(PARAMETERS[k],)] = deviation
        link.parameter_names[k] = f"{entity.name}.{key}[{k}]"
    link.status = "".join(status)
    return link
