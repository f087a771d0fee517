"""Search starts for a cell at several configurations (issue 19): each configuration's branch chosen on its own.

The same holds for a cell without configurations whose cycles have X of their own (three arms on
one base, each reaching its own point: :func:`cycle_blocks`): each cycle's block is chosen in turn.

A cell at C configurations has, per configuration, its own inverse-kinematics branches (shoulder,
elbow, wrist): K branches each make K^C combinations, which a space-filling design of the whole X
meets only by chance (a UR5 at three configurations: 8^3 = 512). But a configuration's own X (its
replicated joints) enter only its own cycles, so with the shared X (a base placement) held, each
configuration's branch can be chosen in turn: from each of the best screened starts, each
configuration's block is redrawn from a space-filling design, moved onto closure with every other
X held, and the best of them (by the screen, log p(X) I_lin(X), the start's own block among them)
kept before the next configuration's turn. The screen never falls along the way, and K draws per
configuration search K^C combinations for C K closures.
"""

from __future__ import annotations

import numpy as np

from bcad.bayes.model import BayesModel
from bcad.compile import CompiledProblem
from bcad.numerics.design import halton

#: screened starts whose configurations are redrawn
ANCHORS = 8
#: climbed maxima from which block moves start (8 took the placement study 7.5 s for the same
#: answers as 4 in 5.6 s; 2 lost the workcell design one seed of 6: bench/global_search.py)
MOVE_ANCHORS = 4
#: draws of each configuration's block per start
DRAWS = 32
#: a block move lands at least this far (unit box, max norm) from the maximum it leaves
MOVE_SPACING = 0.05


def configuration_blocks(compiled: CompiledProblem) -> list[np.ndarray]:
    """Per configuration, a mask of the X columns that are its own (its replicated joints); for a
    cell without configurations, :func:`cycle_blocks`."""
    if not compiled.configurations:
        return cycle_blocks(compiled)
    links = compiled.graph.links
    owner = [links[p.link].configuration if p.link >= 0 else None for p in compiled.parameters.x]
    blocks = [np.array([o == c.name for o in owner]) for c in compiled.configurations]
    return [mask for mask in blocks if mask.any()]


def cycle_blocks(compiled: CompiledProblem) -> list[np.ndarray]:
    """Per cycle, a mask of the X columns that enter that cycle only (three arms on one base, each
    reaching its own point: each arm's joints), where two cycles at least have such X: with the
    X that several cycles share held (the base), each block is chosen on its own, as a
    configuration's is. Nothing for a single cycle, or cycles whose X are all shared."""
    graph = compiled.graph
    members = [{cycle.closing_link, *(index for index, _ in cycle.path)} for cycle in graph.cycles]
    cycles_of = [frozenset(c for c, links in enumerate(members) if p.link in links) for p in compiled.parameters.x]
    blocks = [np.array([owner == frozenset({c}) for owner in cycles_of]) for c in range(len(members))]
    blocks = [mask for mask in blocks if mask.any()]
    return blocks if len(blocks) >= 2 else []


def screen(model: BayesModel, points: np.ndarray) -> np.ndarray:
    """log p(X) I_lin(X), -inf where it is not finite."""
    log_integral, _, _ = model.search_linear.log_integral_parts(points)
    value = model.objective.log_prior(points) + log_integral
    return np.where(np.isfinite(value), value, -np.inf)


def design_box(objective) -> tuple[np.ndarray, np.ndarray]:
    """(low, span) of the space-filling design of X: each X's bounds, a periodic X's one turn."""
    periodic = np.isfinite(objective.periods)
    bounds = objective.bounds
    low = np.where(periodic, objective.period_starts, bounds[:, 0])
    return low, np.where(periodic, objective.periods, bounds[:, 1] - bounds[:, 0])


def redraw_block(model: BayesModel, closure, anchors: np.ndarray, mask: np.ndarray, rng: np.random.Generator,
                 iterations: int, draws: int = DRAWS) -> tuple[np.ndarray, np.ndarray]:
    """``draws`` redraws of the block ``mask`` of each anchor (A, n) from the design, moved onto
    closure with every other X held: the points (A, draws, n) and their screens (A, draws)."""
    low, span = design_box(model.objective)
    rows = np.repeat(anchors, draws, axis=0)
    rows[:, mask] = low[mask] + span[mask] * halton(len(rows), int(mask.sum()), rng)
    closed = model.objective.canonical(closure.close_many(rows, iterations, fixed=~mask)[0])
    return closed.reshape(len(anchors), draws, -1), screen(model, closed).reshape(len(anchors), draws)


def redrawn_starts(model: BayesModel, closure, starts: np.ndarray, scores: np.ndarray, rng: np.random.Generator,
                   iterations: int) -> tuple[np.ndarray, np.ndarray]:
    """The ANCHORS best ``starts`` with each configuration's block chosen in turn (module
    docstring), and their screens. Nothing for a problem with fewer than two configurations
    that have X of their own."""
    blocks = configuration_blocks(model.compiled)
    order = [k for k in np.argsort(-scores, kind="stable") if np.isfinite(scores[k])][:ANCHORS]
    if len(blocks) < 2 or not order:
        return np.empty((0, starts.shape[1])), np.empty(0)
    current = starts[order].copy()
    current_scores = scores[order].copy()
    every = np.arange(len(current))
    for mask in blocks:
        closed, values = redraw_block(model, closure, current, mask, rng, iterations)
        best = np.argmax(values, axis=1)
        gained = values[every, best] > current_scores
        current[gained] = closed[every, best][gained]
        current_scores[gained] = values[every, best][gained]
    return current, current_scores


def block_moves(model: BayesModel, closure, points: np.ndarray, rng: np.random.Generator, iterations: int) -> np.ndarray:
    """From each of ``points`` (distinct climbed maxima, best first), one move per configuration: its
    block replaced by the best-screened other branch (DRAWS draws moved onto closure, every other
    X held), for the search to climb from: a configuration whose branch was chosen at a start with
    another base may have a better one at the base the climb reached."""
    blocks = configuration_blocks(model.compiled)
    if len(blocks) < 2 or not len(points):
        return np.empty((0, points.shape[1] if points.ndim == 2 else 0))
    anchors = points[:MOVE_ANCHORS]
    every = np.arange(len(anchors))
    moves = []
    for mask in blocks:
        closed, values = redraw_block(model, closure, anchors, mask, rng, iterations)
        # Not the anchor's own branch again: draws within the climbing spacing of it are passed over.
        near = model.objective.separation(closed, anchors[:, None, :]) < MOVE_SPACING
        values = np.where(near, -np.inf, values)
        best = np.argmax(values, axis=1)
        found = np.isfinite(values[every, best])
        moves.append(closed[every, best][found])
    return np.vstack(moves)
