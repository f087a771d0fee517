"""The blocks of X that configurations (or cycles) have of their own, and their redraws.

A cell at C configurations has, per configuration, its own X: its replicated joints, which enter
only its own cycles (:func:`configuration_blocks`); a cell without configurations whose cycles have
X of their own (three arms on one base, each reaching its own point) has one block per such cycle
(:func:`cycle_blocks`). With the other X held, a block can be redrawn from a space-filling design
and moved onto closure (:func:`redraw_block`): the branch search
(:mod:`bcad.bayes.branches`) builds on it, and on each configuration's cell alone
(:mod:`bcad.bayes.alone`), where a configuration's branches are ranked without the others'.
"""

from __future__ import annotations

import numpy as np

from bcad.bayes.alone import configuration_masks
from bcad.bayes.model import BayesModel
from bcad.compiler import CompiledProblem
from bcad.numerics.design import halton

#: draws of a configuration's block, by default
DRAWS = 32


def configuration_blocks(compiled: CompiledProblem) -> list[np.ndarray]:
    """Per configuration, a mask of the X columns that are its own (its replicated joints); for a
    cell without configurations, :func:`cycle_blocks`."""
    if not compiled.configurations:
        return cycle_blocks(compiled)
    return [mask for mask in configuration_masks(compiled) if mask.any()]


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


def redraw_block(
    model: BayesModel,
    closure,
    anchors: np.ndarray,
    mask: np.ndarray,
    rng: np.random.Generator,
    iterations: int,
    draws: int = DRAWS,
) -> tuple[np.ndarray, np.ndarray]:
    """``draws`` redraws of the block ``mask`` of each anchor (A, n) from the design, moved onto
    closure with every other X held: the points (A, draws, n) and their screens (A, draws)."""
    low, span = design_box(model.objective)
    rows = np.repeat(anchors, draws, axis=0)
    rows[:, mask] = low[mask] + span[mask] * halton(len(rows), int(mask.sum()), rng)
    closed = model.objective.canonical(closure.close_many(rows, iterations, fixed=~mask)[0])
    return closed.reshape(len(anchors), draws, -1), screen(model, closed).reshape(len(anchors), draws)
