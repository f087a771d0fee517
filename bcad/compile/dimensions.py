"""Entity dimensions that are not exactly known (issue 19): a radius given as a distribution.

A sphere's or cylinder's ``radius: normal(12.7, 0.01)`` is an L parameter named
``ENTITY.radius``: its nominal value is the distribution's mean and its deviation from it is
the distribution shifted by that mean, as every L in bcad is a deviation from nominal. It is
integrated by solve and identified by calibrate like any other L. It enters where the radius
is read off a computed pose: the curvilinear coordinates of ``point_on_sphere`` and
``point_on_cylinder`` and of a measurement read in a sphere or a cylinder
(:class:`bcad.compile.relations.SurfaceCoordinates`). The relations that use a radius as a
constant of their geometry (a sphere on a face, a ball in a socket, a peg in a hole) need it
exactly known.
"""

from __future__ import annotations

from bcad.compile.parameters import DistributionGroup, Parameter, ParameterTable
from bcad.model.distributions import Normal, TruncatedNormal, Uniform
from bcad.model.problem import Problem

#: a normal radius must stay this many standard deviations above 0
MARGIN = 6.0
#: the relations and readings that take an uncertain radius
TAKES_UNCERTAIN_RADIUS = ("point_on_sphere", "point_on_cylinder")


def is_uncertain(value) -> bool:
    return not isinstance(value, (int, float))


def nominal_radius(entity) -> float:
    """The radius, or its distribution's mean."""
    radius = entity.radius
    return float(radius) if not is_uncertain(radius) else float(radius.moments()[0][0])


def deviation(distribution, nominal: float):
    """The distribution of the radius's deviation from ``nominal``, or None if it may reach 0."""
    if isinstance(distribution, Normal):
        return Normal(mean=distribution.mean - nominal, std=distribution.std) if distribution.mean > MARGIN * distribution.std else None
    if isinstance(distribution, Uniform):
        return Uniform(low=distribution.low - nominal, high=distribution.high - nominal) if distribution.low > 0 else None
    if isinstance(distribution, TruncatedNormal):
        if not distribution.low > 0:
            return None
        return TruncatedNormal(mean=distribution.mean - nominal, std=distribution.std, low=distribution.low - nominal,
                               high=distribution.high - nominal)
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
            raise doc.error(("entities", index, "radius"),
                            f"the radius of '{entity.name}' is {radius.shorthand()}; a radius takes a distribution of one "
                            "number: normal, uniform or truncnormal")
        shifted = deviation(radius, nominal_radius(entity))
        if shifted is None:
            raise doc.error(("entities", index, "radius"),
                            f"the radius of '{entity.name}' is {radius.shorthand()}, which may reach 0; expected a normal "
                            f"whose mean is over {MARGIN:g} std, or a uniform or truncnormal above 0")
        columns[entity.name] = len(table.l)
        table.l.append(Parameter(f"{entity.name}.radius", -1, -1))
        table.l_groups.append(DistributionGroup(shifted, (columns[entity.name],)))
    return columns
