"""The SE(3) exponential and its directional derivative (bcad.worstcase.exact) against the matrix
exponential in 300-bit ball arithmetic (python-flint), at angles from 0 to 3 rad: the clearance
errors' exponentials and the slopes the exact search and the sharp bound climb on."""

from __future__ import annotations

import numpy as np
import pytest

from bcad.worstcase.exact import (
    SERIES_THETA2,
    rodrigues_coefficients,
    twist_exponential_derivatives,
    twist_exponentials,
)

flint = pytest.importorskip("flint")


def _hat(twist: np.ndarray) -> np.ndarray:
    (wx, wy, wz), v = twist[:3], twist[3:]
    matrix = np.zeros((4, 4))
    matrix[:3, :3] = [[0.0, -wz, wy], [wz, 0.0, -wx], [-wy, wx, 0.0]]
    matrix[:3, 3] = v
    return matrix


def _exp_minus_identity_and_derivative(twist: np.ndarray, direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """exp(X) - I and d/dt exp(X + t Y) at t = 0 in 300-bit arithmetic: the blocks of
    exp([[X, Y], [0, X]]) = [[exp X, L(X, Y)], [0, exp X]] (the Fréchet derivative's block form)."""
    block = np.zeros((8, 8))
    block[:4, :4] = block[4:, 4:] = _hat(twist)
    block[:4, 4:] = _hat(direction)
    old = flint.ctx.prec
    flint.ctx.prec = 300
    try:
        exp = flint.arb_mat([[flint.arb(float(x)) for x in row] for row in block]).exp()
        minus = [[float((exp[i, j] - (1 if i == j else 0)).mid()) for j in range(4)] for i in range(4)]
        derivative = [[float(exp[i, j].mid()) for j in range(4, 8)] for i in range(4)]
    finally:
        flint.ctx.prec = old
    return np.array(minus), np.array(derivative)


def _twists(seed: int, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Twists with angles log-uniform over 1e-12 to 3 rad (and around the series' threshold),
    translations 0.1 to 100 times their angle's scale, and random directions."""
    rng = np.random.default_rng(seed)
    scales = np.exp(rng.uniform(np.log(1e-12), np.log(3.0), count))
    scales[: count // 4] = np.sqrt(SERIES_THETA2) * rng.uniform(0.5, 2.0, count // 4)
    twists = rng.normal(size=(count, 6)) * scales[:, None]
    twists[:, 3:] *= rng.uniform(0.1, 100.0, (count, 1))
    twists[0] = 0.0
    return twists, rng.normal(size=(count, 6))


@pytest.mark.parametrize("seed", [0, 1])
def test_the_exponential_and_its_derivative_agree_with_300_bit_arithmetic(seed):
    twists, directions = _twists(seed, 60)
    minus = twist_exponentials(twists, minus_identity=True)
    derivative = twist_exponential_derivatives(twists, directions)
    for k, (twist, direction) in enumerate(zip(twists, directions)):
        exact_minus, exact_derivative = _exp_minus_identity_and_derivative(twist, direction)
        # exp - I to its own size (the clearance error is this deviation: no 1 to hide behind)
        scale = max(np.abs(exact_minus).max(), 1e-300)
        assert np.abs(minus[k] - exact_minus).max() <= 1e-14 * scale, (k, np.linalg.norm(twist[:3]))
        assert np.abs(derivative[k] - exact_derivative).max() <= 1e-14 * np.abs(exact_derivative).max(), (
            k,
            np.linalg.norm(twist[:3]),
        )


def test_the_derivative_is_the_exponential_s_slope():
    """A central difference of twist_exponentials along the direction, at angles where its
    truncation and rounding are both below 1e-8 of the slope."""
    twists, directions = _twists(3, 200)
    twists = twists[np.linalg.norm(twists[:, :3], axis=1) > 1e-3]
    h = 1e-5
    central = (
        twist_exponentials(twists + h * directions[: len(twists)])
        - twist_exponentials(twists - h * directions[: len(twists)])
    ) / (2 * h)
    derivative = twist_exponential_derivatives(twists, directions[: len(twists)])
    assert np.abs(derivative - central).max() <= 1e-7 * np.abs(central).max()


def test_rodrigues_coefficients_and_their_slopes_hold_their_precision_on_both_sides_of_the_series():
    """a, b, c and their slopes in theta^2 against 300-bit arithmetic, theta^2 from 1e-16 to 8.9
    (theta below 3 rad), densely about the switch from the Taylor series to the closed forms, whose
    slopes lose 1e-16 / theta^4 of their value: within 2e-15 relative everywhere."""
    theta2 = np.concatenate(
        [
            np.geomspace(1e-16, 8.9, 40),
            SERIES_THETA2 * (1 + np.array([-1e-3, -1e-12, 0.0, 1e-12, 1e-3, 0.1])),
        ]
    )
    values = rodrigues_coefficients(theta2)
    old = flint.ctx.prec
    flint.ctx.prec = 300
    try:
        for i, s in enumerate(theta2):
            S = flint.arb(float(s))
            t = S.sqrt()
            a, b, c = t.sin() / t, (1 - t.cos()) / S, (t - t.sin()) / (S * t)
            exact = [a, b, c, (t.cos() - a) / (2 * S), (a - 2 * b) / (2 * S), (b - 3 * c) / (2 * S)]
            for k, reference in enumerate(exact):
                error = abs(float(((flint.arb(float(values[k][i])) - reference) / reference).mid()))
                assert error <= 2e-15, (["a", "b", "c", "a'", "b'", "c'"][k], s, error)
    finally:
        flint.ctx.prec = old
