"""A bound on the exact clearance error that is tight to the third order of the clearances.

:func:`bcad.worstcase.exact.exact_upper_bounds` adds a scalar remainder to the first-order
maximum: its excess is of the order of sum_j a_j relative (1e-3 on the examples). This module
bounds the exact model itself, by branch and bound over directions as the first-order maximum
is (:mod:`bcad.worstcase.branch_and_bound`), with a sharper bound at each direction.

**The error as a support function.** With E(x) the exact error vector at the clearance
variables x in C, E = vee(skew(dR)) = sin(theta) n for the rotation (dR = exp(theta [n])) and
E = t, dP's translation, for the translation, the largest error is max_{x in C} |E(x)| =
max_{|u| = 1} F(u), F(u) = max_{x in C} u . E(x). F, a supremum of functions linear in u, is
sublinear, so the cone argument of the first-order branch and bound holds unchanged: over a
cell with vertices v_i, F <= max_i F(v_i) / d. For the rotation, theta <= sum_j |dr_j| < pi / 2
(checked), where sin is increasing: max theta = arcsin(max |E|).

**F at one direction u** (:func:`direction_bounds`). g = the first-order map's coefficients
(E's gradient at x = 0), x^ = the support point of g over C (each disc's point along its part
of g, each interval's end along its sign): the first-order maximiser. With G = grad (u . E)(x^)
(a prefix and a suffix sweep of the chain, the exponentials' derivatives in closed form: within
1e-14 relative, :func:`bcad.worstcase.exact.twist_exponential_derivatives`)
and a rigorous bound K(s) of the second directional derivative of u . E over C along steps of
per-joint sizes s (below), Taylor's theorem with the Lagrange remainder gives, for x = x^ + d in C,

    u . E(x) <= u . E(x^) + G . d + K(s) / 2.                                         (1)

Only the points with u . E(x) >= l, the exact error found by the search (a true lower bound),
can raise the maximum above l, and they lie near x^: since x^ maximises g . x over C, every
block b (a disc of radius rho or an interval of half-width zeta) loses

    drop_b = g_b . (x^_b - x_b) >= |g_b| |d_b|^2 / (2 rho)  (disc),  |g_b| |d_b|  (interval),

and (1) with g . d = -sum drop_b gives sum_b drop_b <= u . E(x^) - l + sum_b |G_b - g_b| |d_b| +
K(s) / 2: each |d_b| is bounded (and, starting from the bound of u . E about x = 0, the
bounds shrink in a few rounds to the order of the clearances squared). Then (1) over the
localised set, with G . d bounded per block by the smaller of h_b(G_b) - G_b . x^_b (the exact
maximum over the block) and |G_b - g_b| |d_b|, bounds F(u). Its excess over F(u) is of the order
of K s^2 with s ~ a^2: the clearances to the fourth power, 1e-8 relative on the examples.

**The second derivatives** (dP = prod_j exp(xi_j), xi_j = Ad(G_j^-1) ds_j, Eq. 11): for any
sub-multiplicative norm, ||D exp(X)[Y]|| <= ||Y|| e^||X|| and ||D^2 exp(X)[Y, Y]|| <= ||Y||^2 e^||X||,
so ||D^2 dP[d, d]|| <= (sum_j ||dxi_j||)^2 prod_j e^||xi_j||.

* rotation: the rotations are isometries (no exponential factor) and u . vee(skew(M)) =
  tr([u]^T M) / 2 <= ||M||_2 ([u]'s nuclear norm is 2): K = (sum_j s_r,j)^2, s_r,j = |d dr_j|.
* translation: t = sum_j R_{<j} t_j with R_{<j} = prod_{i<j} exp([omega_i]) and
  t_j = V(omega_j) v_j, V = int_0^1 exp(s [omega]) ds (||V|| <= 1, ||DV[w]|| <= |w| / 2,
  ||D^2 V[w, w]|| <= |w|^2 / 3), v_j linear in x (|v_j| <= b_j + |p_j| a_j =: v_j^max). With
  r_j = |d dr_j|, q_j = |d v_j| <= |d dt_j| + |p_j| r_j and B_j = sum_{i<j} r_i,
  K = sum_j [B_j^2 v_j^max + 2 B_j (r_j v_j^max / 2 + q_j) + r_j^2 v_j^max / 3 + r_j q_j]: a
  rotation with no lever arm (the tool's own dr_z) adds almost nothing, as it should.

**Free intervals.** An axial turn about an axis through the tool (the RX90's base and wrist at
the candle pose) has no first-order effect in any direction: the localisation cannot shrink it,
and its turn multiplies every later joint's step in K. Any point of such an interval maximises
the first-order part, so the set is split into sub-boxes along (at most MAX_FREE of) them, each
bounded about its own centre, and F(u) is the largest of their bounds (the candle's translation
gap: 1.09e-6 whole, 5.5e-7 in halves).

**Rounding.** The chains, their derivatives and the drop bounds are evaluated in
floating point; every direction's bound gets a margin of 1e-11 of its first-order value, four
orders above the rounding error of products of 4 x 4 matrices and two below the 1e-6 gap
asked. The first-order quantities the rest of :mod:`bcad.worstcase` certifies in interval
arithmetic are only used here through this margin.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass

import numpy as np

from bcad.worstcase.branch_and_bound import (
    BLOCKS,
    COVERING_MARGIN,
    SCREW_SLOTS,
    _plane_distance_lower,
    _Triangulation,
    support_upper,
)
from bcad.worstcase.error_map import ErrorMap
from bcad.worstcase.exact import ScaledVariables, arm_lengths, error_tangents, error_transforms, rotation_sine_cosine

#: relative margin of each direction's bound for floating-point rounding (module docstring)
ROUNDING_MARGIN = 1e-11
#: rounds of localisation per direction
LOCALISATION_ROUNDS = 8
#: pieces each free interval is split into, and free intervals split at most (module docstring)
FREE_PIECES = 2
MAX_FREE = 2
#: directions evaluated at once (each one chain per clearance variable)
DIRECTION_BLOCK = 64
MAX_LEVELS = 30
#: cells examined at most: where the sharp bounds' own excess is above the tolerance (a
#: configuration with joints that turn about axes through the tool), splitting stops gaining
MAX_CELLS = 150_000
#: a level that leaves the worst open cell's excess over the threshold above this fraction of
#: the last level's has stalled (the sharp bounds' own excess is reached); two in a row stop
STALL = 0.8
#: sharp bounds evaluated at most, counted in joint transforms (directions x 2 signs x (variables
#: + 1) chains x joints): about 2 s. A chain whose maxima form a ring of directions (a planar arm's
#: rotation) needs more at 20 joints; the search then stops and the scalar bound stands.
SHARP_WORK = 3_000_000


@dataclass
class ExactBound:
    bound: float  # certified upper bound of the exact error (angle for the rotation)
    lower: float  # the lower bound it was certified against
    cells: int
    levels: int
    seconds: float
    converged: bool


def _error_vectors(delta: np.ndarray, problem: str) -> np.ndarray:
    """E of dP (..., 4, 4): (..., 3). Linear in dP's entries, so it maps dP's derivatives to E's."""
    if problem == "rotation":
        return rotation_sine_cosine(delta[..., :3, :3])[0]  # its skew part: sin(theta) times the axis
    return delta[..., :3, 3]


