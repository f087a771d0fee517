"""Edges declared in a problem file turned into graph links, with their checks.

The checks are those of the status vector (Sect. 3.1, item 3): an L
parameter needs a distribution, an F parameter may not have one, and an X
parameter needs bounds (or a prior with bounded support).
"""

from __future__ import annotations

import math

from bcad.compiler.graph import GraphLink
from bcad.compiler.units import parameter_scale, pose_to_internal
from bcad.model.pose import LENGTH_PARAMETERS, PARAMETERS, parameter_group
from bcad.model.problem import PoseSpec, Units
from bcad.model.source import Location, SourceDocument

STATUS_WORDS = {"X": "X (unknown)", "L": "L (free)", "F": "F (fixed)"}


def edge_from_spec(
    name: str, parent: str, child: str, spec: PoseSpec, loc: Location, units: Units, rank: str
) -> GraphLink:
    """A graph link from a pose/status/distributions/bounds spec, converted to internal units."""
    link = GraphLink(name, parent, child, pose_to_internal(spec.pose, units), spec.status, rank=rank, loc=loc)
    for key, distribution in spec.distributions.items():
        group = parameter_group(key)
        link.distributions[group] = distribution.scaled(parameter_scale(group[0], units))
    for key, (low, high) in spec.bounds.items():
        scale = parameter_scale(key, units)
        link.bounds[key] = (low * scale, high * scale)
    if "X" in spec.status:
        # A bounded prior stands in for missing bounds (check_edge guarantees one of the two).
        for parameter, letter in zip(PARAMETERS, spec.status):
            if letter == "X" and parameter not in link.bounds:
                link.bounds[parameter] = tuple(link.distributions[(parameter,)].support)
    return link


def check_edge(spec: PoseSpec, loc: Location, doc: SourceDocument) -> None:
    """Check a spec's distributions and bounds against its status vector."""
    status = dict(zip(PARAMETERS, spec.status))
    if getattr(spec, "close", None) and "X" in spec.status:
        # said before anything about the X's bounds: a closing link has none to give
        raise doc.error(loc + ("status",), closing_x_message(spec.name, spec.status, asked=True))
    covered: dict[str, str] = {}
    for key, distribution in spec.distributions.items():
        where = loc + ("distributions", key)
        group = parameter_group(key)
        if len(group) != distribution.dimension:
            raise doc.error(
                where,
                f"{distribution.type} covers {distribution.dimension} parameter(s) but '{key}' names {len(group)}"
                + ("; write a pair such as 'tx,ty: disc(0.05)'" if distribution.dimension == 2 else ""),
                key=True,
            )
        if len({parameter in LENGTH_PARAMETERS for parameter in group}) > 1:
            raise doc.error(
                where,
                f"'{key}' mixes a translation and a rotation; a pair must be two of tx ty tz or two of rx ry rz",
                key=True,
            )
        for parameter in group:
            if parameter in covered:
                raise doc.error(
                    where, f"parameter {parameter} already has a distribution under '{covered[parameter]}'", key=True
                )
            covered[parameter] = key
            if status[parameter] == "F":
                raise doc.error(
                    where,
                    f"parameter {parameter} is F (fixed) in status {spec.status} but has a distribution; "
                    "make it L (free) or X (unknown), or remove the distribution",
                    key=True,
                )
            if status[parameter] == "X" and len(group) > 1:
                raise doc.error(where, f"a prior on X parameters must be one-dimensional; '{key}' names two", key=True)
    for parameter, letter in status.items():
        if letter == "L" and parameter not in covered:
            raise doc.error(
                loc + ("status",),
                f"parameter {parameter} is L (free) in status {spec.status} but has no distribution; "
                f"add one under distributions, e.g. '{parameter}: normal(0, 0.01)'",
            )
    for key in spec.bounds:
        if status.get(key) != "X":
            raise doc.error(
                loc + ("bounds", key),
                f"bounds are for X (unknown) parameters; {key} is {STATUS_WORDS.get(status.get(key), key)} in "
                f"status {spec.status}",
                key=True,
            )
    for parameter, (low, high) in spec.bounds.items():
        prior = spec.distributions.get(parameter)
        if prior is not None and prior_outside_bounds(prior, low, high):
            raise doc.error(loc + ("distributions", parameter), prior_outside_message(parameter, prior, low, high))
    for parameter, letter in status.items():
        if letter != "X" or parameter in spec.bounds:
            continue
        prior = spec.distributions.get(parameter)
        if prior is None or not all(math.isfinite(v) for v in getattr(prior, "support", (-math.inf, math.inf))):
            raise doc.error(
                loc + ("status",),
                f"parameter {parameter} is X (unknown) in status {spec.status} but has no bounds; "
                f"add e.g. 'bounds: {{{parameter}: [-1, 1]}}' or a uniform prior",
            )


def closing_x_message(name: str, status: str, asked: bool = False) -> str:
    """Why a closing link (``asked``: by its close: true) may have no X."""
    how = " (close: true)" if asked else ""
    return (
        f"'{name}' closes a cycle{how}, so its pose is computed from the cycle (Eq. 1); "
        f"it cannot have X parameters (status {status})"
    )


def prior_outside_bounds(prior, low: float, high: float) -> bool:
    """Whether a prior on an X puts no probability within its bounds [low, high] (the same units):
    its support and the bounds do not overlap."""
    support = getattr(prior, "support", (-math.inf, math.inf))
    return not min(support[1], high) > max(support[0], low)


def prior_outside_message(name: str, prior, low: float, high: float) -> str:
    """The refusal of :func:`prior_outside_bounds`: p(X) is 0 wherever the search may go."""
    support = ", ".join(f"{value:.6g}" for value in prior.support)
    return (
        f"the prior on {name} (its support [{support}]) puts no probability within its bounds "
        f"[{low:.6g}, {high:.6g}]: p(X) is 0 wherever the search may go; move the prior or the bounds"
    )
