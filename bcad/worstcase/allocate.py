"""Tolerance synthesis: the largest scale of the clearances that keeps the exact error
within a spec, bracketed: certified safe below, shown unsafe above.

The clearances scaled by lambda (each joint's also by its weight w_j) form the set lambda C_w,
and the exact error's maximum over it never decreases with lambda (the sets are nested: C_w holds
0 and is convex). So the answer is an interval [lambda_low, lambda_high]:

* lambda_low is **proven safe**: the certified bound of the exact model
  (:func:`bcad.worstcase.exact.exact_upper_bounds`) at lambda_low is within the spec for every
  error the spec names. The first-order certified bound scales exactly with lambda (the
  first-order error is linear in the clearances; the scaled bound is rounded up), so the bound at
  any lambda costs one evaluation of the remainder series, and bisection finds the largest such
  lambda to 1e-12 relative.
* lambda_high is **shown unsafe**: at lambda_high the exact search (:func:`exact_maximum`,
  from +-x* of the first-order problem) finds a feasible clearance whose exact error exceeds the
  spec by more than MARGIN (1e-9 relative, far above the rounding of its evaluation in doubles);
  the found error being nearly linear in lambda, a fixed-point iteration finds where it meets the
  spec, and lambda_high is a hair above.

* lambda_low is then **sharpened**: between the two, bisection on the sharp bound
  (:func:`bcad.worstcase.exact_bound.exact_bound`, tight to the clearances to the fourth power):
  a midpoint is safe where the branch and bound proves the exact error within the spec, unsafe
  where the search finds one above it, and the bisection stops where neither can be shown (the
  spec within the sharp bound's own excess of the maximum) or at SHARP_WIDTH.

Without the sharp bound the interval's width would be the scalar bound's gap (of the order of
the summed rotation clearances, relative, 1e-3 on the examples); with it, about 1e-6.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from bcad.worstcase.branch_and_bound import certified_maximum
from bcad.worstcase.error_map import ErrorMap
from bcad.worstcase.exact import exact_maximum, exact_upper_bounds
from bcad.worstcase.exact_bound import exact_bound

KINDS = ("rotation", "translation")
#: bisection steps (each halves the bracket: 60 reach double precision from any start)
STEPS = 60
#: relative width at which the bisections stop
WIDTH = 1e-12
#: a witness must exceed the spec by this much, relative, to count: far above the rounding of
#: its double-precision evaluation (a product of n 4 x 4 matrices: about n 1e-16 of each entry)
MARGIN = 1e-9
#: the fixed point of the unsafe side stops moving (its search's own resolution is about 1e-12)
FIXED_POINT_WIDTH = 1e-10
#: relative width at which the sharp bisection stops (each step runs a search and a branch and bound)
SHARP_WIDTH = 2e-7
#: boxes of a wall's decision at most (bcad.worstcase.directional; about 0.3 s): the planar arms of
#: arXiv 2104.08896 need 10, many discs at large clearances would not settle in 100 times more
DECISION_BOXES = 3000


@dataclass
class Allocation:
    lambda_low: float  # proven safe
    lambda_high: float  # proven unsafe (inf where no feasible clearance exceeds the spec)
    witness: np.ndarray | None  # the feasible screws (n, 6) at lambda_high whose exact error exceeds the spec
    witness_errors: dict[str, float]
    bound_at_low: dict[str, float]

    @property
    def relative_width(self) -> float:
        if not np.isfinite(self.lambda_high) or self.lambda_high <= 0:
            return float("inf")
        return (self.lambda_high - self.lambda_low) / self.lambda_high


def scaled_map(error_map: ErrorMap, scale: float, weights: np.ndarray) -> ErrorMap:
    """The chain with every clearance of joint j multiplied by ``scale`` x ``weights[j]``."""
    return replace(error_map, clearance=error_map.clearance * (scale * weights)[:, None])


def allocate(error_map: ErrorMap, spec: dict[str, float], weights: np.ndarray | None = None) -> Allocation:
    """The certified bracket [lambda_low, lambda_high] of the largest clearance scale whose exact
    errors stay within ``spec`` ({"rotation": rad, "translation": length, "dx": length, ...}: the
    norms, and displacements along the base frame's axes, :data:`bcad.worstcase.directional.AXES`).

    Each limit's safe scales form an interval [0, lambda*_k] (its error never decreases with the
    scale), so the spec's is [0, min_k lambda*_k], bracketed by the smallest lambda_low and the
    smallest lambda_high."""
    weights = np.ones(error_map.joints) if weights is None else np.asarray(weights, dtype=float)
    norms = {kind: value for kind, value in spec.items() if kind in KINDS}
    found = [allocate_directional(error_map, key, value, weights) for key, value in spec.items() if key not in KINDS]
    if norms:
        found.append(_allocate_norms(error_map, norms, weights))
    low = min(found, key=lambda allocation: allocation.lambda_low)
    high = min(found, key=lambda allocation: allocation.lambda_high)
    bound_at_low: dict[str, float] = {}
    for allocation in found:
        if allocation.lambda_low <= low.lambda_low:
            bound_at_low.update(allocation.bound_at_low)
        else:  # a limit that does not bind: its bound at the spec's lambda_low, not at its own
            bound_at_low.update(bounds_at(error_map, list(allocation.bound_at_low), low.lambda_low, weights))
    return Allocation(low.lambda_low, high.lambda_high, high.witness, high.witness_errors, bound_at_low)


def bounds_at(error_map: ErrorMap, keys: list[str], scale: float, weights: np.ndarray) -> dict[str, float]:
    """The certified exact bound of each limit (a norm's, or a displacement's along a base axis) at
    the clearances scaled by ``scale`` x ``weights``."""
    from bcad.worstcase.directional import directional_maximum, tool_direction

    found = norm_bounds(error_map, [key for key in keys if key in KINDS], scale, weights)
    scaled = scaled_map(error_map, scale, weights)
    for key in (key for key in keys if key not in KINDS):
        found[key] = directional_maximum(scaled, tool_direction(error_map, key), 1e-6, None, DECISION_BOXES).bound
    return found


def norm_bounds(
    error_map: ErrorMap, kinds: list[str], scale: float, weights: np.ndarray, first=None
) -> dict[str, float]:
    """The exact bounds of the rotation and translation norms (``kinds``) at the clearances scaled
    by ``scale`` x ``weights``; ``first``: their first-order maxima at scale 1, where known."""
    if not kinds:
        return {}
    if first is None:
        unit = scaled_map(error_map, 1.0, weights)
        first = {kind: certified_maximum(unit, kind, 1e-9) for kind in kinds}
    scaled = scaled_map(error_map, scale, weights)
    # The first-order bound is linear in the clearances: the unit bound times the scale, rounded up.
    linear = {kind: float(np.nextafter(found.upper_bound * scale, np.inf)) for kind, found in first.items()}
    exact = exact_upper_bounds(scaled, linear.get("rotation", 0.0), linear.get("translation", 0.0))
    return {kind: exact[KINDS.index(kind)] for kind in kinds}


def allocate_directional(error_map: ErrorMap, key: str, limit: float, weights: np.ndarray) -> Allocation:
    """The bracket for one displacement limit along a base axis (``key``: dx, -dy, ...): where
    the directional branch and bound (:mod:`bcad.worstcase.directional`) proves the displacement
    within ``limit`` (lambda_low) and where it finds a feasible clearance beyond it (lambda_high).

    The largest displacement is nearly linear in the scale: a fixed point on the exact search's
    maximum (:func:`bcad.worstcase.directional.largest_found`) lands on lambda*, then decisions
    a hair either side, widened tenfold until each is proven, give a bracket about 1e-8 wide;
    where nothing is proven near it, bisection finds the largest scale proven safe below it."""
    from bcad.worstcase.directional import directional_maximum, largest_found, tool_direction

    u = tool_direction(error_map, key)

    def maximum(scale: float, limit_: float):
        """The decision at ``scale``: its branch and bound capped at DECISION_BOXES (about 0.3 s)."""
        return directional_maximum(scaled_map(error_map, scale, weights), u, 1e-9, limit_, DECISION_BOXES)

    scale = 1.0
    for _ in range(40):  # ends: at most 40 searches
        found_max = largest_found(scaled_map(error_map, scale, weights), u)
        if found_max <= 0.0:
            if scale >= 1e12:
                break
            scale = min(10.0 * scale, 1e12)  # no displacement that way yet (a first-order zero): larger clearances
            continue
        updated = scale * limit / found_max
        if abs(updated - scale) <= FIXED_POINT_WIDTH * scale:
            scale = updated
            break
        scale = min(updated, 1e12)
    low, at_low = 0.0, {key: 0.0}
    for offset in (1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 0.5):
        decided = maximum(scale * (1.0 - offset), limit)
        if decided.verdict == "safe":
            low, at_low = scale * (1.0 - offset), {key: decided.bound}
            break
    else:
        # Nothing proven near the fixed point (a limit the tool never reaches, or one below what
        # the bound resolves): the largest scale proven safe below it, by bisection.
        top = scale
        for _ in range(STEPS):  # ends: at most STEPS decisions
            if top - low <= 1e-6 * top:
                break
            middle = 0.5 * (low + top)
            decided = maximum(middle, limit)
            if decided.verdict == "safe":
                low, at_low = middle, {key: decided.bound}
            else:
                top = middle
    if low > 0.0:
        # A decision's bound is floored at the limit it decides (only points beyond it matter to
        # it), so a safe verdict reads as the limit itself: the bound at lambda_low, to 1e-6.
        bounded = directional_maximum(scaled_map(error_map, low, weights), u, 1e-6, None, DECISION_BOXES)
        at_low = {key: min(at_low[key], bounded.bound)}
    for offset in (1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0):
        decided = maximum(max(scale, low) * (1.0 + offset), limit)
        if decided.verdict == "unsafe":
            return Allocation(low, max(scale, low) * (1.0 + offset), decided.argmax, {key: decided.max}, at_low)
    return Allocation(low, float("inf"), None, {}, at_low)


def _allocate_norms(error_map: ErrorMap, spec: dict[str, float], weights: np.ndarray) -> Allocation:
    """:func:`allocate` for limits of the rotation and translation norms."""
    unit = scaled_map(error_map, 1.0, weights)
    first = {kind: certified_maximum(unit, kind, 1e-9) for kind in KINDS if kind in spec}

    def bounds(scale: float) -> dict[str, float]:
        return norm_bounds(error_map, list(first), scale, weights, first)

    def safe(scale: float) -> bool:
        return all(value <= spec[kind] for kind, value in bounds(scale).items())

    def sharpened(allocation: Allocation) -> Allocation:
        """lambda_low raised (and lambda_high lowered) by bisection on the sharp bound."""
        low, high = allocation.lambda_low, allocation.lambda_high
        at_low, witness = allocation.bound_at_low, (allocation.witness, allocation.witness_errors)
        # The search's witness is nearly where the exact maximum meets the spec: try just below
        # lambda_high first, stepping down fourfold (a few branch and bounds), then bisect.
        step = SHARP_WIDTH
        for _ in range(STEPS):  # ends: at most STEPS branch and bounds
            candidate = high * (1.0 - step)
            if candidate <= low:
                break
            verdict, found_bounds, found_witness = _sharp_verdict(error_map, first, spec, candidate, weights)
            if verdict == "safe":
                low, at_low = candidate, found_bounds
                break
            if verdict == "unsafe":
                high, witness = candidate, found_witness
            else:
                step *= 4.0
        for _ in range(STEPS):
            if high - low <= SHARP_WIDTH * high:
                break
            middle = 0.5 * (low + high)
            verdict, found_bounds, found_witness = _sharp_verdict(error_map, first, spec, middle, weights)
            if verdict == "safe":
                low, at_low = middle, found_bounds
            elif verdict == "unsafe":
                high, witness = middle, found_witness
            else:
                break
        return Allocation(low, high, witness[0], witness[1], at_low)

    def worst(scale: float) -> tuple[float, np.ndarray, dict[str, float]]:
        """The largest ratio of a found exact error to its spec at ``scale``, its screws and errors."""
        scaled = scaled_map(error_map, scale, weights)
        best = (0.0, None, {})
        for kind, found in first.items():
            search = exact_maximum(scaled, found.argmax * scale, kind)
            if search.max / spec[kind] > best[0]:
                best = (search.max / spec[kind], search.argmax, {kind: search.max})
        return best

    # Bracket the safe side: 0 is safe (no clearance, no error); grow until unsafe.
    low, high = 0.0, 1.0
    while safe(high) and high < 1e12:  # ends: the bound grows at least linearly with the scale
        low, high = high, 2.0 * high
    for _ in range(STEPS):
        if high - low <= WIDTH * high:
            break
        middle = 0.5 * (low + high)
        low, high = (middle, high) if safe(middle) else (low, middle)
    lambda_low = low

    # The unsafe side: the found error is nearly linear in the scale, so iterating
    # scale <- scale / (found / spec) reaches where it meets the spec in a few steps; then the
    # smallest scale a little above it where a feasible clearance is shown to exceed the spec.
    scale = high
    for _ in range(30):  # ends: at most 30 searches
        ratio, _, _ = worst(scale)
        if ratio <= 0.0:
            return Allocation(lambda_low, float("inf"), None, {}, bounds(lambda_low))
        updated = scale / ratio
        if abs(updated - scale) <= FIXED_POINT_WIDTH * scale:
            break
        scale = updated
    for margin in (2e-9, 1e-8, 1e-7, 1e-6, 1e-4, 1e-2, 1e-1, 1.0):
        top = max(scale, lambda_low) * (1.0 + margin)
        ratio, screws, errors = worst(top)
        if ratio > 1.0 + MARGIN:
            return sharpened(Allocation(lambda_low, top, screws, errors, bounds(lambda_low)))
    return Allocation(lambda_low, float("inf"), None, {}, bounds(lambda_low))


def _sharp_verdict(
    error_map: ErrorMap, first: dict, spec: dict[str, float], scale: float, weights: np.ndarray
) -> tuple[str, dict[str, float], tuple[np.ndarray | None, dict[str, float]]]:
    """'safe' (every error's sharp bound within its spec), 'unsafe' (a feasible clearance
    exceeds a spec by more than MARGIN) or 'open', with the bounds and the witness."""
    scaled = scaled_map(error_map, scale, weights)
    bounds: dict[str, float] = {}
    verdict = "safe"
    for kind, found in first.items():
        linear = float(np.nextafter(found.upper_bound * scale, np.inf))
        scalar = exact_upper_bounds(
            scaled, linear if kind == "rotation" else 0.0, linear if kind == "translation" else 0.0
        )[KINDS.index(kind)]
        search = exact_maximum(scaled, found.argmax * scale, kind)
        if search.max > spec[kind] * (1.0 + MARGIN):
            return "unsafe", {}, (search.argmax, {kind: search.max})
        if scalar <= spec[kind]:
            bounds[kind] = scalar
            continue
        # the branch and bound aims at the spec: a relative gap of 1 - found / spec proves it
        tol = max(1.0 - search.max / spec[kind], 1e-12)
        sharp = exact_bound(scaled, kind, search.max, search.argmax, tol, scalar)
        if sharp is None or sharp.bound > spec[kind]:
            verdict = "open"
        bounds[kind] = scalar if sharp is None else sharp.bound
    return verdict, bounds, (None, {})