def error_vectors_and_gradients(
    error_map: ErrorMap, screws: np.ndarray, problem: str, joints: np.ndarray, slots: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """E at P sets of screws (P, n, 6) and its derivatives along the variables (joints[k],
    slots[k]): (P, 3) and (P, m, 3), from dP's (:func:`bcad.worstcase.exact.error_tangents`)."""
    delta, tangents = error_tangents(error_map, screws, joints, slots)
    return _error_vectors(delta, problem), _error_vectors(tangents, problem)


class _Geometry:
    """The per-joint constants of the second-derivative bound (module docstring)."""

    def __init__(self, error_map: ErrorMap, problem: str):
        self.problem = problem
        self.absolute = error_map.absolute
        # the screws' bounds (for absolute angles, wider than the variables'), a hair outward: x^
        # may sit an ulp outside C
        clearance = error_map.screw_clearance * (1.0 + 1e-12)
        self.a = np.hypot(clearance[:, 0], clearance[:, 1])  # the largest |dr_j|
        b = np.hypot(clearance[:, 2], clearance[:, 3])  # the largest |dt_j|
        self.p = arm_lengths(error_map) * (1.0 + 1e-12)  # |p_j|, certified
        self.A = float(np.sum(self.a))
        # |e_z x p_j|, p_j the translation of G_j = S_j ... S_n in F_j (floating point, with a
        # margin far above its rounding)
        G = np.eye(4)
        lever = np.zeros(error_map.joints)
        for j in range(error_map.joints - 1, -1, -1):
            G = error_map.S[j] @ G
            lever[j] = np.hypot(G[0, 3], G[1, 3])
        scale = 1.0 + float(np.sum(np.abs(error_map.S[:, :3, 3])))
        self.lever = np.minimum(lever * (1.0 + 1e-12) + 1e-12 * scale, self.p)
        self.v_max = (
            b + self.p * np.abs(clearance[:, 0]) + self.lever * np.abs(clearance[:, 1])
        )  # the largest |v_j| over C
        # Free intervals: an axial turn whose axis passes through the tool (its rows of M vanish:
        # no first-order effect in any direction). The localisation cannot shrink them, and their
        # turn multiplies every later joint's step in K; splitting them into pieces does.
        self.free: list[tuple[int, int]] = []
        if problem == "translation":
            scale = float(np.max(np.abs(error_map.M_float)))
            for block, (rows, column, kind) in enumerate(BLOCKS[problem]):
                if kind != "interval":
                    continue
                for j in range(error_map.joints - 1):  # the last joint's turn moves no later joint
                    if (
                        error_map.clearance[j, column] > 0
                        and np.max(np.abs(error_map.M_float[j, list(rows), :])) <= 1e-12 * scale
                    ):
                        self.free.append((block, j))
            self.free = sorted(self.free, key=lambda f: -error_map.clearance[f[1], BLOCKS[problem][f[0]][1]])[:MAX_FREE]

    def half_curvature(self, steps: list[np.ndarray]) -> np.ndarray:
        """K(s) / 2 for the blocks' step sizes (each (P, n): dr's disc and interval, then dt's) in
        the clearance variables."""
        if self.absolute:  # a step of the links' turns: |d dr_z,j| <= s_j + s_{j-1}
            turn = np.array(steps[1], dtype=float, copy=True)
            turn[..., 1:] += steps[1][..., :-1]
            steps = [steps[0], turn, *steps[2:]]
        r = np.hypot(steps[0], steps[1])  # |d dr_j|: the disc and the interval are orthogonal slots
        if self.problem == "rotation":
            return 0.5 * np.sum(r, axis=1) ** 2
        # |d v_j| <= |d dt_j| + |p_j| |d dr_xy| + |e_z x p_j| |d dr_z|: an axial turn about an
        # axis through the tool moves nothing
        velocity = np.hypot(steps[2], steps[3]) + self.p * steps[0] + self.lever * steps[1]
        before = np.cumsum(r, axis=1) - r  # sum_{i<j} s_r,i: how far R_{<j} turns
        v = self.v_max
        total = np.sum(before**2 * v + before * (r * v + 2.0 * velocity) + r**2 * v / 3.0 + r * velocity, axis=1)
        return 0.5 * total * (1.0 + 1e-12)


def coarse_bounds(error_map: ErrorMap, directions: np.ndarray, problem: str, geometry: _Geometry) -> np.ndarray:
    """F(u) <= h(g) + K(C) / 2 (Taylor about x = 0, where E = 0 and its gradient is g): cheap,
    and within the order of the clearances squared of F."""
    n = error_map.joints
    whole = [
        np.broadcast_to(error_map.clearance[:, column] * (1.0 + 1e-12), (len(directions), n)) for column in range(4)
    ]
    return support_upper(error_map, directions, problem) + geometry.half_curvature(whole)


def direction_bounds(error_map: ErrorMap, directions: np.ndarray, problem: str, geometry: _Geometry) -> np.ndarray:
    """Upper bounds of F(u) = max_{x in C} u . E(x) for unit directions (P, 3) (module docstring):
    over the sub-boxes of the free intervals (:attr:`_Geometry.free`), the largest."""
    if not geometry.free:
        return sub_box_bounds(error_map, directions, problem, geometry, ())
    pieces = []
    for block, joint in geometry.free:
        half = error_map.clearance[joint, BLOCKS[problem][block][1]] / FREE_PIECES
        centres = -FREE_PIECES * half + half * (2 * np.arange(FREE_PIECES) + 1)
        pieces.append([(block, joint, centre, half) for centre in centres])
    return np.max(
        [
            sub_box_bounds(error_map, directions, problem, geometry, combination)
            for combination in itertools.product(*pieces)
        ],
        axis=0,
    )


def sub_box_bounds(
    error_map: ErrorMap, directions: np.ndarray, problem: str, geometry: _Geometry, pieces: tuple
) -> np.ndarray:
    """:func:`direction_bounds` over the clearance set with each free interval (block, joint)
    of ``pieces`` held to [centre - half, centre + half]."""
    P, n = len(directions), error_map.joints
    w = np.einsum("nrc,pc->pnr", error_map.M_float, directions)  # (P, n, 6): the first-order coefficients
    blocks = []  # (slots, radius (n,), coefficient (P, n, k), kind)
    for (rows, column, kind), slots in zip(BLOCKS[problem], SCREW_SLOTS[problem]):
        blocks.append((list(slots), error_map.clearance[:, column], w[:, :, list(rows)], kind))
    # x^: the first-order maximiser per direction, and h(g) = g . x^
    x_hat = np.zeros((P, n, 6))
    for slots, radius, coefficient, kind in blocks:
        if kind == "disc":
            norm = np.linalg.norm(coefficient, axis=2, keepdims=True)
            unit = np.where(norm > 0, coefficient / np.where(norm > 0, norm, 1.0), np.array([1.0, 0.0]))
            x_hat[:, :, slots] = unit * radius[None, :, None]
        else:
            x_hat[:, :, slots[0]] = np.where(coefficient[:, :, 0] >= 0, radius, -radius)[None, :] * np.ones((P, 1))
    for block, joint, centre, _half in pieces:
        # a free interval: its first-order coefficient is 0 for every u, so any point of it
        # maximises the first-order part; the sub-box's centre is x^'s
        x_hat[:, joint, blocks[block][0][0]] = centre
    first_order = support_upper(error_map, directions, problem)  # certified h(g)
    coarse = coarse_bounds(error_map, directions, problem, geometry)
    # u . E(x^) and G: one sweep of the chain each way (error_tangents)
    space = ScaledVariables(error_map, problem)
    joints, slots = space.joints, space.slots
    E, tangents = error_vectors_and_gradients(error_map, x_hat, problem, joints, slots)
    at_hat = np.einsum("pc,pc->p", E, directions)
    G = np.zeros((P, n, 6))
    G[:, joints, slots] = np.einsum("pmc,pc->pm", tangents, directions)
    margin = ROUNDING_MARGIN * np.maximum(first_order, 0.0)

    # Per block: |g_b|, |G_b - g_b|, the exact maximum gain of G_b . d_b over the block, its cap
    slopes, excess, exact_gain, caps, kinds, radii = [], [], [], [], [], []
    for slots, radius, coefficient, kind in blocks:
        G_b = G[:, :, slots]
        if kind == "disc":
            slopes.append(np.linalg.norm(coefficient, axis=2))
            exact_gain.append(radius * np.linalg.norm(G_b, axis=2) - np.sum(G_b * x_hat[:, :, slots], axis=2))
        else:
            slopes.append(np.abs(coefficient[:, :, 0]))
            exact_gain.append(radius * np.abs(G_b[:, :, 0]) - G_b[:, :, 0] * x_hat[:, :, slots[0]])
        excess.append(np.linalg.norm(G_b - coefficient, axis=2))
        caps.append(np.broadcast_to(2.0 * radius, (P, n)).copy())
        kinds.append(kind)
        radii.append(radius)
    for block, joint, _centre, half in pieces:
        G_b = G[:, joint, blocks[block][0][0]]
        caps[block][:, joint] = half
        exact_gain[block][:, joint] = np.abs(G_b) * half  # the sub-box's own maximum of G_b d_b

    def steps_for(drop: np.ndarray) -> list[np.ndarray]:
        """The largest |d_b| of each block whose drop is at most ``drop`` (P,)."""
        drop = np.maximum(drop, 0.0)[:, None]
        found = []
        for slope, cap, kind, radius in zip(slopes, caps, kinds, radii):
            with np.errstate(divide="ignore", invalid="ignore"):
                if kind == "disc":
                    s = np.sqrt(2.0 * radius * drop / slope)
                else:
                    s = drop / slope
            found.append(np.minimum(np.where(np.isfinite(s), s, np.inf), cap) * (1.0 + 1e-12))
        return found

    # Localisation about each direction's own level tau = u . E(x^): F(u) <= max(tau, the bound
    # over the points where u . E >= tau), for any tau; this one keeps the bound tight where
    # F(u) is far below the maximum too, so that only the cells near it need splitting.
    level = at_hat - margin
    steps = steps_for(coarse - level)
    for _ in range(LOCALISATION_ROUNDS):
        remainder = geometry.half_curvature(steps)
        drop = at_hat - level + sum(np.sum(e * s, axis=1) for e, s in zip(excess, steps)) + remainder + margin
        steps = [np.minimum(old, new) for old, new in zip(steps, steps_for(drop))]
    remainder = geometry.half_curvature(steps)
    gain = sum(
        np.sum(np.maximum(np.minimum(exact, e * s), 0.0), axis=1) for exact, e, s in zip(exact_gain, excess, steps)
    )
    refined = np.maximum(at_hat + gain + remainder + margin, level)
    return np.minimum(coarse, refined)


def exact_bound(
    error_map: ErrorMap, problem: str, found: float, argmax: np.ndarray, tol: float = 1e-6, scalar_bound: float = np.inf
) -> ExactBound | None:
    """A certified upper bound of the exact error (rotation angle or translation norm) within
    ``tol`` relative of ``found``, the exact error at the feasible screws ``argmax`` (n, 6) that
    the search reached, where the branch and bound gets there; None where the module's argument
    does not apply (a rotation clearance sum of 1 rad or more) or cannot beat ``scalar_bound``
    (:func:`bcad.worstcase.exact.exact_upper_bounds`: large clearances, where the localisation
    no longer shrinks to the clearances squared).

    The sharp bound in the direction of the error at ``argmax`` is the least any cell near it
    can reach; the branch and bound aims at the larger of ``found / (1 - tol)`` and that bound
    plus a tenth of its excess, so that it settles instead of splitting cells it cannot
    settle."""
    start = time.perf_counter()
    geometry = _Geometry(error_map, problem)
    if geometry.A >= 1.0:
        return None  # sin's monotone range and the exponential factors: leave it to the scalar bound
    if problem == "rotation":
        lower = float(np.sin(found)) * (1.0 - 4e-16)  # E's norm is sin(theta)
    else:
        lower = float(found) * (1.0 - 4e-16)
    if lower <= 0.0:
        return None
    error = _error_vectors(error_transforms(error_map, np.asarray(argmax, dtype=float)[None]), problem)[0]
    if not np.linalg.norm(error) > 0:
        return None
    best_direction = error / np.linalg.norm(error)
    reachable = float(direction_bounds(error_map, best_direction[None], problem, geometry)[0])
    scalar = math.sin(min(scalar_bound, math.pi / 2)) if problem == "rotation" else scalar_bound
    if reachable >= scalar:
        return None
    mesh = _Triangulation(np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0, 0, 1]], dtype=float))
    triangles = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])

    def both_signs(function, directions: np.ndarray) -> np.ndarray:
        # F(-u) = max u . (-E): both signs of a direction are needed (E is not odd in x)
        parts = []
        for first in range(0, len(directions), DIRECTION_BLOCK):
            block = directions[first : first + DIRECTION_BLOCK]
            both = function(error_map, np.vstack([block, -block]), problem, geometry)
            parts.append(np.maximum(both[: len(block)], both[len(block) :]))
        return np.concatenate(parts) if parts else np.zeros(0)

    # Over the hemisphere, with each vertex's bound the larger of F(u) and F(-u): a cell's cone
    # and its mirror image are then both covered. A vertex gets the sharp bound only when a
    # cell of it is not settled by the cheap ones.
    upper = both_signs(coarse_bounds, mesh.vertices)
    sharp = np.zeros(len(upper), dtype=bool)
    settled, cells, converged, level = 0.0, 0, True, 0
    stalls, last_excess = 0, np.inf
    work, cost = 0, 2 * (len(ScaledVariables(error_map, problem)) + 1) * error_map.joints
    threshold = max(lower / (1.0 - tol), reachable + 0.1 * max(reachable - lower, 0.0))

    def cell_bounds(triangles: np.ndarray) -> np.ndarray:
        V = mesh.vertices
        distance = _plane_distance_lower(V[triangles[:, 0]], V[triangles[:, 1]], V[triangles[:, 2]])
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = (
                np.max(upper[triangles], axis=1) / np.where(distance > 0, distance, np.nan) * (1.0 + COVERING_MARGIN)
            )
        return np.where(distance > 0, bound, np.inf)

    for level in range(MAX_LEVELS):
        bound = cell_bounds(triangles)
        # the vertices of the unsettled cells, sorted and once each (np.unique would import numpy.ma: 30 ms)
        vague = np.flatnonzero(np.bincount(triangles[bound > threshold].ravel(), minlength=1))
        vague = vague[~sharp[vague]]
        work += len(vague) * cost
        if work > SHARP_WORK:
            converged = False
            settled = max(settled, float(bound.max()))
            break
        if len(vague):
            upper[vague] = np.minimum(upper[vague], both_signs(direction_bounds, mesh.vertices[vague]))
            sharp[vague] = True
            bound = cell_bounds(triangles)
        cells += len(triangles)
        done = bound <= threshold
        if np.any(done):
            settled = max(settled, float(bound[done].max()))
        open_cells = triangles[~done]
        if len(open_cells) == 0:
            break
        excess = float(bound[~done].max()) - threshold
        stalls = stalls + 1 if excess > STALL * last_excess else 0
        last_excess = excess
        if level == MAX_LEVELS - 1 or cells + 4 * len(open_cells) > MAX_CELLS or stalls >= 2:
            settled = max(settled, float(bound[~done].max()))
            converged = False
            break
        triangles, added = mesh.split(open_cells)
        if len(added):
            upper = np.concatenate([upper, both_signs(coarse_bounds, mesh.vertices[added])])
            sharp = np.concatenate([sharp, np.zeros(len(added), dtype=bool)])
    settled = max(settled, lower) * (1.0 + 4e-16)
    if problem == "rotation":
        if settled >= 1.0:
            return None
        value = math.asin(settled) * (1.0 + 4e-16)
    else:
        value = settled
    value = float(np.nextafter(value, np.inf))
    if value >= scalar_bound:
        return None
    converged = converged and (value - found) <= tol * value
    return ExactBound(value, found, cells, level + 1, time.perf_counter() - start, converged)
