"""The classical answer the papers compare against: close the cycles with
every free parameter at its nominal value, ignoring uncertainty.

With L at nominal the closing poses F_i(X, 0) are deterministic; the
nominal backend solves the least-squares problem

    min_X  sum over closing links of ((Q - nominal) / scale)^2 on their scored
           parameters + (violation / width)^2 of their relations' inequalities

within the bounds of X (scipy.optimize.least_squares, trust-region
reflective), where ``scale`` is each distribution's standard deviation (or
width). It starts from the nominal X of the problem file and, if that does
not close the cycles, from seeded random starts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bcad.compile import CompiledProblem
from bcad.kinematics.chain import Samples
from bcad.solvers.objective import Objective, wrap_angle

RESTARTS = 20
CLOSED = 1e-8  # sum of squared residuals counted as closed


def _scale(distribution) -> float:
    std = getattr(distribution, "std", None)
    if std is not None:
        return float(std)
    if hasattr(distribution, "radius"):
        return float(distribution.radius)
    return float(distribution.high - distribution.low)


@dataclass
class NominalSolution:
    x: np.ndarray
    cost: float
    closed: bool
    starts: int


def solve_nominal(compiled: CompiledProblem, objective: Objective, rng: np.random.Generator) -> NominalSolution:
    from scipy.optimize import least_squares

    nominal_samples = Samples(np.zeros((1, len(compiled.parameters.l))))
    low, high = objective.bounds[:, 0], objective.bounds[:, 1]

    def residuals_of(population: np.ndarray) -> np.ndarray:
        """Residual vectors of a population of X, shape (P, residuals): one batched evaluation."""
        parts = []
        for cycle in objective.cycles:
            transform = cycle.chain.evaluate_population(population, nominal_samples)
            poses = transform.poses()[:, 0]
            for group in cycle.observed:
                deviation = poses[:, list(group.slots)] - group.nominal
                if group.angular:
                    deviation = wrap_angle(deviation)
                parts.append(deviation / _scale(group.distribution))
            if cycle.relation is not None and cycle.relation.inequality_count:
                distances = cycle.relation.inequalities_from(transform.columns, transform.translations)[..., 0]
                violation = np.maximum(distances, 0.0) / cycle.relation.widths[None, :, None]
                parts.append(np.moveaxis(violation, -1, 0).reshape(len(population), -1))
        return np.concatenate(parts, axis=1) if parts else np.zeros((len(population), 1))

    def residuals(x: np.ndarray) -> np.ndarray:
        return residuals_of(x[None])[0]

    def jacobian(x: np.ndarray) -> np.ndarray:
        # Forward differences, every column in one batched evaluation; steps point into the box.
        step = 1e-7 * (high - low)
        step = np.where(x + step <= high, step, -step)
        values = residuals_of(np.vstack([x, x + np.diag(step)]))
        return ((values[1:] - values[0]) / step[:, None]).T

    best: NominalSolution | None = None
    start = np.clip(np.array(compiled.parameters.x_nominal, dtype=float), low, high)
    for attempt in range(RESTARTS + 1):
        if attempt:
            start = rng.uniform(low, high)
        interior = np.clip(start, low + 1e-9 * (high - low), high - 1e-9 * (high - low))
        result = least_squares(residuals, interior, jac=jacobian, bounds=(low, high), method="trf", x_scale="jac")
        cost = float(2.0 * result.cost)
        if best is None or cost < best.cost:
            best = NominalSolution(result.x, cost, cost < CLOSED, attempt + 1)
        if best.closed:
            break
    return best
