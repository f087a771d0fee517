"""The classical answer the papers compare against: close the cycles with
every free parameter at its nominal value, ignoring uncertainty (a calibrated L at its
calibration's MAP: :func:`bcad.compiler.calibration.nominal_deviations`).

With L at nominal the closing poses F_i(X, L_nominal) are deterministic; the
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


@dataclass
class SeparableBlocks:
    """The configurations' (or cycles') own blocks of X (``masks``, (B, n)) where they hold every X
    and enter disjoint sets of cycles (``cycles``, (B, C): which cycles each block moves), so that
    the least squares is a sum of one term per block."""

    masks: np.ndarray
    cycles: np.ndarray

    def terms(self, closure, points: np.ndarray) -> np.ndarray:
        """Each block's term of the least-squares cost at each point, (P, B)."""
        costs = np.array([np.sum(part**2, axis=1) for part in closure.cycle_residuals_of(points)]).T
        return costs @ self.cycles.T.astype(float)


def separable_blocks(model: BayesModel) -> SeparableBlocks | None:
    """The blocks of :func:`bcad.bayes.configurations.configuration_blocks` where they are two or
    more, hold every X, and no two move the same cycle; None otherwise. Which cycles an X moves
    is read off the residuals (each X moved alone from a point of the box), so that a fixture's
    X that one configuration lists but another's cycle passes through, or a joint that mimics
    another configuration's, is seen."""
    blocks = configuration_blocks(model.compiled)
    if len(blocks) < 2 or not np.all(np.any(blocks, axis=0)):
        return None
    closure = model.closure
    low, high = closure.low, closure.high
    centre = low + 0.37 * (high - low)  # a point of the box, not its centre (no symmetry there)
    moved = np.repeat(centre[None], len(low) + 1, axis=0)
    moved[np.arange(1, len(low) + 1), np.arange(len(low))] += 0.01 * (high - low)
    parts = closure.cycle_residuals_of(moved)
    moves = np.array([np.any(part[1:] != part[:1], axis=1) for part in parts]).T  # (n, C)
    cycles = np.array([np.any(moves[mask], axis=0) for mask in blocks])  # (B, C)
    if np.any(cycles.sum(axis=0) > 1):
        return None
    return SeparableBlocks(np.array(blocks), cycles)


def blockwise_best(closure, points: np.ndarray, blocks: SeparableBlocks) -> np.ndarray:
    """The point whose every block is the best of ``points``' for that block's cycles: a restart
    closes all C configurations of a cell only where each of its blocks does (p^C), while some
    restart closes each block far more often."""
    chosen = np.argmin(np.nan_to_num(blocks.terms(closure, points), nan=np.inf), axis=0)  # (B,)
    assembled = points[0].copy()
    for mask, row in zip(blocks.masks, chosen):
        assembled[mask] = points[row, mask]
    return assembled


def closed_by_blocks(
    model: BayesModel, restarts: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, float, int] | None:
    """For a cell of separable blocks (:func:`separable_blocks`), the restarts' blocks combined
    (:func:`blockwise_best`) and closed; then each block still open, the most open first,
    redrawn RESTARTS times with the other X held and closed, until the cell closes or a block's
    redraws close it no better. The point, its cost and the starts redrawn; None for a cell
    without such blocks."""
    blocks = separable_blocks(model)
    if blocks is None:
        return None
    closure = model.closure
    x, cost = closure.close(blockwise_best(closure, restarts, blocks), fallback=False)
    redrawn = 0
    terms = blocks.terms(closure, x[None])[0]
    for b in np.argsort(-terms):
        if cost < CLOSED or terms[b] < CLOSED / len(terms):
            break
        mask = blocks.masks[b]
        rows = np.repeat(x[None], RESTARTS, axis=0)
        rows[:, mask] = rng.uniform(closure.low[mask], closure.high[mask], size=(RESTARTS, int(mask.sum())))
        found, costs = closure.close_many(rows, RESTART_ITERATIONS, first=True, fixed=~mask)
        redrawn += RESTARTS
        best = int(np.argmin(np.nan_to_num(costs, nan=np.inf)))
        if not costs[best] < cost - 0.5 * terms[b]:
            break  # this block closes no better: the cell cannot close by redrawing the others
        x, cost = found[best], float(costs[best])
    return x, cost, redrawn


def solve_nominal(model: BayesModel, rng: np.random.Generator) -> NominalSolution:
    """The cycles closed with L at nominal (module docstring), on the problem's model."""
    compiled = model.compiled
    closure = model.closure
    low, high = closure.low, closure.high
    start = np.clip(np.array(compiled.parameters.x_nominal, dtype=float), low, high)
    x, cost = closure.close(start, fallback=False, iterations=FILE_START_ITERATIONS)
    if cost < CLOSED:
        return NominalSolution(x, cost, True, 1)
    # The file's start does not close: RESTARTS seeded random starts at once (batched); where none
    # closes, the blocks of a cell of several configurations closed one by one; where that does
    # not close either, the robust fallback (scipy's, slow to import) from the best restart.
    restarts, costs = closure.close_many(
        rng.uniform(low, high, size=(RESTARTS, len(low))), RESTART_ITERATIONS, first=True
    )
    best = int(np.argmin(costs))
    if costs[best] < cost:
        x, cost = restarts[best], float(costs[best])
    starts = 1 + RESTARTS
    by_blocks = closed_by_blocks(model, restarts, rng) if cost >= CLOSED else None
    if by_blocks is not None:
        starts += 1 + by_blocks[2]
        if by_blocks[1] < CLOSED:
            return NominalSolution(by_blocks[0], by_blocks[1], True, starts)
    if cost >= CLOSED:
        x, cost = closure.close(x)
    if by_blocks is not None and by_blocks[1] < cost:  # neither closed: the nearer
        x, cost = by_blocks[0], by_blocks[1]
    return NominalSolution(x, cost, cost < CLOSED, starts)
