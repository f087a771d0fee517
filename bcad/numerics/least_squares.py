"""Bounded nonlinear least squares: Levenberg-Marquardt projected on a box.

Shared by the nominal backend (closing the cycles with L at nominal) and calibration (the
MAP of the measurements).
"""

from __future__ import annotations

import numpy as np

ITERATIONS = 200  # Levenberg-Marquardt steps per start
MAX_DAMPING_TRIES = 40
CLOSED = 1e-8  # sum of squared residuals counted as closed


def bounded_least_squares(
    residuals,
    jacobian,
    x: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    iterations: int = ITERATIONS,
    tolerance: float = 1e-12,
    damping: float = 1.0,
) -> tuple[np.ndarray, float]:
    """min |r(x)|^2 on the box [low, high]: Levenberg-Marquardt with Marquardt's diagonal
    scaling on the variables not held at a bound, each step projected on the box and
    kept only if it lowers the cost; it stops when a step lowers the cost by less than
    ``tolerance`` of it. ``damping`` is the first step's Marquardt factor (small: a Gauss-Newton
    step first, for problems that are nearly linear from the start).

    (scipy.optimize.least_squares does the same job, but importing scipy.optimize
    costs 0.66 s of start-up, a fifth of ``bcad solve``'s budget.)
    """
    r = residuals(x)
    cost = float(r @ r)
    for _ in range(iterations):
        if cost < CLOSED * 1e-6:
            break
        J = jacobian(x)
        gradient, normal = J.T @ r, J.T @ J
        # Variables at a bound that the descent direction pushes out stay there (an active set).
        free = ~(((x <= low) & (gradient > 0.0)) | ((x >= high) & (gradient < 0.0)))
        sub = normal[np.ix_(free, free)]
        diagonal = np.maximum(np.diagonal(sub), 1e-12 * max(float(np.max(np.diagonal(sub), initial=0.0)), 1e-300))
        for _ in range(MAX_DAMPING_TRIES):
            step = np.zeros_like(x)
            try:
                step[free] = np.linalg.solve(sub + damping * np.diag(diagonal), -gradient[free])
            except np.linalg.LinAlgError:
                pass
            candidate = np.clip(x + step, low, high)
            r_candidate = residuals(candidate)
            candidate_cost = float(r_candidate @ r_candidate)
            if candidate_cost < cost:
                break
            damping *= 4.0
        else:
            break  # no step lowers the cost: a (local) minimum
        converged = cost - candidate_cost <= tolerance * cost
        x, r, cost = candidate, r_candidate, candidate_cost
        damping = max(damping / 3.0, 1e-12)
        if converged:
            break
    return x, cost
