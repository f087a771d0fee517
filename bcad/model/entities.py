"""Geometric entities attached to frames: point, face, edge, sphere, cylinder.

Every entity defines an *entity frame* relative to the frame it is attached
to; relations (:mod:`bcad.model.problem`) are links between entity frames.

* point: the entity frame is the host frame translated to ``at``.
* face: a planar convex polygon. ``pose`` places the face frame in the host
  frame; its z axis is the face's outward normal and the polygon's vertices
  lie in its xy plane (``vertices``, or ``size: [w, h]`` for a w x h rectangle
  centred on the face frame's origin).
* edge: a segment from ``start`` to ``end``; the entity frame has its origin
  at ``start`` and its x axis along the segment.
* sphere: ``center`` and ``radius``; the entity frame is at the centre.
* cylinder: ``pose`` places the cylinder frame (z along the axis, origin at the
  centre of the base disc), with ``radius`` and ``length``.

A sphere's or cylinder's ``radius`` may be a distribution (``normal(12.7, 0.01)``)
where it is not exactly known: it is then an L parameter ``ENTITY.radius``; so may each
coordinate of a point's ``at`` and of a sphere's ``center``: L parameters ``ENTITY.at[0]`` ...,
each of a face's ``size`` (``ENTITY.size[0]``, ``ENTITY.size[1]``) and of its ``vertices``
(``ENTITY.vertices[2][0]``), an edge's ``start`` and ``end`` (``ENTITY.start[0]`` ...) and a
cylinder's ``length`` (``ENTITY.length``)
(:mod:`bcad.compiler.dimensions`).
"""

from __future__ import annotations

import math
from typing import Annotated, Literal, Union

from pydantic import Field, model_validator

from bcad.model.base import StrictModel
from bcad.model.distributions import Distribution
from bcad.model.pose import LIMIT, Pose, Value
from bcad.relations.kind import nominal_value

#: a radius: a number, or a distribution of it when it is not exactly known (an L parameter
#: ``ENTITY.radius``: :mod:`bcad.compiler.dimensions`)
Radius = Union[Annotated[float, Field(gt=0.0, le=LIMIT)], Distribution]
#: a face's width or height, a cylinder's length: likewise (``ENTITY.size[0]``, ``ENTITY.length``)
Dimension = Radius


#: a dimension's value, or its distribution's mean (the relations read entities with it too)
nominal = nominal_value


Vector3 = Annotated[list[Value], Field(min_length=3, max_length=3)]
#: a position whose coordinates may each be a distribution (an L parameter ``ENTITY.at[k]``)
UncertainVector3 = Annotated[list[Value | Distribution], Field(min_length=3, max_length=3)]
Vector2 = Annotated[list[Value], Field(min_length=2, max_length=2)]
#: a face vertex whose coordinates may each be a distribution (an L parameter ``ENTITY.vertices[i][k]``)
UncertainVector2 = Annotated[list[Value | Distribution], Field(min_length=2, max_length=2)]


class _Entity(StrictModel):
    name: str
    frame: str = Field(description="the frame the entity is attached to")


class Point(_Entity):
    type: Literal["point"]
    at: UncertainVector3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])


class Face(_Entity):
    type: Literal["face"]
    pose: Pose = Field(default_factory=lambda: [0.0] * 6)
    vertices: list[UncertainVector2] | None = Field(None, max_length=1000)
    size: Annotated[list[Dimension], Field(min_length=2, max_length=2)] | None = None

    @model_validator(mode="after")
    def _polygon(self) -> Face:
        if (self.vertices is None) == (self.size is None):
            raise ValueError("a face needs exactly one of 'vertices' (a convex polygon) or 'size' ([w, h])")
        if self.size is not None and min(nominal(v) for v in self.size) <= 0:
            raise ValueError("a face's size must be positive")
        polygon = self.polygon()
        if len(polygon) < 3:
            raise ValueError("a face polygon needs at least 3 vertices")
        floor = _shortest([c for point in polygon for c in point])
        side = min(math.dist(a, b) for a, b in zip(polygon, polygon[1:] + polygon[:1]))
        if side < floor:
            raise ValueError(f"a face side of length {side:.3g} is too short: each must be at least {floor:.3g}")
        if not _is_strictly_convex(polygon):
            raise ValueError("face vertices must form a convex polygon, listed in order around it")
        return self

    def polygon(self) -> list[tuple[float, float]]:
        """Vertices counter-clockwise seen from the outward normal (+z)."""
        if self.size is not None:
            w, h = nominal(self.size[0]) / 2.0, nominal(self.size[1]) / 2.0
            return [(-w, -h), (w, -h), (w, h), (-w, h)]
        points = [(nominal(x), nominal(y)) for x, y in self.vertices]
        return points if _signed_area(points) > 0 else points[::-1]

    def polygon_index(self, vertex: int) -> int:
        """Where the ``vertex``-th of ``vertices`` sits in :meth:`polygon` (reversed if given clockwise)."""
        points = [(nominal(x), nominal(y)) for x, y in self.vertices]
        return vertex if _signed_area(points) > 0 else len(points) - 1 - vertex


