"""Combinations of inverse-kinematics branches, one per configuration (or per cycle's own X).

A cell at C configurations has, per configuration, its own branches (shoulder, elbow, wrist: 8
for a 6R arm, a continuum for a redundant one), K^C combinations in all. The search's starts
meet a combination by chance, and a branch's value where the arm has just closed its cycle says
little of the maximum it climbs to. So every configuration's branches are climbed, then
combined:

1. From an anchor (one of the search's best maxima), each configuration's own X (its block) is
   searched globally with every other X held, as the whole X is (:func:`climbed_branches`): a
   space-filling design of the block moved onto closure
   (:func:`bcad.bayes.configurations.redraw_block`), its best distinct points and the anchor's
   own block climbed on the block's X alone (a Newton step on m of n X evaluates (m / n)^2 of
   the points), in rounds of successive halving; its BRANCHES best distinct maxima are kept.
2. A configuration's X enter only its own cycles, but the configurations share L (one robot's
   errors): a combination's value is not the sum of its branches' gains (branches whose errors
   move the tool alike are scored together). So every combination of the blocks' branches
   (B^C; beyond MAX_ENUMERATED, the best by the summed gains, a beam) is scored on the whole
   objective, log p(X) I_lin(X), in one batch, and the COMBINATIONS best are returned for the
   search to climb in full, shared X included.
3. The anchor's other blocks rank a block's branches in their context, and a branch that is best
   only beside other branches of the others ranks low there (on a UR5 touching a face, a point
   and a sphere, the best known combination changed two configurations' branches at once, and
   either change alone lost). So each block is also searched on its configuration's cell alone
   (:func:`alone_branches`: the other configurations' relations dropped, the shared X held at
   the anchor's), once per lineage, and those branches join every round's combinations.
"""

from __future__ import annotations

import heapq
import itertools

import numpy as np

from bcad.bayes.configurations import configuration_blocks, redraw_block, screen
from bcad.bayes.model import BayesModel
from bcad.bayes.search import climb_starts, climbs_for, distinct_maxima, maximise_in_rounds, scaled

#: a block's search: CLIMB_EFFORT / (m^2 (nL + 1)) climbs for m own X and nL L, within BLOCK_CLIMBS
#: (the cost of a Newton step on the block, as the whole search's budget:
#: :func:`bcad.bayes.search.climbs_for`), STARTS_PER_CLIMB redraws per climb to choose them from
BLOCK_CLIMBS = (8, 32)
STARTS_PER_CLIMB = 3
#: Newton steps of the block climbs' last round (successive halving before it)
BLOCK_ITERATIONS = 40
#: distinct climbed branches of a block combined (the anchor's own among them)
BRANCHES = 8
#: branches per block kept across rounds (:func:`branch_combinations`'s pool)
POOLED = 16
#: combinations returned per anchor for full climbs (in rounds of successive halving): a
#: combination's screen, its blocks at the anchor's context, ranks it poorly against where it
#: climbs to, and the configurations' blocks are coherent wholes (bench/block_exchange.py: no
#: seed's block gains in another seed's context, mixed combinations screen 0.15-0.3 lower). On two
#: UR5 cells at three poses (18 X, spheres and points), 48 instead of 6 brought 5 of 10 seeds
#: within 0.02 of the best known instead of 2, and on a 21-X placement cell the seeds' mean gap
#: from 0.067 to 0.020; its cost, on two cores: a three-pose cell's wall 10 s -> 13 s, the
#: placement cell's 18-24 s -> 30-40 s, two UR5s on one part 5-6 s -> 6-7 s
COMBINATIONS = 48
#: combinations ranked exhaustively up to this many; a beam of this width beyond
MAX_ENUMERATED = 4096


def block_budget(model: BayesModel, mask: np.ndarray, effort: float = 1.0) -> tuple[int, int]:
    """(redraws, climbs) of a block's search, the default's climbs times ``effort`` (the
    settings' ``search_effort``), at least 2."""
    climbs = scaled(climbs_for(int(mask.sum()), len(model.linear.mean_l), BLOCK_CLIMBS), effort, 2)
    return STARTS_PER_CLIMB * climbs, climbs


