"""Batched chain evaluation against plain 4x4 matrix products, and SE(3) conventions."""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bcad.kinematics.chain import AffineParameter, Chain, LinkTransform, Samples, Term
from bcad.kinematics.se3 import invert, matrix_to_pose, pose_to_matrix, rotation_about_axis


def test_rpy_convention_is_rz_ry_rx():
    rx, ry, rz = 0.3, -0.4, 1.1
    R = pose_to_matrix(np.array([0, 0, 0, rx, ry, rz]))[:3, :3]
    expected = rotation_about_axis(2, rz) @ rotation_about_axis(1, ry) @ rotation_about_axis(0, rx)
    np.testing.assert_allclose(R, expected)
    # Rz(pi/2) maps x onto y.
    np.testing.assert_allclose(rotation_about_axis(2, np.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=1e-15)


# A loaded machine (a batch beside the suite) slows generation, not the property: no time checks.
@settings(deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.floats(-3.0, 3.0), min_size=6, max_size=6))
def test_pose_round_trip(values):
    pose = np.array(values)
    pose[4] = np.clip(pose[4], -1.5, 1.5)  # away from the rpy singularity at ry = ±pi/2
    np.testing.assert_allclose(pose_to_matrix(matrix_to_pose(pose_to_matrix(pose))), pose_to_matrix(pose), atol=1e-12)


def _random_link(rng: np.random.Generator, n_x: int, n_l: int) -> LinkTransform:
    parameters = []
    for _ in range(6):
        kind = rng.integers(4)
        offset = float(rng.normal())
        if kind == 0:
            parameters.append(AffineParameter(offset))
        elif kind == 1:
            parameters.append(AffineParameter(offset, (Term("x", int(rng.integers(n_x))),)))
        elif kind == 2:
            parameters.append(
                AffineParameter(offset, (Term("l", int(rng.integers(n_l)), float(rng.choice([1.0, -1.0]))),))
            )
        else:
            parameters.append(
                AffineParameter(
                    offset, (Term("x", int(rng.integers(n_x)), 0.5), Term("l", int(rng.integers(n_l)), 2.0))
                )
            )
    return LinkTransform(tuple(parameters), pose_to_matrix(rng.normal(size=6)), pose_to_matrix(rng.normal(size=6)))


def _reference(links, x, l):
    """Sample-by-sample product of 4x4 matrices: the definition, with no folding."""
    out = []
    for n in range(l.shape[0]):
        xs = x if x.ndim == 1 else x[n]
        T = np.eye(4)
        for link, forward in links:
            q = np.array(
                [
                    p.offset + sum(t.coefficient * (xs[t.index] if t.source == "x" else l[n, t.index]) for t in p.terms)
                    for p in link.parameters
                ]
            )
            M = link.origin @ pose_to_matrix(q) @ link.tip
            T = T @ (M if forward else invert(M))
        out.append(T)
    return np.array(out)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5), st.booleans())
def test_chain_matches_matrix_products(seed, n_links, per_sample_x):
    rng = np.random.default_rng(seed)
    n_x, n_l, n = 3, 4, 5
    links = [(_random_link(rng, n_x, n_l), bool(rng.integers(2))) for _ in range(n_links)]
    x = rng.normal(size=(n, n_x)) if per_sample_x else rng.normal(size=n_x)
    l = rng.normal(size=(n, n_l))
    samples = Samples(l)
    chain = Chain(links)
    np.testing.assert_allclose(chain.evaluate(x, samples).matrices(), _reference(links, x, l), atol=1e-10)
    # Cached trig and cached L-only segments give the same answer for another X.
    if not per_sample_x:
        x2 = x + 0.3
        np.testing.assert_allclose(chain.evaluate(x2, samples).matrices(), _reference(links, x2, l), atol=1e-10)


def test_l_only_links_become_one_cached_segment():
    rng = np.random.default_rng(3)
    l_only = LinkTransform(tuple(AffineParameter(0.1, (Term("l", k),)) for k in range(6)))
    joint = LinkTransform(tuple([AffineParameter()] * 5 + [AffineParameter(0.0, (Term("x", 0),))]))
    chain = Chain([(l_only, True), (l_only, False), (joint, True), (l_only, True)])
    kinds = [type(step).__name__ for step in chain.steps]
    assert kinds.count("SegmentStep") == 2
    l = rng.normal(size=(4, 6))
    x = np.array([0.7])
    links = [(l_only, True), (l_only, False), (joint, True), (l_only, True)]
    np.testing.assert_allclose(chain.evaluate(x, Samples(l)).matrices(), _reference(links, x, l), atol=1e-12)


def test_population_mode_equals_each_individual_on_the_same_samples():
    rng = np.random.default_rng(11)
    links = [(_random_link(rng, 3, 4), bool(rng.integers(2))) for _ in range(4)]
    chain = Chain(links)
    samples = Samples(rng.normal(size=(6, 4)))
    population = rng.normal(size=(5, 3))
    together = chain.evaluate_population(population, samples).matrices()
    assert together.shape == (5, 6, 4, 4)
    for p, individual in enumerate(population):
        np.testing.assert_allclose(together[p], chain.evaluate(individual, samples).matrices(), atol=1e-12)