class Edge(_Entity):
    type: Literal["edge"]
    start: UncertainVector3
    end: UncertainVector3

    @model_validator(mode="after")
    def _distinct(self) -> Edge:
        if self.nominal_start == self.nominal_end:
            raise ValueError("an edge needs distinct 'start' and 'end' points")
        start, end = self.nominal_start, self.nominal_end
        length, floor = math.dist(start, end), _shortest(start + end)
        if length < floor:
            raise ValueError(
                f"an edge of length {length:.3g} is too short to have a direction: 'start' and 'end' must be "
                f"at least {floor:.3g} apart"
            )
        return self

    @property
    def nominal_start(self) -> list[float]:
        return [nominal(v) for v in self.start]

    @property
    def nominal_end(self) -> list[float]:
        return [nominal(v) for v in self.end]


class Sphere(_Entity):
    type: Literal["sphere"]
    center: UncertainVector3 = Field(default_factory=lambda: [0.0, 0.0, 0.0])
    radius: Radius


class Cylinder(_Entity):
    type: Literal["cylinder"]
    pose: Pose = Field(default_factory=lambda: [0.0] * 6)
    radius: Radius
    length: Dimension

    @property
    def nominal_length(self) -> float:
        return nominal(self.length)


class Checkerboard(StrictModel):
    """A checkerboard's inner corners (OpenCV's pattern size is (columns, rows))."""

    rows: int = Field(ge=2, le=1000, description="inner corners along the board's y axis")
    columns: int = Field(ge=2, le=1000, description="inner corners along the board's x axis")
    square: float = Field(gt=0.0, le=LIMIT, description="the side of a square (length)")


class Target(_Entity):
    """Points a camera sees, fixed in the target's frame (``pose`` in its host frame): a
    checkerboard's inner corners (id r columns + c at (c square, r square, 0): OpenCV's object
    points; also a ChArUco board's corners or an AprilGrid's, written as the points they are) or
    a list of ``points`` (id: the position in the list)."""

    type: Literal["target"]
    pose: Pose = Field(default_factory=lambda: [0.0] * 6)
    checkerboard: Checkerboard | None = None
    points: list[Vector3] | None = Field(None, min_length=1, max_length=100_000)

    @model_validator(mode="after")
    def _one_layout(self):
        if (self.checkerboard is None) == (self.points is None):
            raise ValueError(
                "a target needs exactly one of 'checkerboard' ({rows, columns, square}) or 'points' ([[x, y, z], ...])"
            )
        if self.checkerboard is not None and self.checkerboard.rows * self.checkerboard.columns > 100_000:
            raise ValueError("a checkerboard has at most 100,000 corners")
        return self

    def corner_points(self) -> list[list[float]]:
        """Every point's coordinates in the target's frame (problem units), by id."""
        if self.points is not None:
            return [list(map(float, point)) for point in self.points]
        from bcad.kinematics.camera import checkerboard_points

        board = self.checkerboard
        return checkerboard_points(board.rows, board.columns, board.square).tolist()


Entity = Annotated[Point | Face | Edge | Sphere | Cylinder | Target, Field(discriminator="type")]


def _signed_area(points: list[tuple[float, float]]) -> float:
    return 0.5 * sum(x0 * y1 - x1 * y0 for (x0, y0), (x1, y1) in zip(points, points[1:] + points[:1]))


#: the shortest edge (or face side) relative to the larger of 1 and its coordinates' size: below it
#: the direction is lost to rounding (and squared lengths to underflow, below 1e-160)
SHORTEST = 1e-9


def _shortest(coordinates: list[float]) -> float:
    return SHORTEST * max(1.0, max(abs(c) for c in coordinates))


def _is_strictly_convex(points: list[tuple[float, float]]) -> bool:
    n = len(points)
    signs = set()
    for k in range(n):
        (x0, y0), (x1, y1), (x2, y2) = points[k], points[(k + 1) % n], points[(k + 2) % n]
        cross = (x1 - x0) * (y2 - y1) - (y1 - y0) * (x2 - x1)
        # sides turning by less than 1e-12 rad are one line (a scale-free test)
        if abs(cross) < 1e-12 * math.hypot(x1 - x0, y1 - y0) * math.hypot(x2 - x1, y2 - y1):
            return False
        signs.add(cross > 0)
    return len(signs) == 1 and abs(_signed_area(points)) > 0
