"""Distributions: shorthand parsing, sampling against their own densities."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import TypeAdapter, ValidationError
from scipy import integrate, stats

from bcad.model.distributions import Distribution, Normal, TruncatedNormal, Uniform, UniformDisc

adapter = TypeAdapter(Distribution)


def test_shorthand_and_mapping_forms_agree():
    assert adapter.validate_python("normal(0, 0.01)") == Normal(mean=0, std=0.01)
    assert adapter.validate_python("normal(std=0.01)") == Normal(mean=0, std=0.01)
    assert adapter.validate_python({"type": "uniform", "low": -1, "high": 2}) == Uniform(low=-1, high=2)
    assert adapter.validate_python("truncnormal(0, 1, -1, 2)") == TruncatedNormal(mean=0, std=1, low=-1, high=2)
    assert adapter.validate_python("disc(0.5)").dimension == 2


@pytest.mark.parametrize(
    "text", ["normal(0, 0)", "normal(0, -1)", "uniform(1, 1)", "gauss(0, 1)", "normal(0, 1, 2)", "disc(-1)"]
)
def test_invalid_distributions_are_rejected(text):
    with pytest.raises(ValidationError):
        adapter.validate_python(text)


@pytest.mark.parametrize(
    "distribution",
    [Normal(mean=0.3, std=0.2), Uniform(low=-1, high=0.5), TruncatedNormal(mean=0.5, std=1.0, low=-0.5, high=1.0)],
)
def test_densities_integrate_to_one_and_match_samples(distribution):
    low, high = (-5, 5) if isinstance(distribution, Normal) else distribution.support
    total, _ = integrate.quad(lambda v: math.exp(distribution.logpdf(v)), low, high, points=[0.3])
    assert total == pytest.approx(1.0, abs=1e-6)
    samples = distribution.sample(np.random.default_rng(1), 20000)

    def cdf(v):
        return integrate.quad(lambda u: math.exp(distribution.logpdf(u)), low, v)[0]

    statistic = stats.kstest(samples[:2000], np.vectorize(cdf)).statistic
    assert statistic < 0.04


def test_truncated_normal_matches_scipy():
    d = TruncatedNormal(mean=0.2, std=0.5, low=-0.1, high=0.4)
    reference = stats.truncnorm((d.low - d.mean) / d.std, (d.high - d.mean) / d.std, loc=d.mean, scale=d.std)
    grid = np.linspace(-0.05, 0.35, 9)
    np.testing.assert_allclose(d.logpdf(grid), reference.logpdf(grid), rtol=1e-12)


def test_disc_is_area_uniform():
    d = UniformDisc(radius=2.0)
    points = d.sample(np.random.default_rng(2), 40000)
    radius = np.hypot(points[:, 0], points[:, 1])
    assert radius.max() <= 2.0
    # Area-uniform: P(r < R/2) = 1/4.
    assert np.mean(radius < 1.0) == pytest.approx(0.25, abs=0.01)
    assert d.logpdf(np.array([0.0, 0.0])) == pytest.approx(-math.log(4 * math.pi))
    assert d.logpdf(np.array([2.0, 0.1])) == -np.inf


def test_scaling_converts_units():
    assert Normal(mean=1, std=2).scaled(0.5) == Normal(mean=0.5, std=1)
    assert Uniform(low=-1, high=3).scaled(-1) == Uniform(low=-3, high=1)


@pytest.mark.parametrize(
    "distributions, scale",
    [
        ("{rz: 'normal(0, 1e-12)'}", "std"),
        ("{rz: 'uniform(0, 1e-12)'}", "high"),
        ("{rz: 'truncnormal(0, 1e-12, -1e-12, 1e-12)'}", "std"),
        ("{'rx,ry': 'disc(1e-12)'}", "radius"),
    ],
)
def test_the_smallest_spread_the_schema_accepts_survives_the_change_to_radians(tmp_path, distributions, scale):
    """1e-12 deg, the floor of the file's own units, is 1.7e-14 rad: the problem compiles, its
    distribution converted, instead of failing the floor again inside (an internal error)."""
    from bcad.compiler import compile_problem
    from bcad.model import load_problem

    status = "FFFLLF" if "disc" in distributions else "FFFFFL"
    path = tmp_path / "tiny.yaml"
    path.write_text(
        "name: tiny\nunits: {length: m, angle: deg}\nframes: [w, a, b]\nlinks:\n"
        "  - {name: j, parent: w, child: a, status: FFFFFX, bounds: {rz: [-90, 90]}}\n"
        f"  - {{name: e, parent: a, child: b, status: {status}, distributions: {distributions}}}\n"
    )
    groups = compile_problem(load_problem(path)).parameters.l_groups
    assert len(groups) == 1
    assert getattr(groups[0].distribution, scale) == pytest.approx(1e-12 * math.pi / 180, rel=1e-12)
