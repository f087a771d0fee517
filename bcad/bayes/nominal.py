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
closes, from the best point so far with scipy's solver.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

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
        x, cost = closure.close(x)
    return NominalSolution(x, cost, cost < CLOSED, 1 + RESTARTS)
