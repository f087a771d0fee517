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
from bcad.compiler.calibration import nominal_samples
from bcad.kinematics.se3 import wrap_angle
from bcad.numerics.least_squares import CLOSED, ITERATIONS, forward_differences, levenberg_marquardt

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
        # L at nominal: the file's poses, a calibrated L at its calibration's MAP
        self.nominal_samples = nominal_samples(compiled)
        self.low, self.high = objective.bounds[:, 0], objective.bounds[:, 1]

    def residuals_of(self, population: np.ndarray) -> np.ndarray:
        """Residual vectors of a population of X, shape (P, residuals): one batched evaluation."""
        parts = [part for part in self.cycle_residuals_of(population) if part.shape[1]]
        return np.concatenate(parts, axis=1) if parts else np.zeros((len(population), 1))

    def cycle_residuals_of(self, population: np.ndarray) -> list[np.ndarray]:
        """Per cycle, the residuals of a population of X (P, the cycle's residuals)."""
        parts = []
        for cycle in self.objective.cycles:
            transform = cycle.chain.evaluate_population(population, self.nominal_samples)
            poses = transform.poses()[:, 0]
            own = []
            for group in cycle.observed:
                deviation = poses[:, list(group.slots)] - group.nominal
                if group.angular:
                    deviation = wrap_angle(deviation)
                own.append(deviation / _scale(group.distribution))
            if cycle.relation is not None and cycle.relation.inequality_count:
                distances = cycle.relation.inequalities_from(transform.columns, transform.translations)[..., 0]
                violation = np.maximum(distances, 0.0) / cycle.relation.widths[:, None]
                own.append(np.moveaxis(violation, -1, 0).reshape(len(population), -1))
            parts.append(np.concatenate(own, axis=1) if own else np.zeros((len(population), 0)))
        return parts

    def residuals(self, x: np.ndarray) -> np.ndarray:
        return self.residuals_of(x[None])[0]

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        # Forward differences, every column in one batched evaluation; steps point into the box.
        x = np.atleast_2d(x)
        return forward_differences(self.residuals_of, 1e-7 * (self.high - self.low), self.high)(
            x, self.residuals_of(x)
        )[0]

    def _interior(self, starts: np.ndarray) -> np.ndarray:
        low, high = self.low, self.high
        return np.clip(np.asarray(starts, dtype=float), low + 1e-9 * (high - low), high - 1e-9 * (high - low))

    def close_many(
        self, starts: np.ndarray, iterations: int = 40, first: bool = False, fixed: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Every row of ``starts`` moved towards closing the cycles at once, by the batched
        Levenberg-Marquardt (:func:`bcad.numerics.least_squares.levenberg_marquardt`: one
        population evaluation for the residuals and one for the forward-difference Jacobians per
        round). Returns the points and their costs (sum of squared residuals; below CLOSED:
        closed), each after ``iterations`` steps tried at most. ``first``: stop as soon as one
        start has converged (the nominal backend needs one closed X, not all). ``fixed``: a mask
        of the X that stay where they start.

        The steps are projected on the box, not held at its walls (no active set): held walls
        close more of the search's starts (171 of 300 RX90 design points against 94), onto the
        joints' limits, and the search from them ended lower on 6 seeds of 20 (0.12-0.24)."""
        starts = np.atleast_2d(starts)
        n = starts.shape[1]
        chunk = max(1, int(CLOSE_MEMORY // (8 * max(n, 1) ** 2)))  # the normal matrices (P, n, n)
        if len(starts) > chunk:
            parts = [
                self.close_many(starts[k : k + chunk], iterations, first, fixed) for k in range(0, len(starts), chunk)
            ]
            return np.vstack([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
        return levenberg_marquardt(
            self.residuals_of,
            self._interior(starts),
            self.low,
            self.high,
            iterations=iterations,
            tries=iterations,
            first=first,
            fixed=fixed,
            active_set=False,
        )

    def close(self, start: np.ndarray, fallback: bool = True, iterations: int = ITERATIONS) -> tuple[np.ndarray, float]:
        """The X near ``start`` that closes the cycles (least squares), and its cost.

        bcad's Levenberg-Marquardt first (it closes the RX90 example from its first
        start and costs no import); where it stalls short of closing, scipy's
        trust-region reflective solver from the same start, which is more robust
        at kinks and bounds (0.66 s to import, paid only then), and the better of the two.
        ``fallback=False`` keeps to the first (a search start needs no exact closure).
        """
        low, high = self.low, self.high
        interior = self._interior(start)
        found, costs = levenberg_marquardt(
            self.residuals_of, interior[None], low, high, iterations=iterations, tolerance=1e-12, damping=1.0
        )
        x, cost = found[0], float(costs[0])
        if cost < CLOSED or not fallback:
            return x, cost
        from scipy.optimize import least_squares

        result = least_squares(
            self.residuals, interior, jac=self.jacobian, bounds=(low, high), method="trf", x_scale="jac"
        )
        trf_cost = float(2.0 * result.cost)
        return (result.x, trf_cost) if trf_cost < cost else (x, cost)
