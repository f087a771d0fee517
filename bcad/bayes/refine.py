"""Local derivative-based refinement after the GA (the 2000 paper's Sect. 6).

The samples of L are held fixed (common random numbers), which makes the
Monte Carlo estimate a deterministic, almost everywhere smooth function of X;
L-BFGS-B then climbs log G(X) within the bounds. The gradient is a central
finite difference whose 2d + 1 points are evaluated as one population, so a
gradient costs one batched evaluation.

L-BFGS-B's first step has length 1 in its variables; X is therefore scaled
so that a unit step is 1e-3 of each bound's width (0.005 rad on a RX90
joint), a move of the size the GA's final mutations make, instead of the
whole box. A non-finite objective (every sample violates a constraint) is
replaced by a large finite penalty so that the line search can back off.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bcad.bayes.objective import Objective
from bcad.kinematics.chain import Samples

STEP = 1e-5  # finite-difference step, in the unit box of the bounds
UNIT_STEP = 1e-3  # a unit step of the optimiser, in the unit box of the bounds
PENALTY = 1e8


@dataclass
class Refinement:
    x: np.ndarray
    log_value: float
    start_log_value: float
    iterations: int
    evaluations: int


def refine(objective: Objective, x0: np.ndarray, samples: Samples, iterations: int) -> Refinement:
    from scipy.optimize import minimize

    low, high = objective.bounds[:, 0], objective.bounds[:, 1]
    width = high - low
    dimension = len(x0)
    evaluations = 0

    def negative_and_gradient(scaled: np.ndarray) -> tuple[float, np.ndarray]:
        nonlocal evaluations
        unit = scaled * UNIT_STEP
        steps = np.eye(dimension) * STEP
        points = np.clip(np.vstack([unit, unit + steps, unit - steps]), 0.0, 1.0)
        values = objective.log_value(low + width * points, samples, 0.0)
        evaluations += len(points)
        values = np.where(np.isfinite(values), values, -PENALTY)
        spacing = points[1 : dimension + 1].diagonal() - points[dimension + 1 :].diagonal()
        gradient = (values[1 : dimension + 1] - values[dimension + 1 :]) / np.where(spacing > 0, spacing, 1.0)
        return -float(values[0]), -gradient * UNIT_STEP

    start = np.clip((x0 - low) / width, 0.0, 1.0) / UNIT_STEP
    start_value = -negative_and_gradient(start)[0]
    result = minimize(
        negative_and_gradient,
        start,
        jac=True,
        method="L-BFGS-B",
        bounds=[(0.0, 1.0 / UNIT_STEP)] * dimension,
        # Each evaluation is a batched gradient; cap them, since line searches on a
        # noisy estimate can take many.
        options={"maxiter": iterations, "maxfun": 2 * iterations + 5},
    )
    value = -float(result.fun)
    if not value > start_value:
        return Refinement(np.asarray(x0, dtype=float), start_value, start_value, int(result.nit), evaluations)
    return Refinement(low + width * result.x * UNIT_STEP, value, start_value, int(result.nit), evaluations)