def climbed_branches(
    model: BayesModel,
    closure,
    anchor: np.ndarray,
    mask: np.ndarray,
    rng: np.random.Generator,
    iterations: int,
    effort: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """A global search of one block with the rest of X at the anchor (its own design moved onto
    closure, the best distinct redraws climbed on the block's X in rounds of successive halving,
    the anchor's own block first and never dropped): the BRANCHES best distinct maxima, the
    anchor's climbed block first: their block values (B, m) and log p(X) I_lin(X) (B,).
    ``effort``: the settings' ``search_effort`` (:func:`block_budget`)."""
    objective = model.objective
    draws, climbs = block_budget(model, mask, effort)
    closed, screens = redraw_block(model, closure, anchor[None], mask, rng, iterations, draws)
    starts = np.vstack([anchor[None], closed[0]])
    screens = np.concatenate([[np.inf], screens[0]])
    chosen, _ = climb_starts(starts, screens, objective, climbs)
    maxima = maximise_in_rounds(model.search_linear, chosen, BLOCK_ITERATIONS, anchor=anchor, mask=mask)
    own = next(m for m in maxima if m.start == 0)
    kept = [own] + [m for m in distinct_maxima(maxima, BRANCHES, objective.separation) if m is not own]
    kept = kept[:BRANCHES]
    return np.array([m.x[mask] for m in kept]), np.array([m.log_value for m in kept])


def alone_branches(
    model: BayesModel, anchor: np.ndarray, rng: np.random.Generator, iterations: int, effort: float = 1.0
) -> list[np.ndarray]:
    """Per block, the BRANCHES - 1 best distinct branches (block values (B, m)) of a global search of
    that block on its configuration's cell alone (:meth:`BayesModel.configurations_alone`), the
    shared X held at ``anchor``'s (:func:`climbed_branches` on that cell). Nothing where the cell
    has no configurations."""
    found = []
    for mask, cell in zip(configuration_blocks(model.compiled), model.configurations_alone()):
        if cell is None:
            found.append(np.empty((0, int(mask.sum()))))
            continue
        alone, columns = cell
        own = mask[columns]
        values, _ = climbed_branches(alone, alone.closure, anchor[columns], own, rng, iterations, effort)
        found.append(values[1:])  # (its first is the anchor's own block, already a branch of the round's)
    return found


def additive_combinations(gains: list[np.ndarray], count: int) -> list[tuple[int, ...]]:
    """The ``count`` combinations (one index per block) with the largest summed gains, best first,
    by a beam of width ``count`` over the blocks (exact for sums)."""
    beam: list[tuple[float, tuple[int, ...]]] = [(0.0, ())]
    for g in gains:
        extended = [(total + g[i], combo + (i,)) for total, combo in beam for i in range(len(g))]
        beam = heapq.nlargest(count, extended, key=lambda item: item[0])
    return [combo for _, combo in beam]


def branch_combinations(
    model: BayesModel,
    closure,
    anchors: np.ndarray,
    rng: np.random.Generator,
    iterations: int,
    pool: list[np.ndarray] | None = None,
    effort: float = 1.0,
    alone: list[np.ndarray] | None = None,
) -> np.ndarray:
    """Starts for full climbs (module docstring): per anchor, its COMBINATIONS best combinations of
    climbed branches by the whole objective's screen. ``pool``: per block, the branches (block
    values) that earlier rounds found, combined with this round's and extended by them (at most
    POOLED per block, the newest kept). ``effort`` (the settings' ``search_effort``) multiplies each
    block's search and the combinations returned. ``alone``: per block, its branches on its
    configuration's cell alone (:func:`alone_branches`), joined to each anchor's. Nothing for a
    problem with fewer than two blocks."""
    blocks = configuration_blocks(model.compiled)
    if len(blocks) < 2 or not len(anchors):
        return np.empty((0, model.objective.dimension))
    if pool is not None and not pool:
        pool.extend(np.empty((0, int(mask.sum()))) for mask in blocks)
    found = []
    for anchor in np.atleast_2d(anchors):
        branches, gains = [], []
        for b, mask in enumerate(blocks):
            values, scores = climbed_branches(model, closure, anchor, mask, rng, iterations, effort)
            if alone:
                rows = np.repeat(anchor[None], len(alone[b]), axis=0)
                rows[:, mask] = alone[b]
                values, scores = np.vstack([values, alone[b]]), np.concatenate([scores, screen(model, rows)])
            gain = np.where(np.isfinite(scores), scores - scores[0], -np.inf)
            if pool is not None:
                earlier = pool[b][: max(0, POOLED - len(values))]
                # An earlier round's branch has no gain measured at this anchor: ranked last by the sums.
                values, gain = np.vstack([values, earlier]), np.concatenate([gain, np.full(len(earlier), -1e3)])
                pool[b] = values[:POOLED]
            branches.append(values)
            gains.append(gain)
        # The configurations share L (one robot's errors): a combination's value is not the sum of
        # its branches' gains, so every combination (or the MAX_ENUMERATED best by that sum) is
        # scored on the whole objective.
        sizes = [len(g) for g in gains]
        if int(np.prod(sizes, dtype=float)) <= MAX_ENUMERATED:
            combos = list(itertools.product(*(range(size) for size in sizes)))
        else:
            combos = additive_combinations(gains, MAX_ENUMERATED)
        # (the anchor with every block climbed on its own is one of them: a sweep of block climbs)
        starts = np.repeat(anchor[None], len(combos), axis=0)
        for b, (mask, values) in enumerate(zip(blocks, branches)):
            starts[:, mask] = values[[combo[b] for combo in combos]]
        scores = screen(model, starts)
        returned = scaled(COMBINATIONS, effort, 1)
        order = [k for k in np.argsort(-scores, kind="stable")[:returned] if np.isfinite(scores[k])]
        found.extend(starts[order])
    return np.array(found).reshape(-1, model.objective.dimension)
