"""The classical answer the papers compare against: close the cycles with
every free parameter at its nominal value, ignoring uncertainty.

With L at nominal the closing poses F_i(X, 0) are deterministic; the
nominal backend solves the least-squares problem

    min_X  sum over closing links of ((Q - nominal) / scale)^2 on their scored
           parameters + (violation / width)^2 of their relations' inequalities

within the bounds of X (Levenberg-Marquardt projected on the bounds), where ``scale`` is each
distribution's standard deviation (or width). It starts from the nominal X of the problem file and, if that does
not close the cycles within FILE_START_ITERATIONS steps, from RESTARTS seeded
random starts at once (the first to converge is the answer), and where none
closes, from each block's best (:func:`closed_by_blocks`), then from the best restart with
scipy's solver.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from bcad.bayes.configurations import configuration_blocks
from bcad.compiler import CompiledProblem
from bcad.numerics.least_squares import CLOSED

if TYPE_CHECKING:
    from bcad.bayes.model import BayesModel

RESTARTS = 20
#: Levenberg-Marquardt steps from the file's start before the restarts take over (it closes the
#: RX90 example in a few; on the UR5 face example it stalls, and 200 steps cost 0.18 s)
FILE_START_ITERATIONS = 50
#: batched Levenberg-Marquardt iterations of the restarts
RESTART_ITERATIONS = 200


@dataclass
class NominalSolution:
    x: np.ndarray
    cost: float
    closed: bool
    starts: int


def separable_blocks(compiled: CompiledProblem) -> list[np.ndarray]:
    """The configurations' (or cycles') own blocks of X where they are two or more and hold every
    X: the least squares is then a sum of one term per block. Nothing otherwise."""
    blocks = configuration_blocks(compiled)
    return blocks if len(blocks) >= 2 and np.all(np.any(blocks, axis=0)) else []


def blockwise_best(closure, points: np.ndarray, blocks: list[np.ndarray]) -> tuple[np.ndarray, float]:
    """The point whose every block (:func:`separable_blocks`) is the best of ``points``' for that
    block's cycles, and its cost.

    The blocks enter disjoint sets of cycles, so each block's term can be read off by moving that
    block alone: a restart closes all C configurations of a cell only where each of its blocks
    does (p^C), while some restart closes each block far more often (on a UR5 at three poses
    touching faces, 1 of 20 restarts closed every pose on 1 seed of 5, and without this the
    fallback from the best took 0.2-7 s)."""
    assembled = points[0].copy()
    for mask in blocks:
        # cost(the point with this block from row r) = this block's term at r + the others' terms
        moved = np.repeat(assembled[None], len(points), axis=0)
        moved[:, mask] = points[:, mask]
        assembled[mask] = points[int(np.argmin(np.sum(closure.residuals_of(moved) ** 2, axis=1))), mask]
    return assembled, float(np.sum(closure.residuals_of(assembled[None]) ** 2))


def closed_by_blocks(model: BayesModel, restarts: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """For a cell of separable blocks, the restarts' blocks combined (:func:`blockwise_best`) and
    closed; then, while it is not closed, each block in turn redrawn RESTARTS times with the other
    X held and closed, the best kept where it lowers the cost (a block that no restart closed).
    The point and its cost (infinite for a cell without such blocks)."""
    blocks = separable_blocks(model.compiled)
    if not blocks:
        return restarts[0], np.inf
    closure = model.closure
    x, cost = closure.close(blockwise_best(closure, restarts, blocks)[0], fallback=False)
    for mask in blocks:
        if cost < CLOSED:
            break
        rows = np.repeat(x[None], RESTARTS, axis=0)
        rows[:, mask] = rng.uniform(closure.low[mask], closure.high[mask], size=(RESTARTS, int(mask.sum())))
        redrawn, costs = closure.close_many(rows, RESTART_ITERATIONS, first=True, fixed=~mask)
        best = int(np.argmin(costs))
        if costs[best] < cost:
            x, cost = redrawn[best], float(costs[best])
    return x, cost


def solve_nominal(model: BayesModel, rng: np.random.Generator) -> NominalSolution:
    """The cycles closed with L at nominal (module docstring), on the problem's model."""
    compiled = model.compiled
    closure = model.closure
    low, high = closure.low, closure.high
    start = np.clip(np.array(compiled.parameters.x_nominal, dtype=float), low, high)
    x, cost = closure.close(start, fallback=False, iterations=FILE_START_ITERATIONS)
    if cost < CLOSED:
        return NominalSolution(x, cost, True, 1)
    # The file's start does not close: RESTARTS seeded random starts at once (batched), then,
    # where none closes, the robust fallback (scipy's, slow to import) from the best of all.
    restarts, costs = closure.close_many(
        rng.uniform(low, high, size=(RESTARTS, len(low))), RESTART_ITERATIONS, first=True
    )
    best = int(np.argmin(costs))
    if costs[best] < cost:
        x, cost = restarts[best], float(costs[best])
    if cost >= CLOSED:
        # the blocks' best restarts combined, and each block redrawn with the others held; kept
        # only where it closes (else scipy's fallback from the best restart, as without blocks)
        assembled, assembled_cost = closed_by_blocks(model, restarts, rng)
        if assembled_cost < CLOSED:
            x, cost = assembled, assembled_cost
    if cost >= CLOSED:
        x, cost = closure.close(x)
    return NominalSolution(x, cost, cost < CLOSED, 1 + RESTARTS)
