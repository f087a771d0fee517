"""The ridge walk's stages (bcad.bayes.search.walk_ridges) on an objective of two plain ridges in
the unit square, so that what each maximum should do is known: the walk's own objective,
Hessians and step replaced by closed forms."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from bcad.bayes import search
from bcad.bayes.search import LocalMaximum


def two_ridges(units: np.ndarray) -> np.ndarray:
    """Two ridges along u0, rising by 0.2 over the box: at u1 = 0.3, and at u1 = 0.8 five lower."""
    units = np.atleast_2d(units)
    rise = -0.2 * (1.0 - units[:, 0])
    return np.maximum(-5000.0 * (units[:, 1] - 0.3) ** 2 + rise, -5000.0 * (units[:, 1] - 0.8) ** 2 + rise - 5.0)


@pytest.fixture
def walk(monkeypatch):
    model = SimpleNamespace(
        objective=SimpleNamespace(
            bounds=np.array([[0.0, 1.0]] * 2), periods=np.full(2, np.inf), dimension=2, canonical=lambda rows: rows
        )
    )
    monkeypatch.setattr(search, "unit_values", lambda model, to_x: two_ridges)
    monkeypatch.setattr(search, "hessian_step", lambda model: 1e-4)
    monkeypatch.setattr(
        search,
        "derivatives_at",
        lambda values, units, periodic, step: [(0.0, np.zeros(2), -np.diag([4.0, 1e4]), None, None)] * len(units),
    )

    def walked(points, values, **options):
        maxima = [LocalMaximum(np.array(p), v, k, 0) for k, (p, v) in enumerate(zip(points, values))]
        return search.walk_ridges(model, maxima, np.random.default_rng(0), steps=15, **options)

    return walked


def test_each_maximum_walks_its_own_ridge_and_the_hopeless_one_stops(walk):
    points = [(0.1, 0.3), (0.1, 0.8)]
    high, low = walk(points, [float(two_ridges(np.array(p))[0]) for p in points])
    for maximum, ridge in ((high, 0.3), (low, 0.8)):
        assert maximum.log_value == pytest.approx(float(two_ridges(maximum.x)[0]), abs=1e-12)
        assert maximum.x[1] == pytest.approx(ridge, abs=0.05)  # still on its own ridge
    assert high.log_value > -0.01  # near the top, 0.18 above where it set out
    assert high.iterations > 15  # it walked on past its first stage
    # the low ridge's top is 5 below the high one's: no pace of its brings it within reach
    assert low.iterations == 15


def test_a_maximum_without_a_value_walks_and_stops_no_other(walk):
    alone = walk([(0.1, 0.3)], [float(two_ridges(np.array([0.1, 0.3]))[0])])[0]
    beside = walk([(0.1, 0.3), (0.2, 0.3)], [float(two_ridges(np.array([0.1, 0.3]))[0]), np.nan])
    assert beside[0].iterations == alone.iterations > 15
    assert np.isfinite(beside[1].log_value) and beside[1].log_value > -0.01


def test_a_better_maximum_walked_before_stops_a_hopeless_batch(walk):
    start = [(0.1, 0.8)]
    on_its_own = walk(start, [float(two_ridges(np.array(start[0]))[0])])[0]
    beside_a_better = walk(start, [float(two_ridges(np.array(start[0]))[0])], best_known=0.0)[0]
    assert on_its_own.iterations > 15
    assert beside_a_better.iterations == 15
