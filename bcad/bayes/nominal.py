"""The classical answer the papers compare against: close the cycles with
every free parameter at its nominal value, ignoring uncertainty.

With L at nominal the closing poses F_i(X, 0) are deterministic; the
nominal backend solves the least-squares problem

    min_X  sum over closing links of ((Q - nominal) / scale)^2 on their scored
           parameters + (violation / width)^2 of their relations' inequalities

within the bounds of X (Levenberg-Marquardt projected on the bounds), where ``scale`` is each distribution's standard deviation (or
width). It starts from the nominal X of the problem file and, if that does
not close the cycles, from seeded random starts.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from bcad.compile import CompiledProblem
from bcad.kinematics.chain import Samples
from bcad.bayes.objective import Objective

if TYPE_CHECKING:
    from bcad.bayes.model import BayesModel
from bcad.kinematics.se3 import wrap_angle
from bcad.numerics.least_squares import CLOSED, bounded_least_squares

RESTARTS = 20


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


class CycleClosure:
    """The nominal least-squares problem of a compiled problem: its residuals and their Jacobian."""

    def __init__(self, compiled: CompiledProblem, objective: Objective):
        self.objective = objective
        self.nominal_samples = Samples(np.zeros((1, len(compiled.parameters.l))))
        self.low, self.high = objective.bounds[:, 0], objective.bounds[:, 1]

    def residuals_of(self, population: np.ndarray) -> np.ndarray:
        """Residual vectors of a population of X, shape (P, residuals): one batched evaluation."""
        parts = []
        for cycle in self.objective.cycles:
            transform = cycle.chain.evaluate_population(population, self.nominal_samples)
            poses = transform.poses()[:, 0]
            for group in cycle.observed:
                deviation = poses[:, list(group.slots)] - group.nominal
                if group.angular:
                    deviation = wrap_angle(deviation)
                parts.append(deviation / _scale(group.distribution))
            if cycle.relation is not None and cycle.relation.inequality_count:
                distances = cycle.relation.inequalities_from(transform.columns, transform.translations)[..., 0]
                violation = np.maximum(distances, 0.0) / cycle.relation.widths[:, None]
                parts.append(np.moveaxis(violation, -1, 0).reshape(len(population), -1))
        return np.concatenate(parts, axis=1) if parts else np.zeros((len(population), 1))

    def residuals(self, x: np.ndarray) -> np.ndarray:
        return self.residuals_of(x[None])[0]

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        # Forward differences, every column in one batched evaluation; steps point into the box.
        step = 1e-7 * (self.high - self.low)
        step = np.where(x + step <= self.high, step, -step)
        values = self.residuals_of(np.vstack([x, x + np.diag(step)]))
        return ((values[1:] - values[0]) / step[:, None]).T

    def close(self, start: np.ndarray, fallback: bool = True) -> tuple[np.ndarray, float]:
        """The X near ``start`` that closes the cycles (least squares), and its cost.

        bcad's Levenberg-Marquardt first (it closes the RX90 example from its first
        start and costs no import); where it stalls short of closing, scipy's
        trust-region reflective solver from the same start, which is more robust
        at kinks and bounds (0.66 s to import, paid only then), and the better of the two.
        ``fallback=False`` keeps to the first (a search start needs no exact closure).
        """
        low, high = self.low, self.high
        interior = np.clip(start, low + 1e-9 * (high - low), high - 1e-9 * (high - low))
        x, cost = bounded_least_squares(self.residuals, self.jacobian, interior, low, high)
        if cost < CLOSED or not fallback:
            return x, cost
        from scipy.optimize import least_squares

        result = least_squares(self.residuals, interior, jac=self.jacobian, bounds=(low, high), method="trf", x_scale="jac")
        trf_cost = float(2.0 * result.cost)
        return (result.x, trf_cost) if trf_cost < cost else (x, cost)


def solve_nominal(model: BayesModel, rng: np.random.Generator) -> NominalSolution:
    """The cycles closed with L at nominal (module docstring), on the problem's model."""
    compiled = model.compiled
    closure = CycleClosure(compiled, model.objective)
    low, high = closure.low, closure.high
    best: NominalSolution | None = None
    start = np.clip(np.array(compiled.parameters.x_nominal, dtype=float), low, high)
    for attempt in range(RESTARTS + 1):
        if attempt:
            start = rng.uniform(low, high)
        x, cost = closure.close(start)
        if best is None or cost < best.cost:
            best = NominalSolution(x, cost, cost < CLOSED, attempt + 1)
        if best.closed:
            break
    return best
