"""The largest displacement of the tool point along a fixed direction of the base frame, exactly
and certified (the wall of the planar arm of arXiv 2104.08896).

A wall, a fixture or a work envelope limits how far the tool may move one way, not the norm of
its error: ``dx <= 0.09`` says the tool point moves at most 0.09 towards the base's +x. With
p' - p = R_P t, t the translation of dP = P^-1 P' (Eq. 10-11, in F_{n+1}), the displacement along
a unit e of the base frame is u . t with u = R_P^T e, and the question is

    F = max over the clearance set C of u . t(x),

a smooth function of the clearance variables x (:mod:`bcad.worstcase.error_map`) over a product of
discs and intervals.

* **lower bound**: the exact search climbs on u . t from the first-order maximiser
  (:func:`bcad.worstcase.exact.exact_maximum`); its point is feasible, so its value is a true
  lower bound, raised later by any better box corner or centre pulled onto C.
* **upper bound, small clearances**: the sharp bound of the norms' branch and bound at this one
  direction (:func:`bcad.worstcase.exact_bound.direction_bounds`), tight to the clearances to
  the fourth power whatever the number of joints. Where it settles the question, done.
* **upper bound, otherwise**: branch and bound on boxes of the variables scaled to [-1, 1] (a
  disc's box holds it). A box is bounded by Taylor's theorem about its corner x^ along the
  gradient at its centre, u . t(x) <= u . t(x^) + G . (x - x^) + K(s) / 2, G the exact
  gradient at x^ (:func:`bcad.worstcase.exact.error_tangents`) and K the rigorous
  second-derivative bound of :class:`bcad.worstcase.exact_bound._Geometry` (its constants over
  the discs' boxes, sqrt(2) wider than the discs), localised as the sharp bound is: only points
  where u . t reaches the level in question matter, and along each variable whose term of G
  lowers the value moving in from x^ they lie within allowance / slope of it. Values and
  gradients are evaluated in doubles, with a margin far above their rounding (1e-11 relative,
  and 16 n ulps of the chain's length). Boxes wholly outside a disc are dropped; the box with
  the largest bound is split across its widest side (in the problem's units), in batches.

A box's excess shrinks with its square, so the gap closes where it matters: near the
maximiser. With a ``limit``, the search decides instead whether F <= limit
(every box's bound within it: 'safe') or not (a feasible clearance beyond it by more than
MARGIN: 'unsafe'), which is what tolerance synthesis needs (:mod:`bcad.worstcase.allocate`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from bcad.worstcase.error_map import ErrorMap
from bcad.worstcase.exact import ScaledVariables, displacements, error_tangents, exact_maximum

#: the directions of the base frame a spec can name, as (axis, sign)
AXES = {"dx": (0, 1.0), "dy": (1, 1.0), "dz": (2, 1.0), "-dx": (0, -1.0), "-dy": (1, -1.0), "-dz": (2, -1.0)}
#: boxes split at once
BATCH = 256
#: boxes evaluated at most (about 3 s; the search then stops with the gap it reached, still
#: certified: many discs at large clearances, or a direction the clearances hardly move the tool in)
MAX_BOXES = 30_000
#: relative margin of each box's bound for the doubles' rounding (module docstring)
ROUNDING_MARGIN = 1e-11
#: a witness must exceed the limit by this much, relative, to show it unsafe
MARGIN = 1e-9
#: rounds of localisation per box
LOCALISATION_ROUNDS = 6


@dataclass
class DirectionalMaximum:
    max: float  # the largest displacement found at a feasible clearance (a true lower bound of F)
    bound: float  # certified upper bound of F
    argmax: np.ndarray  # (n, 6) the clearance variables of ``max``
    boxes: int
    converged: bool  # the gap reached tol (or, with a limit, the verdict is 'safe' or 'unsafe')
    verdict: str | None = None  # with a limit: 'safe', 'unsafe' or 'open'

    @property
    def gap(self) -> float:
        """(bound - max) / |bound|: the relative gap (where the maximum is not 0)."""
        return (self.bound - self.max) / abs(self.bound) if self.bound != 0 else 0.0


def tool_direction(error_map: ErrorMap, key: str) -> np.ndarray:
    """u = R_P^T e: the base frame's direction ``key`` (:data:`AXES`) in F_{n+1}, where dP's
    translation lives."""
    axis, sign = AXES[key]
    return sign * error_map.nominal[axis, :3]


def first_order_start(error_map: ErrorMap, space: ScaledVariables, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The gradient of u . t at no clearance (scaled variables) and the first-order maximiser
    over the set (each interval's end and each disc's point along it), as variables (n, 6)."""
    _, tangents = error_tangents(error_map, np.zeros((1, error_map.joints, 6)), space.joints, space.slots)
    gradient = (tangents[0, :, :3, 3] @ u) * space.scales
    return gradient, space.screws(space.support(gradient))[0]


