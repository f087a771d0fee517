"""Geometric relations compiled to equality and inequality constraints.

A relation is a link between two entity frames whose pose Q (child entity
frame in parent entity frame, after the relation's frame shifts) must satisfy
equality constraints ``E(Q) = 0`` (which parameters the relation constrains)
and inequality constraints ``C(Q) <= 0`` (Sect. 3.1 of the 2000 paper, item
2). Inequalities are signed distances in length units (positive outside),
evaluated on batches of transforms, so that the tempered relaxation of
Sect. 4.2.1 can widen them smoothly; each has a width, the scale of that
relaxation (Fig. 2). The kinds of the problem language build these (one module each in
:mod:`bcad.relations`); the tests check each against a brute-force computation.

Transforms arrive as ``columns`` (``columns[j]``: column j of the rotations,
shape (3, *batch)) and ``translations`` (3, *batch).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from bcad.kinematics.se3 import rpy_entries
from bcad.numerics.angles import cos_sin
from bcad.tempering import relaxed_log_indicator


def polygon_half_planes(polygon: list[tuple[float, float]]) -> tuple[np.ndarray, np.ndarray]:
    """Outward unit normals (k, 2) and offsets (k,) of a counter-clockwise convex polygon.

    A point p is inside iff ``normals @ p - offsets <= 0`` for every edge.
    """
    vertices = np.asarray(polygon, dtype=float)
    edges = np.roll(vertices, -1, axis=0) - vertices
    normals = np.column_stack([edges[:, 1], -edges[:, 0]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    offsets = np.einsum("ij,ij->i", normals, vertices)
    return normals, offsets


def _polygon_widths(polygon, normals: np.ndarray) -> np.ndarray:
    """The polygon's width along each edge normal."""
    projections = normals @ np.asarray(polygon, dtype=float).T
    return projections.max(axis=1) - projections.min(axis=1)


def _per_row(values: np.ndarray, batch: tuple[int, ...]) -> np.ndarray:
    """A per-inequality array (k,), or bound to samples (k, N), shaped to broadcast with (k, *batch)."""
    if values.ndim == 1:
        return values.reshape((-1,) + (1,) * len(batch))
    return values.reshape((values.shape[0],) + (1,) * (len(batch) - 1) + (values.shape[1],))


