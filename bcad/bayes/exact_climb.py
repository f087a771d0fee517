"""A climb of the exact objective log p(X) Î(X) on common random numbers.

The search (:mod:`bcad.bayes.search`) climbs I_lin, a smooth stand-in. Where
I_lin is not the integrand (a ``uniform``, ``truncnormal`` or ``disc`` L or
score is replaced by the Gaussian of its moments; a relation's inequalities
are smoothed), its maximum is not the objective's. This module climbs the
objective itself:

* With n samples drawn once from the importance proposal at the current X
  (:meth:`bcad.bayes.importance.ImportanceSampler.common_objective`), X' ->
  log p(X') Î(X') is a deterministic function (common random numbers), smooth
  wherever the integrand is: its gradient comes from forward differences
  (corrected to second order with the surrogate's curvature), all n points in
  one batched evaluation.
* The step is Newton's with I_lin's Hessian (:func:`surrogate_hessian`, in the
  unit box of X's bounds: the stand-in's curvature is right in scale where its
  maximum is off) and, beside it, the gradient scaled to the same length; a
  batch of fractions of both is scored on the same samples and the best kept
  if it gains SIGNIFICANCE paired standard errors (smaller gains on common
  samples are as likely the samples' as the integrand's).
* The surrogate's curvature (taken once, at the start) can be far from the
  objective's (a truncated normal's edge is flatter than the Gaussian of its
  moments), so the steps tried reach 8 times Newton's. A trial whose gain is
  positive but within noise doubles the samples; a climb stops where the best
  trial gains less than TOLERANCE, where no trial gains significantly with
  the most samples, after PATIENCE small gains in a row, after ROUNDS
  rounds, or where the budget is spent.
* After each accepted step the samples are drawn again at the new X, so the
  proposal follows the climb (its weights stay balanced however far it goes).
  Where I_lin is not the integrand (a non-Gaussian L or score), the posterior
  in L moves with X by more than its width within one step (a narrow score
  through a uniform L): each point then gets the proposal at itself, drawn
  from the same random numbers (:meth:`~bcad.bayes.importance.ImportanceSampler.moving_objective`),
  a smooth function of X whose weights stay balanced at every trial.
* A relation's inequalities are indicators: on a finite sample their mean is
  a staircase in X with no gradient. Where they weigh on the objective at the
  start (:func:`inequalities_active`), the gradient is the tempered
  objective's (Sect. 4.2.1 of the 2000 paper: outside the set,
  log f^T = -(d / w)^2 / T, at T = TEMPERATURE), while every step is judged
  on the objective itself (T = 0) on the same samples: the smooth stand-in
  chooses the direction, the exact objective decides. There X lies on a ridge
  (a peg within its clearance: 1e-4 of the box across, far longer along it),
  and forward differences of 1e-5 of the box read the few samples that cross
  the boundary, not the slope: the slopes are central differences along the
  surrogate's principal directions, each a tenth of the ridge's width along
  it, where many samples cross; the curvature along each is the larger of the
  surrogate's and the tempered objective's own second difference, the step
  kept within one width, and steps from 1/256 to 64 times it are scored
  (:func:`ridge_steps`). On a UR5 peg placement, from four seeds' answers,
  the climb gains 0.019-0.031, as far as Nelder-Mead on common samples goes
  (tests/bayes/test_exact_climb.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bcad.bayes.model import BayesModel
from bcad.bayes.search import derivatives_at, hessian_step, unit_map, unit_values
from bcad.numerics.weights import effective_sample_size, paired_log_ratio_se

#: common samples per round, raised (up to MAX_SAMPLES) until they hold MIN_EFFECTIVE effective ones
SAMPLES = 2048
MAX_SAMPLES = 16384
MIN_EFFECTIVE = 1500.0
#: forward-difference step of the gradient, in the unit box of X's bounds
GRADIENT_STEP = 1e-5
#: fractions of the Newton and gradient steps scored in each round
FRACTIONS = (8.0, 4.0, 2.0, 1.0, 0.5, 0.25, 0.125, 1.0 / 16, 1.0 / 64)
#: a step is taken where it gains this many paired standard errors: the best of several trials on
#: one sample is biased upwards, and on a 48-L arm moves on any gain climbed the samples' noise
SIGNIFICANCE = 2.0
#: a climb ends after PATIENCE rounds in a row gain less than this (a tenth of the finalists'
#: standard error goal)
TOLERANCE = 5e-4
PATIENCE = 2
#: a gain below this doubles the common samples (up to MAX_SAMPLES)
GROWTH_GAIN = 2e-2
#: rounds of a climb, at most
ROUNDS = 16
#: where the inequalities weigh on the objective (a peg in a hole: X within a clearance's width of
#: a ridge), the gradient is taken by central differences along the surrogate's principal
#: directions, each RIDGE_STEP of the ridge's width along it (1 / sqrt(curvature), in the unit
#: box; at most MAX_RIDGE_STEP): an indicator's mean on a sample is a staircase in X, and at the
#: fixed 1e-5 of the box its differences are the few samples that cross, not the slope
RIDGE_STEP = 0.1
MAX_RIDGE_STEP = 0.05
#: and Newton's step there is kept within this many widths (the surrogate's metric: a trust region,
#: since the gradient along a direction whose curvature the surrogate underrates sends it far off)
RIDGE_RADIUS = 1.0
#: the fractions of the ridge's steps scored, 1/256 to 64: its curvatures are estimates on a
#: staircase, the right step anywhere within two orders of magnitude of theirs
RIDGE_FRACTIONS = tuple(4.0**k for k in range(3, -5, -1))
#: the temperature of the gradient where inequalities weigh on the objective
TEMPERATURE = 1e-4
#: the inequalities are inactive where the samples that break them hold less than this share of
#: the relaxed weight (:func:`inequalities_active`)
ACTIVE_SHARE = 1e-3
#: the cost of a point's evaluation with the moving proposal, in evaluations of the fixed one's,
#: as the climbs' budget counts it: an upper bound (the proposal's chord step and the integrand: 2;
#: 4 where non-Gaussian L are adapted, with the central sample's mode)
MOVING_COST = 5
#: the work of one climb, at most: sample evaluations (rounds x points x samples) times the steps
#: of the problem's chains (a step costs about the same everywhere): 1e6 sample evaluations on
#: the RX90 example (27 steps), 3e7 on a one-link cell (where ROUNDS binds first)
BUDGET = 2.7e7


@dataclass
class ExactClimb:
    """Where the climb ended and what it did."""

    x: np.ndarray
    rounds: int
    #: the paired gains of the accepted steps, summed (on each round's own common samples)
    gain: float
    #: the temperature of the gradient (0: the objective's own)
    temperature: float = 0.0
    sample_evaluations: int = 0


def surrogate_hessian(model: BayesModel, x: np.ndarray) -> np.ndarray:
    """I_lin's Hessian of log p(X) I_lin(X) at X in the unit box of X's bounds (the search's
    finite differences: :func:`bcad.bayes.search.derivatives_from`)."""
    objective = model.objective
    low, width = objective.bounds[:, 0], objective.bounds[:, 1] - objective.bounds[:, 0]
    periodic = np.isfinite(objective.periods)
    unit = (np.asarray(x, dtype=float) - low) / width
    values = unit_values(model.polish_linear, unit_map(objective))  # in blocks of rows: memory bounded
    return derivatives_at(values, unit[None], periodic, hessian_step(model.polish_linear))[0][2]


def inequalities_active(model: BayesModel, x: np.ndarray, samples: int, rng: np.random.Generator) -> bool:
    """Whether the relations' inequalities weigh on the objective near X: with them relaxed (T =
    TEMPERATURE), the samples that break them hold more than ACTIVE_SHARE of the weight (on
    common samples). Where they do not, the objective is smooth about X and the climb needs no
    temperature."""
    values = model.importance.common_objective(x, samples, rng)
    point = np.asarray(x, dtype=float)[None]
    _, strict = values(point, 0.0)
    _, relaxed = values(point, TEMPERATURE)
    breaking = np.isneginf(strict[0]) & np.isfinite(relaxed[0])
    if not np.isfinite(relaxed[0]).any():
        return True
    peak = float(np.max(relaxed[0]))
    weights = np.exp(relaxed[0] - peak)
    return bool(weights[breaking].sum() > ACTIVE_SHARE * weights.sum())


def objective_near(model: BayesModel, x: np.ndarray, samples: int, rng: np.random.Generator, moving: bool):
    """The common-random-number objective for points near X: the proposal at each point drawn from
    one seed (``moving``), or the proposal at X for all (:mod:`bcad.bayes.importance`)."""
    if moving:
        return model.importance.moving_objective(samples, int(rng.integers(2**63)))
    return model.importance.common_objective(x, samples, rng)


def scaled_to(gradient: np.ndarray, step: np.ndarray) -> np.ndarray:
    """The gradient scaled to the length of ``step`` (the ascent tried beside Newton's step)."""
    return gradient * (float(np.linalg.norm(step)) / max(float(np.linalg.norm(gradient)), 1e-300))


def newton_and_ascent(gradient: np.ndarray, vectors: np.ndarray, curvature: np.ndarray):
    """Newton's step with the surrogate's curvature (its eigenvectors and |eigenvalues|, damped),
    and the gradient scaled to the same length (both in the unit box)."""
    newton = vectors @ ((vectors.T @ gradient) / curvature)
    return newton, scaled_to(gradient, newton)


def ridge_steps(
    values, unit: np.ndarray, periodic: np.ndarray, to_x, vectors: np.ndarray, curvature: np.ndarray, temperature: float
):
    """Newton's step and the scaled gradient where the inequalities weigh on the objective (module
    docstring), in the unit box.

    Along each of the surrogate's principal directions, a point ahead and one behind, RIDGE_STEP
    of the ridge's width 1 / sqrt(curvature) away (at most MAX_RIDGE_STEP of the box); a point
    that leaves the box is held on it, and the slope and curvature along the direction are those
    of the parabola through the centre and the two points where they are (projected on the
    direction): at a bound, one-sided. The curvature is the larger of the surrogate's and the
    tempered objective's own (the exact indicator's ridge is narrower than the smoothed one's),
    floored where both are flat at the curvature whose width is MAX_RIDGE_STEP; Newton's step in
    that basis is kept within RIDGE_RADIUS widths.

    Returns the two steps (None where a value is not finite) and the points evaluated."""
    n = len(unit)
    spread = np.minimum(RIDGE_STEP / np.sqrt(curvature), MAX_RIDGE_STEP)  # (n,): each direction's step
    offsets = (vectors * spread).T  # row i: direction i's step
    stencil = np.vstack([unit + offsets, unit - offsets])
    stencil = np.where(periodic, stencil, np.clip(stencil, 0.0, 1.0))  # where to_x puts them
    f, _ = values(to_x(np.vstack([unit[None], stencil])), temperature)
    if not np.all(np.isfinite(f)):
        return None, None, 2 * n + 1
    # where each point is along its direction: +-spread, less where the box held it
    along = np.sum((stencil - unit) * np.vstack([vectors.T, vectors.T]), axis=1)
    a, b = along[:n], along[n:]
    up, down = f[1 : n + 1] - f[0], f[n + 1 :] - f[0]
    ahead, behind = a > 0.1 * spread, b < -0.1 * spread
    a, b = np.where(ahead, a, 1.0), np.where(behind, b, -1.0)
    both = ahead & behind
    # f(t) = f0 + g t + c t^2 / 2 through (a, f0 + up) and (b, f0 + down): c, then g
    second = np.where(both, 2.0 * (up / a - down / b) / (a - b), 0.0)
    slopes = np.where(both, up / a - second * a / 2.0, np.where(ahead, up / a, np.where(behind, down / b, 0.0)))
    flat = (RIDGE_STEP / MAX_RIDGE_STEP) ** 2
    curvature = np.maximum(np.maximum(curvature, -second), flat)
    steps = slopes / curvature
    size = math.sqrt(float(np.sum(curvature * steps * steps)))  # in widths
    if size > RIDGE_RADIUS:
        steps *= RIDGE_RADIUS / size
    newton = vectors @ steps
    return newton, scaled_to(vectors @ slopes, newton), 2 * n + 1


def climb_exact(model: BayesModel, x: np.ndarray, rng: np.random.Generator, budget: float = BUDGET) -> ExactClimb:
    """X moved uphill on the exact objective (module docstring), within ``budget`` sample evaluations
    times chain steps."""
    objective = model.objective
    low, high = objective.bounds[:, 0], objective.bounds[:, 1]
    width = high - low
    periodic = np.isfinite(objective.periods)
    n = len(low)
    current = np.asarray(x, dtype=float).copy()
    hessian = surrogate_hessian(model, current)
    eigenvalues, vectors = np.linalg.eigh(-0.5 * (hessian + hessian.T))
    damping = 1e-6 * max(float(np.max(np.abs(eigenvalues), initial=0.0)), 1.0)
    curvature = np.abs(eigenvalues) + damping

    to_x = unit_map(objective)
    steps = max(1, sum(len(chain.steps) for chain in model.linear.chains))
    budget = budget / steps
    # Where I_lin is not the integrand (non-Gaussian L or scores), the posterior in L moves with
    # X by more than its width within a step: the proposal moves with X (three times the cost).
    moving = not model.importance.surrogate_is_exact
    cost = MOVING_COST if moving else 1
    samples = SAMPLES
    tempered = bool(model.linear.relations) and inequalities_active(model, current, samples, rng)
    temperature = TEMPERATURE if tempered else 0.0
    fractions = RIDGE_FRACTIONS if tempered else FRACTIONS
    per_round = (2 * n + 1 if tempered else n) + 2 * len(fractions)  # points evaluated per round
    spent, rounds, gained, small = 0, 0, 0.0, 0
    for _ in range(ROUNDS):
        if spent + (per_round + 1) * samples * cost > budget:
            break
        values = objective_near(model, current, samples, rng, moving)
        centre, centre_weights = values(current[None], 0.0)
        spent += samples * cost
        effective = effective_sample_size(centre_weights[0])
        if effective < MIN_EFFECTIVE and samples < MAX_SAMPLES:
            samples = int(min(MAX_SAMPLES, samples * MIN_EFFECTIVE / max(effective, 1.0)))
            if spent + (per_round + 2) * samples * cost > budget:
                break
            values = objective_near(model, current, samples, rng, moving)
            centre, centre_weights = values(current[None], 0.0)
            spent += samples * cost
        if not np.isfinite(centre[0]):
            break
        unit = (current - low) / width
        if tempered:
            newton, ascent, evaluated = ridge_steps(values, unit, periodic, to_x, vectors, curvature, temperature)
            spent += evaluated * samples * cost
            if newton is None:
                break
        else:
            # Forward differences, pointing into the box, corrected to second order with the
            # surrogate's curvature (as the search's: derivatives_from).
            h = np.where(periodic | (unit + GRADIENT_STEP <= 1.0), GRADIENT_STEP, -GRADIENT_STEP)
            f, _ = values(to_x(unit + np.diag(h)), temperature)
            spent += n * samples * cost
            gradient = (f - centre[0]) / h - 0.5 * np.diagonal(hessian) * h
            if not np.all(np.isfinite(gradient)):
                break
            newton, ascent = newton_and_ascent(gradient, vectors, curvature)
        trials = np.vstack([unit + a * d for d in (newton, ascent) for a in fractions])
        trial_x = to_x(trials)
        trial_values, trial_weights = values(trial_x, 0.0)  # the steps judged on the objective itself
        spent += len(trials) * samples * cost
        rounds += 1
        best = int(np.argmax(np.where(np.isfinite(trial_values), trial_values, -np.inf)))
        gain = float(trial_values[best] - centre[0])
        if not gain > SIGNIFICANCE * paired_log_ratio_se(trial_weights[best], centre_weights[0]):
            # The best of the trials is as likely the samples' gain as the objective's: more
            # samples, or the end where they are at their cap or the trials gain nothing worth
            # resolving (less than TOLERANCE: the climb is at the top).
            if samples >= MAX_SAMPLES or gain < TOLERANCE:
                break
            samples = min(MAX_SAMPLES, 2 * samples)
            continue
        current, gained = trial_x[best], gained + gain
        small = small + 1 if gain < TOLERANCE else 0
        if small >= PATIENCE:
            break
        if gain < GROWTH_GAIN and samples < MAX_SAMPLES:
            # Near the top, the gains are of the order of the samples' noise: more samples
            # (the paper's growing N, Sect. 4.2.3), so that the climb settles instead of wandering.
            samples = min(MAX_SAMPLES, 2 * samples)
    return ExactClimb(current, rounds, gained, temperature, spent)
