"""The cycles closed with every free parameter at nominal: the residuals of the closing links'
scored parameters (and their relations' inequalities) over their scale, and batched
Levenberg-Marquardt on them within the bounds of X. The nominal backend (:mod:`bcad.bayes.nominal`)
solves it once; the global search moves its design onto closure with it
(:func:`bcad.bayes.estimators.search_starts`), and the configurations' block moves with part of X
held (:mod:`bcad.bayes.configurations`). Built once per problem, with its BayesModel.
"""

from __future__ import annotations

import numpy as np

from bcad.bayes.objective import Objective
from bcad.compiler import CompiledProblem
from bcad.kinematics.chain import Samples
from bcad.kinematics.se3 import wrap_angle
from bcad.numerics.least_squares import CLOSED, ITERATIONS, bounded_least_squares

#: bytes of Levenberg-Marquardt normal matrices that close_many holds at once
CLOSE_MEMORY = 64e6


def _scale(distribution) -> float:
    std = getattr(distribution, "std", None)
    if std is not None:
        return float(std)
    if hasattr(distribution, "radius"):
        return float(distribution.radius)
    return float(distribution.high - distribution.low)


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

    def close_many(
        self, starts: np.ndarray, iterations: int = 40, first: bool = False, fixed: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Every row of ``starts`` moved towards closing the cycles at once: Levenberg-Marquardt
        on the box, batched over the starts (one population evaluation for the residuals and
        one for the forward-difference Jacobians per iteration). Returns the points and their
        costs (sum of squared residuals; below CLOSED: closed). ``first``: stop as soon as one
        start has converged (the nominal backend needs one closed X, not all). ``fixed``: a mask
        of the X that stay where they start (their Jacobian columns are zero, so is their step)."""
        starts = np.atleast_2d(starts)
        n = starts.shape[1]
        chunk = max(1, int(CLOSE_MEMORY // (8 * max(n, 1) ** 2)))  # the normal matrices (P, n, n)
        if len(starts) > chunk:
            parts = [
                self.close_many(starts[k : k + chunk], iterations, first, fixed) for k in range(0, len(starts), chunk)
            ]
            return np.vstack([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
        low, high = self.low, self.high
        x = np.clip(starts.astype(float), low + 1e-9 * (high - low), high - 1e-9 * (high - low))
        count = len(x)
        r = self.residuals_of(x)
        cost = np.sum(r * r, axis=1)
        damping = np.full(count, 1e-3)
        step = 1e-7 * (high - low)
        for _ in range(iterations):
            active = cost >= CLOSED * 1e-6
            if not active.any() or (first and not active.all()):
                break
            signs = np.where(x + step <= high, 1.0, -1.0)  # (P, n): steps into the box
            shifted = x[:, None, :] + np.eye(n)[None] * (step * signs)[:, None, :]
            values = self.residuals_of(shifted.reshape(-1, n)).reshape(count, n, -1)
            J = np.swapaxes((values - r[:, None, :]) / (step * signs)[:, :, None], 1, 2)  # (P, k, n)
            if fixed is not None:
                J[:, :, fixed] = 0.0
            gradient = np.einsum("pkn,pk->pn", J, r)
            normal = np.einsum("pkn,pkm->pnm", J, J)
            diagonal = np.maximum(np.diagonal(normal, axis1=1, axis2=2), 1e-12)
            system = normal + damping[:, None, None] * np.eye(n)[None] * diagonal[:, :, None]
            with np.errstate(all="ignore"):
                delta = -np.linalg.solve(system, gradient[..., None])[..., 0]
            delta = np.where(np.isfinite(delta), delta, 0.0)
            candidate = np.clip(x + delta, low, high)
            r_candidate = self.residuals_of(candidate)
            cost_candidate = np.sum(r_candidate * r_candidate, axis=1)
            better = active & np.isfinite(cost_candidate) & (cost_candidate < cost)
            x[better], r[better], cost[better] = candidate[better], r_candidate[better], cost_candidate[better]
            damping = np.where(better, np.maximum(damping / 3.0, 1e-12), np.minimum(damping * 4.0, 1e12))
        return x, cost

    def close(self, start: np.ndarray, fallback: bool = True, iterations: int = ITERATIONS) -> tuple[np.ndarray, float]:
        """The X near ``start`` that closes the cycles (least squares), and its cost.

        bcad's Levenberg-Marquardt first (it closes the RX90 example from its first
        start and costs no import); where it stalls short of closing, scipy's
        trust-region reflective solver from the same start, which is more robust
        at kinks and bounds (0.66 s to import, paid only then), and the better of the two.
        ``fallback=False`` keeps to the first (a search start needs no exact closure).
        """
        low, high = self.low, self.high
        interior = np.clip(start, low + 1e-9 * (high - low), high - 1e-9 * (high - low))
        x, cost = bounded_least_squares(self.residuals, self.jacobian, interior, low, high, iterations)
        if cost < CLOSED or not fallback:
            return x, cost
        from scipy.optimize import least_squares

        result = least_squares(
            self.residuals, interior, jac=self.jacobian, bounds=(low, high), method="trf", x_scale="jac"
        )
        trf_cost = float(2.0 * result.cost)
        return (result.x, trf_cost) if trf_cost < cost else (x, cost)
