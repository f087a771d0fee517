"""The batched bounded Levenberg-Marquardt against independent answers: scipy's bounded linear
least squares, Rosenbrock's known minimum, and each row solved alone."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from bcad.numerics.least_squares import CLOSED, damped_step, levenberg_marquardt


def _linear(seed: int):
    rng = np.random.default_rng(seed)
    k, n = rng.integers(4, 12), rng.integers(2, 6)
    A, b = rng.standard_normal((k, n)), rng.standard_normal(k) * 3.0
    low, high = -rng.uniform(0.1, 1.0, n), rng.uniform(0.1, 1.0, n)  # optimum often on a bound
    return A, b, low, high


@pytest.mark.parametrize("seed", range(12))
def test_a_bounded_linear_problem_matches_scipy_from_every_start(seed):
    A, b, low, high = _linear(seed)
    reference = lsq_linear(A, b, bounds=(low, high), tol=1e-14, lsmr_tol="auto").x
    starts = np.random.default_rng(100 + seed).uniform(low, high, (6, len(low)))
    x, cost = levenberg_marquardt(lambda X: X @ A.T - b, starts, low, high, iterations=500, tolerance=1e-15)
    assert np.all((x >= low) & (x <= high))
    np.testing.assert_allclose(x, np.broadcast_to(reference, x.shape), atol=1e-6)
    np.testing.assert_allclose(cost, np.sum((A @ reference - b) ** 2), rtol=1e-9)


def _rosenbrock(X):
    return np.stack([10.0 * (X[:, 1] - X[:, 0] ** 2), 1.0 - X[:, 0]], axis=1)


def test_rosenbrock_reaches_its_minimum_from_scattered_starts():
    starts = np.random.default_rng(3).uniform(-2.0, 2.0, (20, 2))
    x, cost = levenberg_marquardt(_rosenbrock, starts, np.full(2, -3.0), np.full(2, 3.0), iterations=500)
    assert np.all(cost < CLOSED)
    np.testing.assert_allclose(x, 1.0, atol=1e-4)


def test_rows_are_independent_of_each_other():
    starts = np.random.default_rng(4).uniform(-2.0, 2.0, (5, 2))
    low, high = np.full(2, -3.0), np.full(2, 3.0)
    together, _ = levenberg_marquardt(_rosenbrock, starts, low, high, iterations=7)
    alone = np.vstack([levenberg_marquardt(_rosenbrock, row[None], low, high, iterations=7)[0] for row in starts])
    np.testing.assert_allclose(together, alone, rtol=0, atol=1e-12)


def test_fixed_variables_stay_and_the_others_solve_given_them():
    A, b, low, high = _linear(1)
    fixed = np.zeros(len(low), dtype=bool)
    fixed[0] = True
    start = np.zeros((1, len(low)))
    start[0, 0] = 0.5 * high[0]
    x, _ = levenberg_marquardt(lambda X: X @ A.T - b, start, low, high, fixed=fixed, iterations=500, tolerance=1e-15)
    assert x[0, 0] == start[0, 0]
    rest = lsq_linear(A[:, 1:], b - A[:, 0] * start[0, 0], bounds=(low[1:], high[1:]), tol=1e-14).x
    np.testing.assert_allclose(x[0, 1:], rest, atol=1e-6)


def test_first_stops_every_row_once_one_is_closed():
    # one start at the minimum's doorstep, one far away: with first, the far one is left unclosed
    starts = np.array([[0.999, 0.998], [-1.9, 1.9]])
    low, high = np.full(2, -3.0), np.full(2, 3.0)
    _, cost = levenberg_marquardt(_rosenbrock, starts, low, high, iterations=500, first=True)
    assert cost[0] < CLOSED * 1e-6 and cost[1] > CLOSED
    _, cost = levenberg_marquardt(_rosenbrock, starts, low, high, iterations=500)
    assert np.all(cost < CLOSED)


def test_held_variables_are_not_differentiated_and_the_rest_as_before():
    """With some variables fixed, their Jacobian columns are not evaluated (0) and the others are
    the full forward differences' bit for bit; the bounded problem with them held matches scipy's
    on the free variables alone."""
    from bcad.numerics.least_squares import forward_differences

    rng = np.random.default_rng(3)
    A, b = rng.standard_normal((9, 5)), rng.standard_normal(9)
    calls = []

    def residuals_of(X):
        calls.append(len(X))
        return np.sin(X) @ A.T - b

    low, high = -np.ones(5), np.ones(5)
    fixed = np.array([True, False, True, False, False])
    x = rng.uniform(-0.9, 0.9, (4, 5))
    x[0, 1] = high[1]  # a step that would leave the box goes backwards
    r = residuals_of(x)
    full = forward_differences(residuals_of, 1e-7 * (high - low), high)(x, r)
    calls.clear()
    held = forward_differences(residuals_of, 1e-7 * (high - low), high, fixed)(x, r)
    assert calls == [4 * 3]  # three free columns per row
    assert np.array_equal(held[:, :, ~fixed], full[:, :, ~fixed]) and not held[:, :, fixed].any()
    start = rng.uniform(-0.5, 0.5, (3, 5))
    found, _ = levenberg_marquardt(
        lambda X: X @ A.T - b, start, low, high, iterations=500, tolerance=1e-15, fixed=fixed
    )
    for row, point in zip(start, found):
        assert np.array_equal(point[fixed], row[fixed])
        rest = lsq_linear(A[:, ~fixed], b - A[:, fixed] @ row[fixed], bounds=(low[~fixed], high[~fixed]), tol=1e-14)
        np.testing.assert_allclose(point[~fixed], rest.x, atol=1e-6)


def test_a_singular_system_takes_its_least_norm_step_and_closes():
    # one residual in two variables and no damping on the first step: J^T J = [[1, 1], [1, 1]] is
    # singular, and the least-norm Gauss-Newton step closes x0 + x1 = 1 at (0.5, 0.5) at once
    x, cost = levenberg_marquardt(
        lambda x: x[:, :1] + x[:, 1:] - 1.0,
        np.array([[0.0, 0.0], [2.0, 0.0]]),
        np.full(2, -5.0),
        np.full(2, 5.0),
        damping=0.0,
        active_set=False,
    )
    np.testing.assert_allclose(x, [[0.5, 0.5], [1.5, -0.5]], atol=1e-6)
    np.testing.assert_allclose(cost, 0.0, atol=1e-12)


def test_damped_step_matches_solve_where_regular_and_pinv_where_singular():
    rng = np.random.default_rng(3)
    regular = rng.standard_normal((4, 3, 3))
    regular = regular @ np.swapaxes(regular, 1, 2) + np.eye(3)
    rhs = rng.standard_normal((4, 3, 1))
    np.testing.assert_allclose(damped_step(regular, rhs), np.linalg.solve(regular, rhs), rtol=1e-12)
    singular = regular.copy()
    singular[2] = [[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 2.0]]
    found = damped_step(singular, rhs)
    np.testing.assert_allclose(found[[0, 1, 3]], np.linalg.solve(regular[[0, 1, 3]], rhs[[0, 1, 3]]), rtol=1e-9)
    np.testing.assert_allclose(found[2], np.linalg.lstsq(singular[2], rhs[2], rcond=None)[0], atol=1e-12)
