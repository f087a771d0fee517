"""Gradient search of X* on the linearised objective log p(X) + log I_lin(X).

I_lin (:mod:`bcad.bayes.linear`) is deterministic and smooth in X, so
Newton's method climbs it: on the unit box of X's bounds, with a
finite-difference gradient and Hessian whose 1 + n + n (n + 1) / 2 points are
evaluated as one batched population, damped (Levenberg-Marquardt) and with
an active set at the bounds. The objective is badly conditioned (the scored
directions are stiff, the redundant ones soft), where L-BFGS-B took hundreds
of iterations and Newton takes tens; where the stiff scores' ridge is curved
(a redundant arm's closure), each trial step is also taken back onto it by a
second-order correction (:func:`second_order_correction`), without which the
steps along it crawled. The climbs start from several points
(the nominal solution and the best of a space-filling design moved towards
closure: :func:`bcad.bayes.estimators.search_starts`), advance in lockstep
(:func:`advance`: one batched evaluation per round of derivatives or trial
points for all climbs), share their steps by successive halving
(:func:`maximise_in_rounds`) and return every end point, best first, grouped
into basins (:func:`group_basins`), so that a more exact estimator can choose
among them (:mod:`bcad.bayes.importance`). A periodic X (a joint whose bounds
span a turn: :func:`bcad.bayes.objective.periodic_unknowns`) has no walls: the
climbs wrap it, and basins are compared the short way round it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bcad.bayes.linear import LinearModel

#: finite-difference step of the Hessian, in the unit box of the bounds
HESSIAN_STEP = 1e-5
#: the step where the cell is scored by inequalities alone (:func:`hessian_step`): their narrow
#: ridge (a peg centred in its hole) is then in the soft part, whose forward second differences
#: err by about h times its third derivative (no Gauss-Newton part takes it). On a UR5 peg cell,
#: climbs from six stopped maxima gained 0.00-0.07 with 1e-5 and 0.03-0.23 with 3e-7, as far as
#: Nelder-Mead from the same points (values are smooth to about 1e-12, so the second
#: differences' noise there is near 1e-12 / h^2 = 10, below the soft curvatures of 30 and more)
INEQUALITY_HESSIAN_STEP = 3e-7
#: a step that raises log p(X) I_lin(X) by less than this ends the search (a tenth of
#: the importance estimate's typical standard error: smaller gains are not resolved)
CONVERGED = 5e-4
#: Levenberg-Marquardt damping: initial (relative to the largest curvature) and its decrease after a success
INITIAL_DAMPING = 1e-6
DAMPING_DECREASE = 3.0
#: consecutive steps that gain less than CONVERGED before the search stops (one small
#: gain is often a step cut short by the damping, not a maximum). A redundant arm's ridge
#: (problems/studies/iiwa_probe_face.yaml) climbs slowly: with 3 its climb stopped 0.0035 below
#: the top L-BFGS-B finds, with 4 0.0001 below (the RX90 example's search 0.1 s longer)
PATIENCE = 4
#: damping increases tried before a Newton step gives up
MAX_DAMPING_TRIES = 30
#: value standing in for -inf, so that a line search can back off
PENALTY = 1e12
#: two maxima closer than this (unit box of the bounds, max norm) are one basin
BASIN_TOLERANCE = 1e-2
#: two climbs start at least this far apart (unit box of the bounds, max norm)
CLIMB_SPACING = 0.05
#: the climbs' budget: a climb's Newton step evaluates I_lin at about n^2 points, each linearised
#: in its nL free parameters, so CLIMB_EFFORT / (n^2 (nL + 1)) climbs (:func:`climbs_for`) cost
#: about the same on every problem: 12 on the RX90 (12 X, 48 L; raised to the floor of 24,
#: :data:`bcad.bayes.estimators.CLIMBS`), 147 and the cap of 192 on the
#: UR5 face and sphere examples (6 and 5 X, 15 and 11 L), whose many close maxima need them (10
#: seeds of the UR5 face: 8 within 0.02 of the best known with 48 climbs and 240 starts, 5 with
#: 12 and 64; the sphere: 5 with 48, 9 with 96, 10 with 192); the 21-X placement study's branch
#: search starts from its own 32 (:data:`bcad.bayes.estimators.BLOCK_CELL_CLIMBS`)
CLIMB_EFFORT = 84672
#: Newton steps per round of successive halving (:func:`maximise_in_rounds`)
ROUNDS = (4, 8, 12, 16)


#: distance between X's in the unit box (max norm; periodic X the short way round), broadcast over
#: leading axes: one X against a stack (k, n) gives k distances
Separation = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass
class LocalMaximum:
    x: np.ndarray
    log_value: float  # log p(X) + log I_lin(X)
    start: int
    iterations: int
    #: the climb stopped because it stopped gaining (not cut short by its step budget)
    converged: bool = False
    #: walked on along its ridge (:func:`walk_ridges`)
    walked: bool = False


#: chain values (12 per transform) that one block of the search's evaluations holds, at most (256 MB)
SEARCH_VALUES = 1 << 25


def maximise_in_rounds(
    model: LinearModel,
    starts: np.ndarray,
    iterations: int,
    rounds: tuple[int, ...] = ROUNDS,
    anchor: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    keep_first: bool = True,
) -> list[LocalMaximum]:
    """Damped Newton from every start, in rounds of successive halving: every climb takes
    ``rounds[0]`` steps, the better half of them ``rounds[1]`` more, and so on; the best climb
    then goes on to ``iterations`` steps in all (and no climb takes more: with fewer iterations
    than the rounds' steps, the rounds stop there). A climb dropped on the way ends where it
    stood. The first start (the nominal solution) is never dropped and climbs to the end too,
    so the search is never worse than a local climb from it (unless not ``keep_first``: a
    batch of further starts, where that climb is already made). Every climb's end point, best
    first (so the climbs' budget goes where the values are, and the number of climbs can grow
    with the time a user gives).

    With ``anchor`` and ``mask``, only the X of ``mask`` climb (``starts`` are whole X's; the
    other X stay at the anchor's values): a configuration's own joints on their own."""
    objective = model.objective
    mask = np.ones(objective.dimension, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    low, high = objective.bounds[mask, 0], objective.bounds[mask, 1]
    width = high - low
    periodic = np.isfinite(objective.periods[mask])
    to_x = unit_map(objective, mask, anchor)
    values = unit_values(model if anchor is None else model.holding(anchor, mask), to_x)
    climbs = [Climb(np.clip((start[mask] - low) / width, 0.0, 1.0)) for start in np.atleast_2d(starts)]
    difference_step = hessian_step(model)
    advance(values, climbs, 0, periodic, difference_step)  # their derivatives, in one batch
    active = list(range(len(climbs)))
    target = 0
    for steps in rounds:
        target = min(target + steps, iterations)  # (no climb takes more than ``iterations`` steps)
        advance(values, [climbs[k] for k in active], target, periodic, difference_step)
        kept = sorted(active, key=lambda k: -climbs[k].value)[: max(1, (len(active) + 1) // 2)]
        active = kept + ([0] if keep_first and 0 not in kept else [])
    best = sorted(active, key=lambda k: -climbs[k].value)[0]
    advance(
        values, [climbs[k] for k in sorted({best, 0} if keep_first else {best})], iterations, periodic, difference_step
    )
    found = [
        LocalMaximum(to_x(c.unit[None])[0], c.value, index, c.iterations, c.stopped) for index, c in enumerate(climbs)
    ]
    found.sort(key=lambda m: -m.log_value)
    return found


def climbs_for(dimension: int, free: int, limits: tuple[int, int]) -> int:
    """CLIMB_EFFORT / (n^2 (nL + 1)) climbs for n unknowns and nL free parameters, within ``limits``."""
    return int(np.clip(round(CLIMB_EFFORT / (max(dimension, 1) ** 2 * (free + 1))), *limits))


def scaled(count: float, effort: float, least: int, most: int | None = None) -> int:
    """A default budget ``count`` times the settings' ``search_effort``, rounded half up, within
    ``least`` and ``most``."""
    value = max(least, math.floor(count * effort + 0.5))
    return value if most is None else min(value, most)


def unit_map(
    objective, mask: np.ndarray | None = None, anchor: np.ndarray | None = None
) -> Callable[[np.ndarray], np.ndarray]:
    """Rows of unit coordinates (of X[mask]; every X by default) -> X: each X's bounds, a periodic
    X wrapped round its circle, the others clipped to their box, and the X outside ``mask`` at
    the ``anchor``'s values."""
    mask = np.ones(objective.dimension, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    low, high = objective.bounds[mask, 0], objective.bounds[mask, 1]
    periodic = np.isfinite(objective.periods[mask])
    base = np.asarray(anchor if anchor is not None else np.zeros(objective.dimension), dtype=float)

    def to_x(unit: np.ndarray) -> np.ndarray:
        unit = np.atleast_2d(unit)
        rows = np.repeat(base[None], len(unit), axis=0)
        rows[:, mask] = low + (high - low) * np.where(periodic, unit, np.clip(unit, 0.0, 1.0))
        return objective.canonical(rows)

    return to_x


def unit_values(model: LinearModel, to_x: Callable[[np.ndarray], np.ndarray]):
    """The climbs' ``values``: rows of unit coordinates -> log p(X) + log I_lin(X) of ``to_x(rows)``
    (-PENALTY where not finite) and, ``with_residuals``, the whitened residuals. Rows evaluated at
    once: each linearises the chains at 2 nL + 1 points of L, so a block of rows holds at most
    SEARCH_VALUES chain values (memory does not grow with n^3)."""
    objective = model.objective
    block = max(1, SEARCH_VALUES // max(1, 12 * model.points.count * len(model.chains)))

    def values(unit: np.ndarray, with_residuals: bool = False):
        population = to_x(unit)
        parts = [
            model.log_integral_parts(population[start : start + block]) for start in range(0, len(population), block)
        ]
        log_integral = np.concatenate([part[0] for part in parts])
        whitened = np.concatenate([part[2] for part in parts])
        log_value = objective.log_prior(population) + log_integral
        log_value = np.where(np.isfinite(log_value), log_value, -PENALTY)
        return (log_value, whitened) if with_residuals else log_value

    return values


def scored_by_inequalities_alone(model: LinearModel) -> bool:
    """Whether nothing but relations' inequalities scores the cell (a peg in a hole): no score's
    whitened residual then carries the stiff part of the Hessian."""
    return bool(model.relations) and not len(model.scored_rows)


def hessian_step(model: LinearModel) -> float:
    """The finite-difference step of ``model``'s climbs: INEQUALITY_HESSIAN_STEP where nothing but
    relations' inequalities scores the cell, else HESSIAN_STEP."""
    return INEQUALITY_HESSIAN_STEP if scored_by_inequalities_alone(model) else HESSIAN_STEP


def derivative_points(
    unit: np.ndarray, periodic: np.ndarray, step: float = HESSIAN_STEP
) -> tuple[np.ndarray, np.ndarray]:
    """The points of :func:`derivatives_from` about ``unit`` (1 + n + n (n + 1) / 2 + n rows) and the
    steps h, pointing into the box (a periodic coordinate has no wall: always forward): x,
    x + h_i e_i, x + h_i e_i + h_j e_j (i <= j), then the mirrors x - h_i e_i (outside the box
    where x is within h of a wall: those columns fall back to forward differences)."""
    n = len(unit)
    h = np.where(periodic | (unit + 2.0 * step <= 1.0), step, -step)
    upper_i, upper_j = np.triu_indices(n)
    return np.vstack([unit, unit + np.diag(h), unit + np.diag(h)[upper_i] + np.diag(h)[upper_j], unit - np.diag(h)]), h


def central_columns(unit: np.ndarray, h: np.ndarray, periodic: np.ndarray) -> np.ndarray:
    """Per X, whether its mirror point x - h e_i lies in the box (central differences)."""
    mirror = unit - h
    return periodic | ((mirror >= 0.0) & (mirror <= 1.0))


def derivatives_at(
    values, units: np.ndarray, periodic: np.ndarray, step: float = HESSIAN_STEP
) -> list[tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """f, gradient, Hessian, the whitened residuals' Jacobian and the residuals
    (:func:`derivatives_from`) at each row of ``units``, every row's points
    (:func:`derivative_points`) in one batched evaluation of ``values``."""
    built = [derivative_points(unit, periodic, step) for unit in units]
    f, w = values(np.vstack([points for points, _ in built]), with_residuals=True)
    size = len(built[0][0])
    return [
        derivatives_from(
            f[k * size : (k + 1) * size], w[k * size : (k + 1) * size], h, central_columns(unit, h, periodic)
        )
        for k, (unit, (_, h)) in enumerate(zip(units, built))
    ]


def derivatives_from(
    f: np.ndarray, w: np.ndarray, h: np.ndarray, central: np.ndarray | None = None
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """f, gradient and Hessian by finite differences from the values ``f`` and whitened
    residuals ``w`` at the points of :func:`derivative_points` (``central``: per X, whether its
    mirror point is in the box, :func:`central_columns`; default every one), and w's Jacobian and
    w at the point (the climbs' second-order correction: :func:`second_order_correction`).

    f = -|w|^2 / 2 + s: a stiff least-squares part (w, the whitened residual of the
    scored parameters) and a soft rest s. The stiff part's Hessian is Gauss-Newton's
    -J_w^T J_w, J_w by central differences of w (forward ones at a wall), the soft part's by
    second differences of s = f + |w|^2 / 2 (whose small third derivatives keep them
    accurate; second differences of f itself are swamped by the stiff part's).
    Points: x, x + h_i e_i, x + h_i e_i + h_j e_j (i <= j) and x - h_i e_i:
    H_ij = (s_ij - s_i - s_j + s) / (h_i h_j), and the gradient of f by central differences
    (forward ones at a wall, corrected to second order with the diagonal of H).

    J_w must be central: a forward difference's error (h w'' / 2) puts (dJ)^T dJ into the
    Hessian, of the order of 1e3 in the unit box on a UR5 at three configurations, where the
    soft directions' curvatures are 30 to 700: their Newton steps were noise, and the climbs
    stopped 0.13 below what one configuration's joints alone climbed to.
    """
    n = len(h)
    central = np.ones(n, dtype=bool) if central is None else central
    upper_i, upper_j = np.triu_indices(n)
    count = 1 + n + len(upper_i)
    soft = f[:count] + 0.5 * np.sum(w[:count] * w[:count], axis=1)
    base, single, pairs = soft[0], soft[1 : n + 1], soft[n + 1 :]
    hessian = np.empty((n, n))
    hessian[upper_i, upper_j] = (pairs - single[upper_i] - single[upper_j] + base) / (h[upper_i] * h[upper_j])
    hessian[upper_j, upper_i] = hessian[upper_i, upper_j]
    forward_w, mirror_w = w[1 : n + 1], w[count:]
    differences = np.where(central[:, None], (forward_w - mirror_w) / 2.0, forward_w - w[0])
    jacobian = differences.T / h  # (k, n)
    hessian -= jacobian.T @ jacobian
    forward_f, mirror_f = f[1 : n + 1], f[count:]
    gradient = np.where(
        central, (forward_f - mirror_f) / (2.0 * h), (forward_f - f[0]) / h - 0.5 * np.diagonal(hessian) * h
    )
    return float(f[0]), gradient, hessian, jacobian, w[0]


@dataclass
class Climb:
    """One damped Newton climb's state (:func:`advance`), in the unit box."""

    unit: np.ndarray
    value: float = -np.inf
    gradient: np.ndarray | None = None
    hessian: np.ndarray | None = None
    #: the Jacobian of the whitened residuals w in the unit box (k, n): the stiff part's
    jacobian: np.ndarray | None = None
    residual: np.ndarray | None = None  # w at the climb's point
    damping: float = 0.0
    iterations: int = 0
    small_gains: int = 0
    #: it stopped gaining (or has no free direction): more steps would not move it
    stopped: bool = False


def advance(
    values, climbs: list[Climb], target: int, periodic: np.ndarray, difference_step: float = HESSIAN_STEP
) -> None:
    """Every climb on to ``target`` steps in all (fewer where it stops), all in lockstep: each
    round of derivatives and of trial points is one batched evaluation of ``values`` (rows of
    points -> values, and the whitened residuals with ``with_residuals``), which costs far
    less than a call per climb.

    Each climb takes Levenberg-Marquardt damped Newton steps on the variables that are not
    held at a bound by the gradient (an active set; a ``periodic`` coordinate has no walls:
    ``values`` wraps it), each step projected on the box and kept only if it raises the
    value; the damping shrinks after a success and grows after a failure. Each trial point is
    scored with its second-order correction too (:func:`second_order_correction`), and the better
    kept. Measured on the
    RX90 example, this reached a given value in a quarter of L-BFGS-B's time, and Hessians
    refreshed only every few steps (symmetric rank-one updates in between) stopped short. A
    climb stops when PATIENCE steps in a row raise its value by less than CONVERGED, or when
    MAX_DAMPING_TRIES damping increases find no better point.
    """

    def refresh(group: list[Climb]) -> None:
        if not group:
            return
        found = derivatives_at(values, [c.unit for c in group], periodic, difference_step)
        for climb, (climb.value, climb.gradient, climb.hessian, climb.jacobian, climb.residual) in zip(group, found):
            if climb.damping == 0.0:
                climb.damping = INITIAL_DAMPING * max(float(np.max(np.abs(np.diagonal(climb.hessian)))), 1.0)

    refresh([c for c in climbs if c.gradient is None])
    active = [c for c in climbs if not c.stopped and c.iterations < target]
    while active:
        systems = {}
        for climb in active:
            unit, gradient = climb.unit, climb.gradient
            free = periodic | ~(((unit <= 0.0) & (gradient < 0.0)) | ((unit >= 1.0) & (gradient > 0.0)))
            if not free.any():
                climb.stopped = True
                continue
            H = -climb.hessian[np.ix_(free, free)]
            eigenvalues, vectors = np.linalg.eigh(0.5 * (H + H.T))
            systems[id(climb)] = (free, eigenvalues, vectors, vectors.T @ gradient[free])
        pending = [c for c in active if not c.stopped]
        accepted: list[tuple[Climb, np.ndarray, float]] = []
        for _ in range(MAX_DAMPING_TRIES):
            if not pending:
                break
            candidates = []
            for climb in pending:
                # Ascent step (|H| + lambda I)^-1 g: H's negative curvature reflected.
                free, eigenvalues, vectors, projected = systems[id(climb)]
                step = np.zeros_like(climb.unit)
                step[free] = vectors @ (projected / (np.abs(eigenvalues) + climb.damping))
                moved = climb.unit + step
                if np.any(~periodic & ((moved < 0.0) | (moved > 1.0))):
                    moved = climb.unit + bounded_step(climb, free, periodic, step)
                candidates.append(np.where(periodic, moved, np.clip(moved, 0.0, 1.0)))
            trial, trial_w = values(np.array(candidates), with_residuals=True)
            # Each trial also with its second-order correction (Nocedal and Wright, Sect. 18.3), the
            # better of the two kept: a step along a curved ridge of the stiff scores leaves them
            # at second order, which the quadratic model cannot see and the value punishes
            # (stiff curvatures of 1e8-3e9 in the unit box beside soft ones of 1e2), so the damping
            # grew until the steps crawled; the correction takes the trial back onto the ridge.
            corrected = [
                second_order_correction(climb, candidate, w, systems[id(climb)][0], periodic)
                for climb, candidate, w in zip(pending, candidates, trial_w)
            ]
            changed = [k for k, (c, t) in enumerate(zip(corrected, candidates)) if not np.array_equal(c, t)]
            if changed:  # (none where nothing scores the cell but inequalities)
                second = values(np.array([corrected[k] for k in changed]))
                for k, value in zip(changed, second):
                    if value > trial[k]:
                        candidates[k], trial[k] = corrected[k], value
            still = []
            for climb, candidate, value in zip(pending, candidates, trial):
                if value > climb.value:
                    accepted.append((climb, candidate, float(value)))
                else:
                    climb.damping *= 4.0
                    still.append(climb)
            pending = still
        for climb in pending:  # no better point within MAX_DAMPING_TRIES
            climb.stopped = True
        for climb, candidate, value in accepted:
            climb.small_gains = climb.small_gains + 1 if value - climb.value < CONVERGED else 0
            climb.iterations += 1
            climb.damping = max(climb.damping / DAMPING_DECREASE, 1e-12)
            climb.unit = candidate
            climb.stopped = climb.small_gains >= PATIENCE
        refresh([climb for climb, _, _ in accepted])
        active = [c for c in climbs if not c.stopped and c.iterations < target]


def second_order_correction(
    climb: Climb, candidate: np.ndarray, w: np.ndarray, free: np.ndarray, periodic: np.ndarray
) -> np.ndarray:
    """The ``candidate`` step of ``climb`` corrected back onto its stiff scores' ridge: the least
    (minimum-norm) move of the ``free`` variables that removes, to first order, the part of the
    whitened residual ``w`` at the candidate that the climb's linear model (w + J d at its point)
    did not predict, projected on the box. The candidate itself where ``w`` is not finite or there
    is no score."""
    delta = np.zeros_like(candidate)
    if climb.jacobian is not None and climb.jacobian.shape[0] and free.any() and np.all(np.isfinite(w)):
        excess = w - (climb.residual + climb.jacobian @ (candidate - climb.unit))
        delta[free] = -np.linalg.lstsq(climb.jacobian[:, free], excess, rcond=1e-10)[0]
    moved = candidate + delta
    return np.where(periodic, moved, np.clip(moved, 0.0, 1.0))


#: the ridge walk (:func:`walk_ridges`): candidates per point and step, steps per stage, and how
#: often the Hessian whose eigenvectors shape the candidates is refreshed
WALK_CANDIDATES = 32
WALK_STEPS = 100
WALK_REFRESH = 10
#: a point walks another stage while its last one gained more than WALK_GAIN (log units) and,
#: gaining as much in each stage left, it would come within WALK_REACH of the best point's value;
#: WALK_STAGES stages at most
WALK_GAIN = 0.005
WALK_REACH = 0.02
WALK_STAGES = 8


def walk_ridges(
    model: LinearModel,
    maxima: list[LocalMaximum],
    rng: np.random.Generator,
    steps: int = WALK_STEPS,
    stages: int = WALK_STAGES,
    best_known: float = -np.inf,
) -> list[LocalMaximum]:
    """Each maximum walked further along its ridge by a batched (1 + lambda) evolution strategy:
    WALK_CANDIDATES points per step drawn about it along the eigenvectors of its Hessian, each
    scaled by 1 / sqrt(|curvature| + 1) (a step across a stiff direction is as small as the
    ridge is narrow), the best taken where it gains; the scale grows 1.5 times after a gain and
    halves after none. The candidates of every maximum are one batched evaluation per step. The
    walk goes in stages of ``steps`` steps; a maximum walks another stage while its last one
    gained more than WALK_GAIN and as much again in each stage left would bring it within
    WALK_REACH of the best value, its batch's or ``best_known`` (the caller's other maxima), ``stages``
    stages at most.

    Where the inequalities alone score a cell (a peg in a hole), the maxima lie on ridges a few
    hundredths of a millimetre wide whose curvature across (1e8-1e10 in the unit box) drowns
    what second differences can resolve along them (1e2), and the Newton climbs stop short: on
    a UR5 peg placement, six climbs that had stopped 0.1-0.5 below their ridge's top gained
    0.11-0.53 in 100 steps of 64 candidates (0.7 s each), within 0.02 of where Nelder-Mead (an independent,
    derivative-free optimiser, 3000 serial evaluations) goes from the same points. Such a ridge
    can also be long and curved: on another, whose top lies 100 mm along the base's placement,
    100 steps went 15 mm and ended 0.04 below the top (exactly), 400 steps went 60-90 mm.
    There, 32 candidates a step reached within 0.002 of where 64 did, in two thirds of the time."""
    if not maxima:
        return maxima
    objective = model.objective
    low, width = objective.bounds[:, 0], objective.bounds[:, 1] - objective.bounds[:, 0]
    periodic = np.isfinite(objective.periods)
    to_x = unit_map(objective)
    values = unit_values(model, to_x)
    step = hessian_step(model)
    units = np.array([np.clip((m.x - low) / width, 0.0, 1.0) for m in maxima])
    best = np.array([m.log_value for m in maxima], dtype=float)
    best[np.isnan(best)] = -np.inf  # a value that was never computed: any finite point gains
    scale = np.full(len(maxima), 0.5)
    walked = np.zeros(len(maxima), dtype=int)
    walking = np.arange(len(maxima))  # the maxima still walking
    count, n = WALK_CANDIDATES, units.shape[1]
    for stage in range(stages):
        stage_start = best[walking].copy()
        for k in range(steps):
            if k % WALK_REFRESH == 0:
                hessians = np.array(
                    [hessian for _, _, hessian, *_ in derivatives_at(values, units[walking], periodic, step)]
                )
                eigenvalues, vectors = np.linalg.eigh(-0.5 * (hessians + np.swapaxes(hessians, 1, 2)))
                shapes = vectors / np.sqrt(np.abs(eigenvalues) + 1.0)[:, None, :]  # (P, n, n): scaled eigenvectors
            moves = rng.standard_normal((len(walking), count, n))
            candidates = units[walking, None, :] + scale[walking, None, None] * np.einsum("pcn,pmn->pcm", moves, shapes)
            candidates = np.where(periodic, candidates, np.clip(candidates, 0.0, 1.0))
            scored = values(candidates.reshape(-1, n)).reshape(len(walking), count)
            chosen = np.argmax(scored, axis=1)
            top = scored[np.arange(len(walking)), chosen]
            gained = top > best[walking]
            units[walking[gained]] = candidates[gained, chosen[gained]]
            best[walking[gained]] = top[gained]
            scale[walking] = np.clip(np.where(gained, scale[walking] * 1.5, scale[walking] * 0.5), 1e-6, 1.0)
        walked[walking] += steps
        # a maximum that was not finite when it set out has gained whatever it reached; the gains
        # shrink as a walk nears its top, so the last stage's, repeated, overstates what is left
        gain = np.where(np.isfinite(stage_start), best[walking] - stage_start, np.inf)
        left = stages - stage - 1
        if not left:
            break
        reaches = best[walking] + gain * left >= max(np.max(best), best_known) - WALK_REACH
        walking = walking[(gain > WALK_GAIN) & reaches]
        if not len(walking):
            break
    xs = to_x(units)
    return [
        LocalMaximum(x, float(value), m.start, m.iterations + int(steps_walked), m.converged, walked=True)
        for x, value, m, steps_walked in zip(xs, best, maxima, walked)
    ]


def bounded_step(climb: Climb, free: np.ndarray, periodic: np.ndarray, step: np.ndarray) -> np.ndarray:
    """The damped Newton step of a climb whose plain ``step`` (on the ``free`` variables) leaves the
    box: the variables it would carry out are held at the bound they reach (their move fixed) and
    the others solved again for the model's maximum given those moves, until no more leave
    (projected Newton). Clipping the
    plain step instead drops its moves across the bound, and with them what kept the stiff scores
    in balance: on a 7-joint arm with a joint 1e-5 inside its limit, every clipped step lost
    whatever it gained, the damping rose until the steps were 3e-5 of the box, and the climb
    stopped 0.02 below its ridge's top."""
    unit, hessian = climb.unit, climb.hessian
    held = np.zeros_like(unit)  # the moves of the variables held at a bound
    active = free.copy()
    while True:  # each round holds one variable more, or returns
        moved = unit + step
        out = active & ~periodic & ((moved < 0.0) | (moved > 1.0))
        if not out.any():
            return step
        held[out] = np.clip(moved[out], 0.0, 1.0) - unit[out]
        active &= ~out
        if not active.any():
            return held
        # maximum of g^T s + s^T H s / 2 over the active s_a: (-H_aa) s_a = g_a + H_ah s_h (reflected, damped)
        rhs = climb.gradient[active] + hessian[np.ix_(active, ~active)] @ held[~active]
        curvature = -hessian[np.ix_(active, active)]
        eigenvalues, vectors = np.linalg.eigh(0.5 * (curvature + curvature.T))
        step = held.copy()
        step[active] = vectors @ ((vectors.T @ rhs) / (np.abs(eigenvalues) + climb.damping))


def distinct_maxima(
    maxima: list[LocalMaximum], count: int, separation: Separation, tolerance: float = BASIN_TOLERANCE
) -> list[LocalMaximum]:
    """The best ``count`` maxima further than ``tolerance`` apart (``separation``:
    :meth:`bcad.bayes.objective.Objective.separation`)."""
    chosen: list[LocalMaximum] = []
    for maximum in maxima:
        if not chosen or np.all(separation(maximum.x, np.array([other.x for other in chosen])) > tolerance):
            chosen.append(maximum)
        if len(chosen) == count:
            break
    return chosen


@dataclass
class Basin:
    """A distinct local maximum of the search and the climbs that reached it."""

    x: np.ndarray
    log_value: float  # log p(X) + log I_lin(X) at its best climb
    climbs: int  # how many climbs ended in it
    iterations: int
    converged: bool = False  # a climb into it converged (others may have been cut short)
    starts: int = 1  # how many screened starts its climbs stand for


def group_basins(
    maxima: list[LocalMaximum],
    separation: Separation,
    tolerance: float = BASIN_TOLERANCE,
    weights: np.ndarray | None = None,
) -> list[Basin]:
    """The maxima grouped into basins, best first: a maximum within ``tolerance`` (``separation``:
    :meth:`bcad.bayes.objective.Objective.separation`, the unit box's max norm) of a better one is
    the same basin (both climbs count). ``weights[start]``: how many screened starts the climb
    from ``start`` stands for (default 1)."""
    basins: list[Basin] = []
    centres = np.empty((len(maxima), len(maxima[0].x) if maxima else 0))  # the basins' x, in order
    for maximum in sorted(maxima, key=lambda m: -m.log_value):
        weight = 1 if weights is None else int(weights[maximum.start])
        # the first basin within the tolerance, all basins compared in one broadcast
        near = np.flatnonzero(separation(maximum.x, centres[: len(basins)]) <= tolerance)
        if len(near):
            basin = basins[near[0]]
            basin.climbs += 1
            basin.starts += weight
            basin.converged = basin.converged or maximum.converged
        else:
            centres[len(basins)] = maximum.x
            basins.append(Basin(maximum.x, maximum.log_value, 1, maximum.iterations, maximum.converged, weight))
    return basins


def unseen_mass(basins: list[Basin]) -> float:
    """Good-Turing's estimate of the share of starts that would end in a basin not yet seen: the
    share of starts whose basin was reached by that one start only (Good 1953)."""
    starts = sum(basin.starts for basin in basins)
    return sum(basin.starts == 1 for basin in basins) / starts if starts else 1.0


def climb_starts(
    starts: np.ndarray, screen: np.ndarray, objective, count: int, taken: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The nominal solution, then the best-screened starts, each at least CLIMB_SPACING (unit box,
    max norm, :meth:`~bcad.bayes.objective.Objective.separation`) from those chosen before:
    ``count`` distinct places to climb from. Also, for each, how many screened starts it stands
    for (itself and those closer to it than CLIMB_SPACING: they would climb the same way).

    With ``taken`` (the starts of climbs already made, the nominal solution first), ``count``
    more, each as far from those too, and not the nominal solution again."""
    chosen = [0] if taken is None else []
    previous = starts[:0] if taken is None else np.atleast_2d(taken)
    for index in np.argsort(-screen[1:], kind="stable") + 1:
        if len(chosen) >= count or not np.isfinite(screen[index]):
            break
        others = np.vstack([previous, starts[chosen]])
        if np.all(objective.separation(starts[index], others) > CLIMB_SPACING):
            chosen.append(int(index))
    if not chosen:
        return starts[:0], np.zeros(0, dtype=int)
    distance = objective.separation(starts[:, None, :], starts[chosen][None, :, :])  # (starts, chosen)
    nearest = np.argmin(distance, axis=1)
    stands_for = np.bincount(nearest[np.min(distance, axis=1) <= CLIMB_SPACING], minlength=len(chosen))
    return starts[chosen], np.maximum(stands_for, 1)