def _project(normals: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """n_k . xy for normals (k, 2), or bound to samples (k, 2, N), and points (2, *batch): (k, *batch)."""
    if normals.ndim == 2:
        return np.tensordot(normals, xy, axes=(1, 0))
    batch = xy.shape[1:]
    shaped = normals.reshape(normals.shape[:2] + (1,) * (len(batch) - 1) + (normals.shape[2],))
    return np.sum(shaped * xy[None], axis=1)


def _radial(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.sqrt(x * x + y * y)


@dataclass(frozen=True)
class RelationConstraint:
    """Constraints of one relation on its link's pose Q: the parameters its equalities set to 0
    (``constrained``) and ``widths.size`` inequalities (subclasses' :meth:`inequalities_from`)."""

    kind: str
    constrained: tuple[str, ...]
    widths: np.ndarray  # (count,): each inequality's tempering scale
    #: uncertain dimensions of the geometry: (attribute, L column, coefficients shaped like
    #: the attribute): each sample's attribute is its nominal value + coefficients x L[column]
    #: (:meth:`bind`). Named by the dimension's L parameter until the compiler resolves it to its column.
    uncertain: tuple = field(default=(), kw_only=True)

    #: whether the signed distances are linear in the translation and in the rotation's columns
    #: (a face's polygon, a segment): a first-order distance about a pose is then exact up to the
    #: rotation's second order, and the linearised surrogate may use it
    #: (:meth:`bcad.bayes.linear.LinearModel._log_inequalities`)
    linear_in_pose = False

    @property
    def depends_on_rotation(self) -> bool:
        """Whether the signed distances depend on the pose's rotation (not where a point's position
        alone is constrained: its distances need no rotation matrices, and their linearisation
        no rotation steps)."""
        return True

    @property
    def inequality_count(self) -> int:
        return int(self.widths.size)

    def bind(self, columns) -> RelationConstraint:
        """The relation with each sample's geometry: ``columns[c]`` (N,) the samples' L column c
        (a batch's ``Samples.columns``). The bound attributes gain a trailing sample axis, which
        broadcasts with the transforms' batch (N,) or (P, N)."""
        if not self.uncertain:
            return self
        values: dict[str, np.ndarray] = {}
        for attribute, column, coefficients in self.uncertain:
            base = values.get(attribute)
            if base is None:
                base = np.asarray(getattr(self, attribute), dtype=float)[..., None]
            values[attribute] = base + np.asarray(coefficients, dtype=float)[..., None] * np.asarray(columns[column])
        return replace(self, uncertain=(), **values).rebuilt()

    def rebuilt(self) -> RelationConstraint:
        """The geometry derived from bound attributes (a polygon's half-planes from its vertices)."""
        return self

    def dimension_variance(self, poses: np.ndarray, variances: np.ndarray) -> np.ndarray:
        """Each inequality's variance from the uncertain dimensions at poses (P, 6), to first order
        (central differences of one std either side), for the linearised surrogate: (P, count)."""
        poses = np.atleast_2d(poses)
        total = np.zeros((len(poses), self.inequality_count))
        for column in {column for _, column, _ in self.uncertain}:
            std = float(np.sqrt(max(variances[column], 0.0)))
            if std == 0.0:
                continue
            # each pose twice, its dimension one std either side: the samples of one batch of 2P
            alone = replace(self, uncertain=tuple(u for u in self.uncertain if u[1] == column))
            bound = alone.bind({column: np.tile([std, -std], len(poses))})
            distances = bound.inequalities(np.repeat(poses, 2, axis=0))  # (2P, count)
            total += (0.5 * (distances[0::2] - distances[1::2])) ** 2
        return total

    #: the relation's pose is in curvilinear coordinates (:class:`PointOnSurface`: spherical or
    #: cylindrical about a surface), not Cartesian; only a closing link's computed pose can be
    curvilinear = False

    def inequalities_from(self, columns, translations: np.ndarray) -> np.ndarray:
        """Signed distances C(Q), shape (count, *batch); inside when all <= 0."""
        return np.zeros((0,) + translations.shape[1:])

    def inequalities(self, poses: np.ndarray) -> np.ndarray:
        """Signed distances for poses (N, 6) (in the relation's coordinates), shape (N, count)."""
        poses = np.atleast_2d(poses)
        translations = poses[:, :3].T
        if self.curvilinear:
            translations = self.cartesian(translations)
        # columns[j]: the rotation's column j (3, N)
        columns = np.swapaxes(rpy_entries(poses[:, 3:]), 0, 1) if self.depends_on_rotation else None
        return self.inequalities_from(columns, translations).T

    def log_satisfaction(self, columns, translations: np.ndarray, temperature: float) -> np.ndarray:
        """log p(H | Q): 0 or -inf at T = 0, relaxed as in Sect. 4.2.1 for T > 0; shape (*batch)."""
        if self.inequality_count == 0:
            return np.zeros(translations.shape[1:])
        distances = self.inequalities_from(columns, translations)
        widths = self.widths.reshape((-1,) + (1,) * (distances.ndim - 1))
        return relaxed_log_indicator(distances, widths, temperature).sum(axis=0)


@dataclass(frozen=True)
class PolygonContact(RelationConstraint):
    """Points of the child (``points``, in its frame) inside the parent face's polygon, projected
    on its plane: one inequality per point and edge, ``normals @ xy - offsets``."""

    linear_in_pose = True

    points: np.ndarray = None  # (p, 3)
    normals: np.ndarray = None  # (k, 2), or bound to samples (k, 2, N)
    offsets: np.ndarray = None  # (k,), or (k, N)
    #: the polygon's vertices (k, 2), counter-clockwise: set where they are uncertain (bound: (k, 2, N))
    polygon: np.ndarray = field(default=None, kw_only=True)

    @property
    def depends_on_rotation(self) -> bool:
        """Only where a contact point is off the child frame's origin (a face's corners), or may be."""
        return bool(np.any(np.asarray(self.points) != 0.0)) or any(u[0] == "points" for u in self.uncertain)

    def rebuilt(self) -> PolygonContact:
        if self.polygon is None or np.ndim(self.polygon) != 3:
            return self
        vertices = self.polygon  # (k, 2, N): each sample's polygon
        edges = np.roll(vertices, -1, axis=0) - vertices
        normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1)
        normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
        return replace(self, normals=normals, offsets=np.sum(normals * vertices, axis=1))

    def inequalities_from(self, columns, translations):
        batch = translations.shape[1:]
        out = np.empty((len(self.points), len(self.offsets)) + batch)
        offsets = _per_row(self.offsets, batch)
        for index, point in enumerate(self.points):
            # a point (3,) or, bound to samples, (3, N): each coordinate broadcasts over the batch
            xy = translations[:2] + sum(columns[j][:2] * point[j] for j in range(3) if np.any(point[j] != 0.0))
            out[index] = _project(self.normals, xy) - offsets
        return out.reshape((-1,) + batch)


@dataclass(frozen=True)
class DiscOnFace(PolygonContact):
    """A disc of ``radius`` centred on the child frame's origin, normal to its z axis, inside the
    parent polygon: along each edge normal n (in the plane), the disc's projection reaches
    n . c + radius sqrt(1 - (n . a)^2), c its centre and a its axis (the support function of a
    disc; exact at any tilt)."""

    linear_in_pose = False  # the reach is not linear in the axis
    depends_on_rotation = True  # through the disc's axis

    radius: float = 0.0

    def inequalities_from(self, columns, translations):
        batch = translations.shape[1:]
        axis = columns[2]
        along = _project(self.normals, axis[:2])  # n . a, (k, *batch)
        reach = self.radius * np.sqrt(np.maximum(1.0 - along * along, 0.0))
        return _project(self.normals, translations[:2]) - _per_row(self.offsets, batch) + reach


@dataclass(frozen=True)
class OnSegment(RelationConstraint):
    """The child's origin between the parent edge's ends: -tx <= 0 and tx - length <= 0."""

    linear_in_pose = True
    depends_on_rotation = False

    length: float = 0.0

    def inequalities_from(self, columns, translations):
        return np.stack([-translations[0], translations[0] - self.length])


@dataclass(frozen=True)
class OverlappingSegments(RelationConstraint):
    """The child edge (from its origin along its x axis, ``child_length``) overlaps the parent
    edge [0, ``length``] along x: its start before the parent's end, its end after the parent's start."""

    linear_in_pose = True

    length: float = 0.0
    child_length: float = 0.0

    def inequalities_from(self, columns, translations):
        start = translations[0]
        end = start + self.child_length * columns[0][0]
        return np.stack([start - self.length, -end])


@dataclass(frozen=True)
class WithinBall(RelationConstraint):
    """The child's origin within ``clearance`` of the parent's: |t| - clearance <= 0."""

    depends_on_rotation = False

    clearance: float = 0.0

    def inequalities_from(self, columns, translations):
        return (np.sqrt(np.sum(translations * translations, axis=0)) - self.clearance)[None]


@dataclass(frozen=True)
class WithinCylinder(RelationConstraint):
    """The child's origin within ``radial`` of the parent cylinder's axis and between ``low`` and
    ``high`` along it: sqrt(tx^2 + ty^2) - radial, low - tz, tz - high."""

    depends_on_rotation = False

    radial: float = 0.0
    low: float = 0.0
    high: float = 0.0

    def inequalities_from(self, columns, translations):
        return np.stack(
            [
                _radial(translations[0], translations[1]) - self.radial,
                self.low - translations[2],
                translations[2] - self.high,
            ]
        )


#: the 16 angles of :func:`max_radial_on_circle`'s grid and their harmonics (cos, sin, cos 2, sin 2, 1)
_GRID = np.linspace(0.0, 2 * np.pi, 16, endpoint=False)
_GRID_HARMONICS = np.stack([np.cos(_GRID), np.sin(_GRID), np.cos(2 * _GRID), np.sin(2 * _GRID), np.ones(16)], axis=1)


#: where the first harmonic's amplitude exceeds this many times the second's, the squared radial
#: distance has a single maximum, within 24 degrees of the first harmonic's (module function below)
_FIRST_HARMONIC_DOMINANT = 5.0


def max_radial_on_circle(A: np.ndarray, B: np.ndarray, C: np.ndarray, radius: float) -> np.ndarray:
    """max over phi of |A + radius (cos phi B + sin phi C)| for 2-vectors (2, *batch): the largest
    distance from the z axis of a circle (or ellipse) projected on the xy plane.

    The squared distance is |A|^2 + w + a cos(phi - alpha) + b cos(2 phi - beta), a trigonometric
    polynomial of degree 2, with at most two local maxima (an ellipse's two ends along its major
    axis, moved by A). Newton's method on its derivative finds them:

    * where a > 5 b (a circle, or a peg's slightly tilted rim, off the axis): a stationary point
      has |sin(phi - alpha)| <= 2 b / a < 0.4, and within 24 degrees of alpha the curvature is
      below -0.91 a + 4 b < 0: one maximum there, on a concave stretch, which Newton's method
      climbs to from alpha (whose cosine and sine are the first harmonic's coefficients, scaled);
    * elsewhere (an ellipse: a tilted peg, or one near the axis) from the best of 16 grid
      angles, 4 steps where the curvature is negative. This can end on the lesser of two
      maxima, or stop between two close ones: on near-orthonormal B and C 2e-5 of the distance
      short (4 of 200,000 draws), with two maxima either side of the first harmonic's up to
      5e-4, on random ellipses up to 1.4e-2. Climbing from both maxima's grid angles, and
      uphill where the curvature is not negative, gives the exact maximum; but then the value
      is the larger of two smooth branches, with a kink where they exchange, on the ridge
      where a centred peg sits: the search's Newton climbs on a UR5 peg placement stopped 0.09
      below where Nelder-Mead goes (tests/bayes/test_global_search.py), where with one climb
      from the best grid angle they stop within 0.02 of it. A smooth formulation of the two
      maxima would serve both.

    Exact to rounding where a > 5 b (tests/relations/test_relations_geometry.py, against the best
    of 20001 angles)."""
    ab, ac = np.sum(A * B, axis=0), np.sum(A * C, axis=0)
    bb, cc, bc = np.sum(B * B, axis=0), np.sum(C * C, axis=0), np.sum(B * C, axis=0)
    batch = ab.shape
    # f = 2 r (ab cos + ac sin) + r^2 (bb cos^2 + 2 bc sin cos + cc sin^2) = p cos + q sin + u cos 2 + v sin 2 + w
    p, q = (2 * radius * ab).ravel(), (2 * radius * ac).ravel()
    u, v = (radius**2 * (bb - cc) / 2).ravel(), (radius**2 * bc).ravel()
    first, second = np.hypot(p, q), np.hypot(u, v)
    best = np.empty_like(p)
    dominant = first > _FIRST_HARMONIC_DOMINANT * second
    near = np.flatnonzero(dominant)
    if len(near):
        cos, sin = p[near] / first[near], q[near] / first[near]
        best[near] = _circle_newton(cos, sin, p[near], q[near], u[near], v[near])
    rest = np.flatnonzero(~dominant)
    if len(rest):
        best[rest] = _grid_maximum(p[rest], q[rest], u[rest], v[rest])
    best = best.reshape(batch) + radius**2 * (bb + cc) / 2
    return np.sqrt(np.maximum(np.sum(A * A, axis=0) + best, 0.0))


def _grid_maximum(p, q, u, v) -> np.ndarray:
    """max of p cos + q sin + u cos 2 + v sin 2 by Newton's method from the best of 16 grid angles
    (4 steps, taken where the curvature is negative). The grid's sines and cosines are constants
    (no trigonometry per point): the values on it are a (16, 4) matrix of harmonics times the
    coefficients. The angle is carried as its cosine and sine from there, turned by each step
    (:func:`bcad.numerics.angles.cos_sin` of the step: polynomials once the steps are small) and
    normalised at the end, so the value is f's at an angle."""
    on_grid = _GRID_HARMONICS[:, :4] @ np.stack([p, q, u, v])  # (16, N)
    start = np.argmax(on_grid, axis=0)
    c, s = _GRID_HARMONICS[start, 0], _GRID_HARMONICS[start, 1]
    for _ in range(4):
        c, s = _turned_back(c, s, _newton_step(c, s, p, q, u, v))
    norm = np.sqrt(c * c + s * s)
    return np.maximum(_harmonics(c / norm, s / norm, p, q, u, v), on_grid.max(axis=0))


def _turned_back(c: np.ndarray, s: np.ndarray, delta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cosine and sine of the angle whose cosine and sine are ``c`` and ``s``, minus ``delta``
    (:func:`bcad.numerics.angles.cos_sin` of the step: polynomials once the steps are small)."""
    cos_d, sin_d = cos_sin(delta)
    return c * cos_d + s * sin_d, s * cos_d - c * sin_d


def _harmonics(c, s, p, q, u, v):
    """p cos + q sin + u cos 2 + v sin 2 at the angle whose cosine and sine are ``c`` and ``s``."""
    return p * c + q * s + u * (2 * c * c - 1) + v * (2 * s * c)


def _newton_step(c, s, p, q, u, v):
    """Newton's step on the derivative of :func:`_harmonics` at the angle (c, s), f' / f'' (the
    angle minus it climbs), where the curvature f'' is negative; 0 elsewhere."""
    c2, s2 = 2 * c * c - 1, 2 * s * c
    d1 = -p * s + q * c - 2 * u * s2 + 2 * v * c2
    d2 = -p * c - q * s - 4 * u * c2 - 4 * v * s2
    return np.where(d2 < 0, d1 / np.where(d2 < 0, d2, -1.0), 0.0)


def _circle_newton(c: np.ndarray, s: np.ndarray, p, q, u, v, steps: int = 4) -> np.ndarray:
    """p cos + q sin + u cos 2 + v sin 2 at the maximum that Newton's method on its derivative
    climbs to from the angle whose cosine and sine are ``c`` and ``s``, on a concave stretch that
    holds it (each step at most 0.2 rad: from within 24 degrees, 4 reach it to rounding), and never
    below the start's value. The angle is carried as its cosine and sine, turned by each step
    (:func:`_turned_back`) and normalised at the end, so the value is f's at an angle."""
    at_start = _harmonics(c, s, p, q, u, v)
    for _ in range(steps):
        c, s = _turned_back(c, s, np.clip(_newton_step(c, s, p, q, u, v), -0.2, 0.2))
    norm = np.sqrt(c * c + s * s)
    return np.maximum(_harmonics(c / norm, s / norm, p, q, u, v), at_start)


@dataclass(frozen=True)
class PegInHole(RelationConstraint):
    """A peg (child cylinder, ``peg_radius``: origin at the end that goes in first, z along its
    axis, out of the hole) in a hole (parent cylinder, ``hole_radius``: origin at its bottom, z
    out of it, ``depth`` its length). With t the peg's end and a, u1, u2 its axes:

    * the peg's surface between its end and the hole's mouth inside the hole. The distance to
      the hole's axis is convex along each of the surface's lines (parallel to a), so its
      largest value is on the end's rim or on the surface's section by the mouth's plane
      z = depth (an ellipse: t + s a + R_peg (cos phi w1 + sin phi w2), s = (depth - tz) / a_z,
      w_i = u_i - (u_i,z / a_z) a): max radial on the rim - R_hole <= 0 and on the section
      - R_hole <= 0. So the tilt is limited by the clearance over the engaged length, and the
      rim's R_peg (1 / cos - 1) counts;
    * the end's rim above the bottom: R_peg sqrt(1 - a_z^2) - tz <= 0;
    * the end below the mouth (engaged): tz - depth <= 0;
    * the peg pointing out of the hole: -a_z <= 0.
    """

    hole_radius: float = 0.0
    peg_radius: float = 0.0
    depth: float = 0.0

    def inequalities_from(self, columns, translations):
        u1, u2, axis = columns[0], columns[1], columns[2]
        a_z = axis[2]
        safe = np.where(a_z > 1e-9, a_z, 1e-9)
        rim = max_radial_on_circle(translations[:2], u1[:2], u2[:2], self.peg_radius)
        s = (self.depth - translations[2]) / safe
        centre = translations[:2] + s * axis[:2]
        w1 = u1[:2] - (u1[2] / safe) * axis[:2]
        w2 = u2[:2] - (u2[2] / safe) * axis[:2]
        mouth = max_radial_on_circle(centre, w1, w2, self.peg_radius)
        # A peg that does not point out of the hole: its mouth test reads as far outside, finitely.
        limit = 1e6 * np.maximum(self.hole_radius, self.depth)
        mouth = np.where(a_z > 1e-9, np.minimum(mouth, limit), limit)
        tilt = np.sqrt(np.maximum(1.0 - a_z * a_z, 0.0))
        return np.stack(
            [
                rim - self.hole_radius,
                mouth - self.hole_radius,
                self.peg_radius * tilt - translations[2],
                translations[2] - self.depth,
                -a_z,
            ]
        )


@dataclass(frozen=True)
class SurfaceCoordinates:
    """A chain's curvilinear coordinates about a surface of ``radius`` (``to_coordinates``:
    :func:`spherical_coordinates` or :func:`cylindrical_coordinates`); with ``column`` set, the
    radius is not exactly known and each sample's is radius + L[column]
    (:mod:`bcad.compiler.dimensions`): :meth:`bind` gives a batch's map."""

    to_coordinates: object
    radius: float
    column: int | None = None

    def __call__(self, translations: np.ndarray) -> np.ndarray:
        return self.to_coordinates(translations, self.radius)

    def bind(self, samples):
        if self.column is None:
            return self
        # (N,): broadcasts over the translations' (3, N) and (3, P, N)
        return SurfaceCoordinates(self.to_coordinates, self.radius + samples.columns[self.column])

    def at(self, l_values: np.ndarray) -> SurfaceCoordinates:
        """The map at one value of L (nL,): the radius radius + L[column] where it is uncertain."""
        if self.column is None:
            return self
        return SurfaceCoordinates(self.to_coordinates, self.radius + float(l_values[self.column]))

    def gradients(self, translations: np.ndarray) -> np.ndarray:
        """d coordinates / d translation, (3 coordinates, 3 axes, *batch): exact
        (:func:`spherical_gradients`, :func:`cylindrical_gradients`)."""
        return COORDINATE_GRADIENTS[self.to_coordinates](translations, self.radius)

    def radius_rates(self, translations: np.ndarray) -> np.ndarray:
        """d coordinates / d radius, (3, *batch). Both maps are affine in the radius (an arc length
        is radius x angle, the distance rho - radius), so the rate is the map at radius 1 less the
        map at radius 0: (longitude, latitude, -1) on a sphere, (theta, 0, -1) on a cylinder."""
        return self.to_coordinates(translations, 1.0) - self.to_coordinates(translations, 0.0)


def surface_coordinates(relation: PointOnSurface, column: int | None = None) -> SurfaceCoordinates:
    """The chain's coordinates of a curvilinear relation (``column``: its uncertain radius's L)."""
    return SurfaceCoordinates(type(relation).to_coordinates, relation.radius, column)


def spherical_coordinates(translations: np.ndarray, radius: float) -> np.ndarray:
    """(tx, ty, tz) of a point in a sphere's frame -> (radius longitude, radius latitude, rho - radius):
    arc lengths on the sphere (longitude in (-pi, pi], latitude in [-pi/2, pi/2]) and the distance
    to the surface, all lengths."""
    x, y, z = translations
    rho = np.sqrt(x * x + y * y + z * z)
    longitude = np.arctan2(y, x)
    latitude = np.arctan2(z, np.sqrt(x * x + y * y))
    return np.stack([radius * longitude, radius * latitude, rho - radius])


def spherical_gradients(translations: np.ndarray, radius: float) -> np.ndarray:
    """d :func:`spherical_coordinates` / d (tx, ty, tz), (3 coordinates, 3 axes, *batch). With
    r^2 = x^2 + y^2 and rho^2 = r^2 + z^2: d longitude = (-y, x, 0) / r^2, d latitude =
    (-x z / r, -y z / r, r) / rho^2 and d rho = (x, y, z) / rho (arc lengths times the radius)."""
    x, y, z = translations
    r2 = x * x + y * y
    r = np.sqrt(r2)
    rho2 = r2 + z * z
    rho = np.sqrt(rho2)
    zero = np.zeros_like(r)
    longitude = np.stack([_ratio(-y, r2), _ratio(x, r2), zero])
    latitude = np.stack([_ratio(-x * z, r * rho2), _ratio(-y * z, r * rho2), _ratio(r, rho2)])
    return np.stack([radius * longitude, radius * latitude, _ratio(translations, rho)])


def _ratio(numerator: np.ndarray, denominator: np.ndarray) -> np.ndarray:
    """numerator / denominator, 0 where the denominator is 0: on the axis of a sphere's poles or of a
    cylinder the longitude has no direction, and the latitude's slope is a kink whose central
    difference is 0 (likewise the distance at the centre)."""
    numerator, denominator = np.broadcast_arrays(numerator, denominator)
    return np.divide(numerator, denominator, out=np.zeros(numerator.shape), where=denominator != 0.0)


def cylindrical_gradients(translations: np.ndarray, radius: float) -> np.ndarray:
    """d :func:`cylindrical_coordinates` / d (tx, ty, tz), (3 coordinates, 3 axes, *batch). With
    r^2 = x^2 + y^2: d theta = (-y, x, 0) / r^2 (times the radius), d z = (0, 0, 1) and
    d r = (x, y, 0) / r."""
    x, y, _ = translations
    r2 = x * x + y * y
    r = np.sqrt(r2)
    zero, one = np.zeros_like(r), np.ones_like(r)
    theta = np.stack([_ratio(-y, r2), _ratio(x, r2), zero])
    return np.stack([radius * theta, np.stack([zero, zero, one]), np.stack([_ratio(x, r), _ratio(y, r), zero])])


def cartesian_from_spherical(coordinates: np.ndarray, radius: float) -> np.ndarray:
    """Inverse of :func:`spherical_coordinates`."""
    longitude, latitude = coordinates[0] / radius, coordinates[1] / radius
    rho = coordinates[2] + radius
    return np.stack(
        [rho * np.cos(latitude) * np.cos(longitude), rho * np.cos(latitude) * np.sin(longitude), rho * np.sin(latitude)]
    )


def cylindrical_coordinates(translations: np.ndarray, radius: float) -> np.ndarray:
    """(tx, ty, tz) of a point in a cylinder's frame -> (radius theta, z, rho - radius): the arc
    length round the axis (theta in (-pi, pi] from the frame's x axis), the height along the
    axis and the distance to the lateral surface, all lengths."""
    x, y, z = translations
    return np.stack([radius * np.arctan2(y, x), z, np.sqrt(x * x + y * y) - radius])


def cartesian_from_cylindrical(coordinates: np.ndarray, radius: float) -> np.ndarray:
    """Inverse of :func:`cylindrical_coordinates`."""
    theta, rho = coordinates[0] / radius, coordinates[2] + radius
    return np.stack([rho * np.cos(theta), rho * np.sin(theta), coordinates[1]])


#: each curvilinear map's exact derivative in the translation (:meth:`SurfaceCoordinates.gradients`)
COORDINATE_GRADIENTS = {spherical_coordinates: spherical_gradients, cylindrical_coordinates: cylindrical_gradients}


@dataclass(frozen=True)
class PointOnSurface(RelationConstraint):
    """A point on a curved surface of ``radius`` (the entity ``surface``): the relation's pose is
    in the surface's curvilinear coordinates, ``to_coordinates(translations, radius)`` (and
    back, ``to_cartesian``), whose tz is the distance to the surface."""

    depends_on_rotation = False

    radius: float = 0.0
    surface: str = ""
    curvilinear = True

    def cartesian(self, coordinates: np.ndarray) -> np.ndarray:
        """Cartesian translations (3, *batch) of the relation's coordinates (3, *batch)."""
        return type(self).to_cartesian(coordinates, self.radius)


@dataclass(frozen=True)
class PointOnSphere(PointOnSurface):
    """A point on a sphere: spherical coordinates (:func:`spherical_coordinates`)."""

    to_coordinates = staticmethod(spherical_coordinates)
    to_cartesian = staticmethod(cartesian_from_spherical)


@dataclass(frozen=True)
class PointOnCylinder(PointOnSurface):
    """A point on the lateral surface of a cylinder of ``length`` (its frame: z along the axis,
    origin at the base disc's centre): cylindrical coordinates (:func:`cylindrical_coordinates`);
    the point between the end discs is two inequalities, -z and z - length."""

    length: float = 0.0
    to_coordinates = staticmethod(cylindrical_coordinates)
    to_cartesian = staticmethod(cartesian_from_cylindrical)

    def inequalities_from(self, columns, translations):
        return np.stack([-translations[2], translations[2] - self.length])


def polygon_contact(kind: str, constrained: tuple[str, ...], points, polygon) -> PolygonContact:
    """Points of the child (in its frame) inside the parent face's ``polygon``, each inequality's
    tempering width the polygon's width along its normal."""
    normals, offsets = polygon_half_planes(polygon)
    widths = np.tile(_polygon_widths(polygon, normals), len(points))
    return PolygonContact(kind, constrained, widths, np.asarray(points, dtype=float), normals, offsets)


def disc_on_face(kind: str, polygon, radius: float) -> DiscOnFace:
    """A disc of ``radius`` on the child frame's origin inside the parent ``polygon``."""
    normals, offsets = polygon_half_planes(polygon)
    return DiscOnFace(
        kind, ("tz", "rx", "ry"), _polygon_widths(polygon, normals), np.zeros((1, 3)), normals, offsets, float(radius)
    )


def within_cylinder(kind: str, radius: float, length: float, inner_radius: float = 0.0) -> WithinCylinder:
    """A centre within R - r of a cylinder's axis and between r and L - r along it (r =
    ``inner_radius``: 0 for a point, a sphere's radius)."""
    radial = float(radius - inner_radius)
    low, high = float(inner_radius), float(length - inner_radius)
    return WithinCylinder(kind, (), np.array([2.0 * radial, high - low, high - low]), radial, low, high)