def largest_found(error_map: ErrorMap, u: np.ndarray) -> float:
    """The largest displacement along u the exact search finds from the first-order maximiser
    (a feasible clearance's: a lower bound of F, no certificate)."""
    space = ScaledVariables(error_map, "translation")
    if not len(space):
        return 0.0
    return float(exact_maximum(error_map, first_order_start(error_map, space, u)[1], "translation", direction=u).max)


def directional_maximum(
    error_map: ErrorMap, u: np.ndarray, tol: float = 1e-6, limit: float | None = None, max_boxes: int = MAX_BOXES
) -> DirectionalMaximum:
    """max over the clearance set of u . t(x) (module docstring), within a relative gap ``tol``;
    with ``limit``, until it is decided whether the maximum is within it; at most ``max_boxes``
    boxes."""
    from bcad.worstcase.exact_bound import _Geometry, direction_bounds

    n = error_map.joints
    space = ScaledVariables(error_map, "translation")
    if not len(space):
        zero = np.zeros((n, 6))
        return DirectionalMaximum(
            0.0, 0.0, zero, 0, True, None if limit is None else ("safe" if limit >= 0 else "unsafe")
        )
    joints, slots, scales, pairs, m = space.joints, space.slots, space.scales, space.pairs, len(space)
    screws_of, feasible = space.screws, space.feasible
    # K's constants over the boxes: the discs' columns sqrt(2) wider (a box holds its disc)
    widened = error_map.clearance.copy()
    widened[:, [0, 2]] *= np.sqrt(2.0) * (1.0 + 1e-12)
    geometry = _Geometry(replace(error_map, clearance=widened), "translation")
    length = 1.0 + float(np.sum(np.linalg.norm(error_map.S[:, :3, 3], axis=1)))
    rounding = 16.0 * n * np.finfo(float).eps * length

    def steps_of(distance: np.ndarray) -> list[np.ndarray]:
        """Each joint's largest step per block (dr disc, dr_z, dt disc, dt_z) for steps of at most
        ``distance`` along each scaled variable."""
        real = distance * scales
        steps = [np.zeros((len(distance), n)) for _ in range(4)]
        for block, block_slots in enumerate(((0, 1), (2,), (3, 4), (5,))):
            chosen = np.isin(slots, block_slots)
            if np.any(chosen):
                squares = np.zeros((len(distance), n))
                np.add.at(squares.T, joints[chosen], (real[:, chosen] ** 2).T)
                steps[block] = np.sqrt(squares)
        return steps

    def bounds(lo: np.ndarray, hi: np.ndarray, level: float) -> tuple[np.ndarray, np.ndarray]:
        """Upper bounds of the boxes over their points where u . t >= ``level`` (module docstring),
        and their first-order corners x^ (candidates for the lower bound)."""
        centre = 0.5 * (lo + hi)
        _, tangents = error_tangents(error_map, screws_of(centre), joints, slots)
        slope = (tangents[..., :3, 3] @ u) * scales
        corner = np.where(slope >= 0.0, hi, lo)  # x^: the box's maximiser of the linearisation at its centre
        delta, tangents = error_tangents(error_map, screws_of(corner), joints, slots)
        value = delta[:, :3, 3] @ u
        # G . (x - x^) = -s_k d_k with d_k = |x_k - x^_k| in [0, w_k]: s_k > 0 where G agrees
        # with the corner (moving in lowers the value), s_k <= 0 where it does not
        agreeing = np.where(slope >= 0.0, 1.0, -1.0) * (tangents[..., :3, 3] @ u) * scales
        width = hi - lo
        rising = np.sum(np.where(agreeing <= 0.0, -agreeing * width, 0.0), axis=1)
        margin = ROUNDING_MARGIN * (np.abs(value) + rising) + rounding
        distance = width.copy()
        for _ in range(LOCALISATION_ROUNDS):
            # only points with u . t >= level matter: there sum over s_k > 0 of s_k d_k is at most D
            curvature = geometry.half_curvature(steps_of(distance))
            allowance = np.maximum(value + rising + curvature + margin - level, 0.0)
            with np.errstate(divide="ignore", invalid="ignore"):
                reach = np.where(agreeing > 0.0, allowance[:, None] / agreeing, np.inf)
            distance = np.minimum(distance, reach)
        curvature = geometry.half_curvature(steps_of(distance))
        return np.maximum(value + rising + curvature + margin, level), corner

    def outside(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """Boxes with no point in some disc (certainly: the nearest point's norm above 1)."""
        if not len(pairs):
            return np.zeros(len(lo), dtype=bool)
        nearest = np.maximum(np.maximum(lo, -hi), 0.0)[:, pairs]
        return np.hypot(nearest[..., 0], nearest[..., 1]).max(axis=1) > 1.0 + 1e-12

    # the first-order maximiser over C (each interval's end and each disc's point along the
    # gradient at 0), and the exact search's climb from it (bcad.worstcase.exact.exact_maximum)
    gradient, start = first_order_start(error_map, space, u)
    search = exact_maximum(error_map, start, "translation", direction=u)
    best_y = space.scaled(search.argmax)
    best = float(search.max)
    size = float(np.sum(np.abs(gradient)))  # the first-order maximum: the scale of the gap

    def answer(bound: float, boxes: int) -> DirectionalMaximum:
        if limit is not None:
            verdict = "unsafe" if best > limit + MARGIN * abs(limit) else ("safe" if bound <= limit else "open")
            return DirectionalMaximum(best, bound, screws_of(best_y[None])[0], boxes, verdict != "open", verdict)
        return DirectionalMaximum(
            best, bound, screws_of(best_y[None])[0], boxes, bound <= best + tol * max(abs(best), size)
        )

    if geometry.A >= 1.0:
        # K's constants hold for rotation clearances summing to less than 1 rad (as the sharp bound's)
        return answer(float("inf"), 0)
    # The sharp bound of the norm's branch and bound at this one direction (Taylor about the
    # first-order maximiser, localised: bcad.worstcase.exact_bound): tight to the clearances
    # to the fourth power, whatever the number of joints. Where it settles the question, done.
    sharp = float(direction_bounds(error_map, u[None], "translation", _Geometry(error_map, "translation"))[0])
    by_sharp_bound = answer(max(sharp, best), 1)
    if by_sharp_bound.converged:
        return by_sharp_bound

    def level() -> float:
        return limit if limit is not None else best

    # Else (large clearances: the localisation no longer shrinks to their square) branch and
    # bound on boxes of the variables, each bounded about its own first-order corner.
    lo, hi = -np.ones((1, m)), np.ones((1, m))
    upper = np.array([sharp])
    settled = -np.inf  # the largest bound of the boxes set aside
    boxes = 1
    while True:  # ends: every round evaluates at least one box, and MAX_BOXES stops it
        keep = upper > (limit if limit is not None else best + tol * max(abs(best), size))
        if np.any(~keep):
            settled = max(settled, float(upper[~keep].max()))
        lo, hi, upper = lo[keep], hi[keep], upper[keep]
        if len(upper) == 0 or boxes >= max_boxes or (limit is not None and best > limit + MARGIN * abs(limit)):
            break
        order = np.argsort(-upper)[:BATCH]
        rest = np.ones(len(upper), dtype=bool)
        rest[order] = False
        chosen_lo, chosen_hi = lo[order], hi[order]
        widest = np.argmax((chosen_hi - chosen_lo) * scales, axis=1)
        rows = np.arange(len(order))
        middle = 0.5 * (chosen_lo[rows, widest] + chosen_hi[rows, widest])
        left_hi, right_lo = chosen_hi.copy(), chosen_lo.copy()
        left_hi[rows, widest] = middle
        right_lo[rows, widest] = middle
        child_lo = np.vstack([chosen_lo, right_lo])
        child_hi = np.vstack([left_hi, chosen_hi])
        inside = ~outside(child_lo, child_hi)
        child_lo, child_hi = child_lo[inside], child_hi[inside]
        boxes += len(child_lo)
        child_upper = np.zeros(0)
        if len(child_lo):
            child_upper, corners = bounds(child_lo, child_hi, level())
            candidates = feasible(np.vstack([corners, 0.5 * (child_lo + child_hi)]))
            found = displacements(error_map, screws_of(candidates), u)
            if found.max() > best:
                best, best_y = float(found.max()), candidates[int(np.argmax(found))]
        lo = np.vstack([lo[rest], child_lo])
        hi = np.vstack([hi[rest], child_hi])
        upper = np.concatenate([upper[rest], child_upper])
    bound = min(sharp, max([settled, best] + ([float(upper.max())] if len(upper) else [])))
    return answer(bound, boxes)
