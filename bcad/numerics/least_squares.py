"""Bounded nonlinear least squares: Levenberg-Marquardt projected on a box, batched over starts.

One implementation for every least-squares problem bcad solves: closing the cycles with L at
nominal (the nominal backend, and the search's starts moved onto the closure manifold) and the
MAP of a calibration's measurements.

(scipy.optimize.least_squares does the job for one start, but importing scipy.optimize costs
0.66 s of start-up, a fifth of ``bcad solve``'s budget, and it solves one start at a time where
the search closes hundreds at once.)
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

ITERATIONS = 200  # accepted Levenberg-Marquardt steps per start, at most
MAX_DAMPING_TRIES = 40  # rejected steps in a row before a start is taken as a (local) minimum
CLOSED = 1e-8  # sum of squared residuals counted as closed

#: rows of points (P, n) -> their residuals (P, k)
Residuals = Callable[[np.ndarray], np.ndarray]
#: rows of points (P, n) and their residuals (P, k) -> the Jacobians (P, k, n)
Jacobians = Callable[[np.ndarray, np.ndarray], np.ndarray]


def forward_differences(
    residuals_of: Residuals, step: np.ndarray, high: np.ndarray, fixed: np.ndarray | None = None
) -> Jacobians:
    """Jacobians by forward differences of ``step`` (n,) (a step that would leave the box below
    ``high`` goes backwards), every row's shifted points in one evaluation of ``residuals_of``;
    the columns of ``fixed`` variables (a mask (n,)) are not evaluated and left 0."""
    moved = np.arange(len(step)) if fixed is None else np.flatnonzero(~np.asarray(fixed, dtype=bool))

    def jacobians(x: np.ndarray, r: np.ndarray) -> np.ndarray:
        count, n = x.shape
        if not len(moved):  # every variable held: nothing moves
            return np.zeros((count, r.shape[1], n))
        signed = np.where(x + step <= high, step, -step)[:, moved]  # (P, m)
        shifted = np.repeat(x[:, None, :], len(moved), axis=1)  # (P, m, n): each moved in one variable
        shifted[:, np.arange(len(moved)), moved] += signed
        values = residuals_of(shifted.reshape(-1, n)).reshape(count, len(moved), -1)
        J = np.zeros((count, r.shape[1], n))
        J[:, :, moved] = np.swapaxes((values - r[:, None, :]) / signed[:, :, None], 1, 2)
        return J

    return jacobians


def damped_step(system: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Each (n, n) system of the batch solved for its right-hand side (n, 1); where one is singular
    in floating point (columns of the Jacobian 1e-16 of the others, as a joint that does not move a
    contact point, whose cross terms eliminate to an exact zero pivot), the least-norm solution
    of every system of the batch (their pseudo-inverses: the same solution for the others)."""
    with np.errstate(all="ignore"):
        try:
            return np.linalg.solve(system, rhs)
        except np.linalg.LinAlgError:
            return np.linalg.pinv(system) @ rhs


