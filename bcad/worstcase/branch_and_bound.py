"""Certified maximum of the first-order pose error over the clearance bounds.

The problems of Berger et al. (2010), max |dp_r| and max |dp_t| subject to
Eq. 6-9, are both max |A x| over x in C, with C a product of discs and
intervals (one disc and one interval per clearance of each joint). Since
|A x| = max over unit u of u^T A x,

    max_{x in C} |A x| = max_{|u| = 1} f(u),   f(u) = h_C(A^T u)
                       = sum over discs rho |B u| + sum over intervals zeta |c^T u|,

where h_C is C's support function. f is convex and positively homogeneous;
the search is over the 2-sphere whatever the number of joints, and since
f(-u) = f(u), over the half-space z >= 0 only.

Branch and bound on a geodesic triangulation of that hemisphere (four
octahedron faces, each split into four by its edge midpoints):

* upper bound of a cell with vertices v_1, v_2, v_3: any unit u in the cone
  they span is u = sum mu_i v_i, mu_i >= 0, with sum mu_i <= 1 / d, d the
  distance from the origin to the triangle's plane; f sublinear gives
  f(u) <= max_i f(v_i) / d. The bound is exact at the vertices and its excess
  shrinks with the square of the cell's size, so the relative gap reaches
  1e-6 after about ten subdivisions. Every f(v_i) and d are computed with
  outward-rounded interval arithmetic on a certified enclosure of A
  (:mod:`bcad.worstcase.error_map`), and the cell's bound is inflated by
  1e-12 relative: the float midpoints of shared edges can leave slivers of
  directions about 1e-16 rad wide between neighbouring cones, and f, a
  support function, changes by at most max f times the angle (its gradient
  A x*(u) is no longer than max |A x|), so the margin covers them.
* lower bound: for the best direction found, x* = argmax_{x in C} u^T A x
  (each disc's point along B u, each interval's end along c^T u), pulled a
  few ulps inside C and checked to be feasible in exact arithmetic; |A x*|,
  bounded from below in interval arithmetic, is a true lower bound.

Cells whose bound falls below the lower bound / (1 - tol) are settled; the
certified upper bound is the largest bound of the settled cells.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from bcad.worstcase.error_map import ErrorMap
from bcad.worstcase.intervals import Interval, down, norm_lower, norm_upper, up

COVERING_MARGIN = 1e-12
MAX_LEVELS = 40
#: open cells at most in one level: beyond it the search stops with the gap it reached (still a
#: certified bound), so no tolerance can exhaust memory
MAX_OPEN_CELLS = 400_000

# (rows of M_j, clearance column, kind) for each problem: rows 0-2 pair R_j u
# with dr_j (rotation) or dt_j (translation); rows 3-5 pair [p_j]x R_j u with dr_j;
# rows 6 and 7 pair the rz variable (dr_z, or a link's absolute turn) with its
# rotation and translation effects (bcad.worstcase.error_map).
BLOCKS = {
    "rotation": [((0, 1), 0, "disc"), ((6,), 1, "interval")],
    "translation": [((3, 4), 0, "disc"), ((7,), 1, "interval"), ((0, 1), 2, "disc"), ((2,), 3, "interval")],
}
# Where each block's variables sit in the error screw ds_j = [dr; dt].
SCREW_SLOTS = {
    "rotation": [(0, 1), (2,)],
    "translation": [(0, 1), (2,), (3, 4), (5,)],
}


@dataclass
class MaxErrorResult:
    max: float
    upper_bound: float
    argmax: np.ndarray  # (n, 6) error screws
    seconds: float
    cells: int
    levels: int
    #: whether the relative gap reached the tolerance (False: stopped at MAX_OPEN_CELLS or MAX_LEVELS)
    converged: bool = True

    @property
    def gap(self) -> float:
        return 0.0 if self.upper_bound == 0 else (self.upper_bound - self.max) / self.upper_bound


def _transposed_map(error_map: ErrorMap, directions: np.ndarray, rows: list[int]) -> Interval:
    """Enclosures of the rows ``rows`` of M_j u for every direction u: shape (P, n, len(rows))."""
    M = error_map.M
    products = Interval(M.lo[None, :, rows], M.hi[None, :, rows]).scale(directions[:, None, None, :])
    return products.sum(axis=3)


def support_upper(error_map: ErrorMap, directions: np.ndarray, problem: str) -> np.ndarray:
    """Certified upper bounds of f(u) = h_C(A^T u) for directions (P, 3)."""
    used = sorted({row for rows, _column, _kind in BLOCKS[problem] for row in rows})
    W = _transposed_map(error_map, directions, used)
    at = {row: index for index, row in enumerate(used)}
    total = np.zeros(len(directions))
    for rows, column, kind in BLOCKS[problem]:
        radius = error_map.clearance[:, column][None, :]  # (1, n)
        if kind == "disc":
            size = norm_upper([W[:, :, at[r]] for r in rows])
        else:
            size = W[:, :, at[rows[0]]].magnitude()
        terms = up(radius * size)
        for j in range(terms.shape[1]):
            total = up(total + terms[:, j])
    return total


def support_estimate(error_map: ErrorMap, directions: np.ndarray, problem: str) -> np.ndarray:
    """f(u) in plain floating point, to rank directions."""
    W = np.einsum("nrc,pc->pnr", error_map.M_float, directions)
    total = np.zeros(len(directions))
    for rows, column, kind in BLOCKS[problem]:
        radius = error_map.clearance[:, column]
        size = np.linalg.norm(W[:, :, list(rows)], axis=2) if kind == "disc" else np.abs(W[:, :, rows[0]])
        total += size @ radius
    return total


def maximiser(error_map: ErrorMap, direction: np.ndarray, problem: str) -> np.ndarray:
    """x* = argmax_{x in C} u^T A x, as (n, 6) error screws, certified feasible."""
    w = error_map.M_float @ direction  # (n, 8)
    screws = np.zeros((error_map.joints, 6))
    for (rows, column, kind), slots in zip(BLOCKS[problem], SCREW_SLOTS[problem]):
        radius = error_map.clearance[:, column]
        if kind == "disc":
            vector = w[:, list(rows)]
            norm = np.linalg.norm(vector, axis=1)
            safe = np.where(norm > 0, norm, 1.0)
            point = np.where(norm[:, None] > 0, vector / safe[:, None], np.array([1.0, 0.0]))
            point = point * (radius * (1.0 - 8 * np.finfo(float).eps))[:, None]
            # Exact feasibility: x^2 + y^2 <= r^2 with the left side rounded up, the right down
            # (a zero radius gives the point 0, feasible as it is).
            while True:
                left = up(up(point[:, 0] * point[:, 0]) + up(point[:, 1] * point[:, 1]))
                bad = (left > down(radius * radius)) & (radius > 0)
                if not np.any(bad):
                    break
                point[bad] *= 1.0 - 1e-15
            screws[:, list(slots)] = point
        else:
            screws[:, slots[0]] = np.where(w[:, rows[0]] >= 0, radius, -radius)
    return screws


def error_lower(error_map: ErrorMap, screws: np.ndarray, problem: str) -> float:
    """A certified lower bound of |dp| (the problem's part) for given error screws."""
    rows = [row for block_rows, _column, _kind in BLOCKS[problem] for row in block_rows]
    slots = [slot for block_slots in SCREW_SLOTS[problem] for slot in block_slots]
    # dp_k = sum over joints j and paired (row, slot) of M_j[row, k] x_j[slot]
    terms = Interval(error_map.M.lo[:, rows, :], error_map.M.hi[:, rows, :]).scale(screws[:, slots][:, :, None])
    total = Interval(terms.lo.reshape(-1, 3), terms.hi.reshape(-1, 3)).sum(axis=0)
    return float(norm_lower([total[k] for k in range(3)]))


def error_value(error_map: ErrorMap, screws: np.ndarray, problem: str) -> float:
    """|dp| (the problem's part) in floating point."""
    dp = np.zeros(3)
    for (rows, _column, _kind), slots in zip(BLOCKS[problem], SCREW_SLOTS[problem]):
        for row, slot in zip(rows, slots):
            dp += error_map.M_float[:, row, :].T @ screws[:, slot]
    return float(np.linalg.norm(dp))


def _plane_distance_lower(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Certified lower bound of the distance from the origin to the planes of triangles (a, b, c)."""
    A, B, C = Interval(a), Interval(b), Interval(c)
    e1, e2 = B - A, C - A
    normal = [
        e1[:, 1] * e2[:, 2] - e1[:, 2] * e2[:, 1],
        e1[:, 2] * e2[:, 0] - e1[:, 0] * e2[:, 2],
        e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0],
    ]
    dot = normal[0] * A[:, 0] + normal[1] * A[:, 1] + normal[2] * A[:, 2]
    return down(dot.mignitude() / norm_upper(normal))


class _Triangulation:
    """Vertices of a geodesic triangulation, with vectorised edge-midpoint subdivision."""

    def __init__(self, vertices: np.ndarray):
        self.vertices = np.asarray(vertices, dtype=float)
        self.edge_keys = np.zeros(0, dtype=np.int64)  # sorted keys of split edges
        self.edge_vertex = np.zeros(0, dtype=np.int64)  # their midpoint's index

    def split(self, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The four children of each triangle, and the indices of vertices it had to add."""
        first = triangles[:, [0, 1, 2]]
        second = triangles[:, [1, 2, 0]]
        low, high = np.minimum(first, second), np.maximum(first, second)
        keys = low.astype(np.int64) * (1 << 31) + high
        unique, inverse = np.unique(keys, return_inverse=True)
        position = np.searchsorted(self.edge_keys, unique)
        known = (
            (position < len(self.edge_keys)) & (self.edge_keys[np.minimum(position, len(self.edge_keys) - 1)] == unique)
            if len(self.edge_keys)
            else np.zeros(len(unique), dtype=bool)
        )
        index = np.empty(len(unique), dtype=np.int64)
        index[known] = self.edge_vertex[position[known]]
        fresh = np.flatnonzero(~known)
        added = np.arange(len(self.vertices), len(self.vertices) + len(fresh))
        if len(fresh):
            a = self.vertices[unique[fresh] >> 31]
            b = self.vertices[unique[fresh] & ((1 << 31) - 1)]
            middle = a + b
            self.vertices = np.concatenate([self.vertices, middle / np.linalg.norm(middle, axis=1, keepdims=True)])
            index[fresh] = added
            order = np.argsort(np.concatenate([self.edge_keys, unique[fresh]]), kind="stable")
            self.edge_keys = np.concatenate([self.edge_keys, unique[fresh]])[order]
            self.edge_vertex = np.concatenate([self.edge_vertex, added])[order]
        mids = index[inverse].reshape(-1, 3)  # midpoints of edges (0,1), (1,2), (2,0)
        i, j, k = triangles[:, 0], triangles[:, 1], triangles[:, 2]
        m_ij, m_jk, m_ki = mids[:, 0], mids[:, 1], mids[:, 2]
        children = np.concatenate(
            [
                np.stack([i, m_ij, m_ki], axis=1),
                np.stack([m_ij, j, m_jk], axis=1),
                np.stack([m_ki, m_jk, k], axis=1),
                np.stack([m_ij, m_jk, m_ki], axis=1),
            ]
        )
        return children, added


#: a certified bound below the smallest normal double is an error of 0 to within what doubles resolve
#: (a tool point on its joint's axis turns in place: rounding leaves bounds of 1e-323)
ZERO_ERROR = float(np.finfo(float).tiny)


def clearance_enters(error_map: ErrorMap, problem: str) -> bool:
    """Whether any clearance enters the ``problem``'s error (rotation: the rotation clearances;
    translation: all of them); where none does, the error is 0 exactly, in either model."""
    columns = {column for _rows, column, _kind in BLOCKS[problem]}
    return bool(np.any(error_map.clearance[:, sorted(columns)] > 0))


def reached_gap(lower: float, upper: float) -> float:
    """(upper - lower) / upper, the gap a search reached; 0 where the bound is below ZERO_ERROR."""
    return (upper - lower) / upper if upper >= ZERO_ERROR else 0.0


def certified_maximum(error_map: ErrorMap, problem: str, tol: float = 1e-6) -> MaxErrorResult:
    """max |dp_r| (``problem="rotation"``) or max |dp_t| (``"translation"``) with a certified bound."""
    start = time.perf_counter()
    if not clearance_enters(error_map, problem):
        # No clearance enters this error: the error set is {0}, exactly.
        return MaxErrorResult(0.0, 0.0, np.zeros((error_map.joints, 6)), time.perf_counter() - start, 0, 0)
    mesh = _Triangulation(np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0, 0, 1]]))
    triangles = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    upper = support_upper(error_map, mesh.vertices, problem)
    estimate = support_estimate(error_map, mesh.vertices, problem)

    best_screws = maximiser(error_map, mesh.vertices[int(np.argmax(estimate))], problem)
    lower = error_lower(error_map, best_screws, problem)
    settled_bound = 0.0
    cells = 0
    level = 0
    converged = True
    for level in range(MAX_LEVELS):
        V = mesh.vertices
        distance = _plane_distance_lower(V[triangles[:, 0]], V[triangles[:, 1]], V[triangles[:, 2]])
        vertex_bound = np.max(upper[triangles], axis=1)
        bound = up(up(vertex_bound / np.where(distance > 0, distance, np.nan)) * (1.0 + COVERING_MARGIN))
        bound = np.where(distance > 0, bound, np.inf)  # a degenerate cell is never settled, only split
        cells += len(triangles)
        threshold = lower / (1.0 - tol) if tol < 1.0 else np.inf
        done = (bound <= threshold) | (bound < ZERO_ERROR)
        if np.any(done):
            settled_bound = max(settled_bound, float(bound[done].max()))
        open_cells = triangles[~done]
        if len(open_cells) == 0:
            break
        if level == MAX_LEVELS - 1 or 4 * len(open_cells) > MAX_OPEN_CELLS:
            settled_bound = max(settled_bound, float(bound[~done].max()))
            converged = False
            break
        triangles, added = mesh.split(open_cells)
        if len(added):
            directions = mesh.vertices[added]
            upper = np.concatenate([upper, support_upper(error_map, directions, problem)])
            estimate = np.concatenate([estimate, support_estimate(error_map, directions, problem)])
            screws = maximiser(error_map, mesh.vertices[int(np.argmax(estimate))], problem)
            value = error_lower(error_map, screws, problem)
            if value > lower:
                lower, best_screws = value, screws
    return MaxErrorResult(
        max=lower,
        upper_bound=max(settled_bound, lower),
        argmax=best_screws,
        seconds=time.perf_counter() - start,
        cells=cells,
        levels=level + 1,
        converged=converged,
    )