def levenberg_marquardt(
    residuals_of: Residuals,
    starts: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    jacobians: Jacobians | None = None,
    *,
    iterations: int = ITERATIONS,
    tries: int | None = None,
    tolerance: float = 0.0,
    damping: float = 1e-3,
    first: bool = False,
    fixed: np.ndarray | None = None,
    active_set: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """min |r(x)|^2 on the box [low, high] from every row of ``starts`` (P, n) at once.

    Levenberg-Marquardt with Marquardt's diagonal scaling, (J^T J + lambda diag(J^T J)) d = -J^T r,
    on the variables not held at a bound by the descent direction (an active set), each step
    projected on the box and kept only if it lowers the cost; lambda starts at ``damping`` (small:
    a Gauss-Newton step first), shrinks 3 times after a success and grows 4 times after a failure.
    Each round evaluates the residuals of the rows still running once, and the Jacobians of those
    that moved (a rejected step keeps its row's Jacobian).

    A row stops when it is closed (cost below CLOSED * 1e-6), after ``iterations`` accepted steps
    or ``tries`` steps tried (accepted or not: each costs an evaluation), after MAX_DAMPING_TRIES
    rejected steps in a row (a local minimum), or when a step lowers its cost by no more than
    ``tolerance`` of it.

    Args:
        residuals_of: rows of points (P, n) -> residuals (P, k).
        starts: the starting points (P, n), clipped into the box.
        low: the box's lower bounds (n,).
        high: the box's upper bounds (n,).
        jacobians: rows of points and their residuals -> Jacobians (P, k, n); by default forward
            differences of 1e-7 of the box (:func:`forward_differences`).
        iterations: accepted steps per row, at most.
        tries: steps tried per row, at most (a budget of evaluations).
        tolerance: relative decrease of the cost below which a row has converged.
        damping: the first step's lambda.
        first: stop every row as soon as one is closed (one closed point is all that is wanted).
        fixed: mask (n,) of the variables that stay where they start.
        active_set: hold a variable at a bound that the descent direction pushes out (the
            bounded problem's solution); without, every variable takes its part of the
            unbounded step, which is then clipped to the box (a projected step: cheaper moves
            along the walls, and a point that cannot close against a wall stays unclosed).

    Returns:
        The points (P, n) and their costs (P,): sums of squared residuals.
    """
    low, high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
    x = np.clip(np.atleast_2d(np.asarray(starts, dtype=float)), low, high)
    count, n = x.shape
    if jacobians is None:  # (a fixed variable's column is never used: not evaluated)
        jacobians = forward_differences(residuals_of, 1e-7 * (high - low), high, fixed)
    tries = iterations * MAX_DAMPING_TRIES if tries is None else tries
    r = residuals_of(x)
    cost = np.sum(r * r, axis=1)
    lam = np.full(count, float(damping))
    accepted = np.zeros(count, dtype=int)
    tried = np.zeros(count, dtype=int)
    rejected = np.zeros(count, dtype=int)
    running = ~(cost < CLOSED * 1e-6)
    stale = np.ones(count, dtype=bool)  # rows whose Jacobian is not at their point
    J = np.zeros((count, r.shape[1], n))
    identity = np.eye(n)
    while running.any() and not (first and (cost < CLOSED * 1e-6).any()):
        rows = np.flatnonzero(running)
        update = rows[stale[rows]]
        if len(update):
            J[update] = jacobians(x[update], r[update])
            stale[update] = False
        Jr, rr, xr = J[rows], r[rows], x[rows]
        transposed = np.swapaxes(Jr, 1, 2)  # batched products: several times faster than einsum's loops
        gradient = (transposed @ rr[:, :, None])[:, :, 0]
        normal = transposed @ Jr
        free = np.ones_like(xr, dtype=bool)
        if active_set:
            # A variable at a bound that the descent direction pushes out stays there.
            free = ~(((xr <= low) & (gradient > 0.0)) | ((xr >= high) & (gradient < 0.0)))
        if fixed is not None:
            free &= ~fixed
        both = free[:, :, None] & free[:, None, :]
        diagonal = np.diagonal(normal, axis1=1, axis2=2) * free
        diagonal = np.maximum(diagonal, 1e-12)  # a variable the residuals ignore: a step of 0
        # Held variables: an identity row and a zero right-hand side, so their step is 0.
        system = np.where(both, normal, 0.0) + identity * np.where(free, lam[rows, None] * diagonal, 1.0)[:, None, :]
        step = -damped_step(system, (gradient * free)[..., None])[..., 0]
        step = np.where(np.isfinite(step), step, 0.0)
        candidate = np.clip(xr + step, low, high)
        r_candidate = residuals_of(candidate)
        cost_candidate = np.sum(r_candidate * r_candidate, axis=1)
        better = np.isfinite(cost_candidate) & (cost_candidate < cost[rows])
        converged = better & (cost[rows] - cost_candidate <= tolerance * cost[rows])
        moved = rows[better]
        x[moved], r[moved], cost[moved] = candidate[better], r_candidate[better], cost_candidate[better]
        stale[moved] = True
        lam[rows] = np.where(better, np.maximum(lam[rows] / 3.0, 1e-12), lam[rows] * 4.0)
        accepted[rows] += better
        tried[rows] += 1
        rejected[rows] = np.where(better, 0, rejected[rows] + 1)
        running[rows] = ~(
            (cost[rows] < CLOSED * 1e-6)
            | (accepted[rows] >= iterations)
            | (tried[rows] >= tries)
            | (rejected[rows] >= MAX_DAMPING_TRIES)
            | converged
        )
    return x, cost
