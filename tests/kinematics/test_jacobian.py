"""Analytic pose derivatives in L against central differences of the chain's definition."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bcad.compiler import compile_problem
from bcad.kinematics.chain import AffineParameter, Chain, LinkTransform, Samples, Term
from bcad.kinematics.jacobian import pose_jacobian
from bcad.kinematics.se3 import matrix_to_pose, pose_to_matrix
from bcad.model import load_problem
from tests.kinematics.test_chain import _random_link, _reference

REPO = __import__("pathlib").Path(__file__).resolve().parents[2]


def _poses(links, x, l_rows):
    """The definition's poses (4x4 products, then the pose vector) for each row of L."""
    return np.array([matrix_to_pose(T) for T in _reference(links, x, l_rows)])


def _central_differences(links, x, l_values, h=1e-6):
    n = len(l_values)
    rows = np.repeat(l_values[None], 2 * n, axis=0)
    rows[:n] += h * np.eye(n)
    rows[n:] -= h * np.eye(n)
    poses = _poses(links, x, rows)
    difference = poses[:n] - poses[n:]
    difference[:, 3:] = (difference[:, 3:] + np.pi) % (2 * np.pi) - np.pi
    return (difference / (2 * h)).T  # (6, nL)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5))
def test_matches_differences_of_the_definition(seed, n_links):
    # Random links used forward and backward, each parameter constant, in X, in L (coefficient
    # ±1) or in both (coefficients 0.5 and 2), an L shared by several steps.
    rng = np.random.default_rng(seed)
    n_x, n_l = 3, 4
    links = [(_random_link(rng, n_x, n_l), bool(rng.integers(2))) for _ in range(n_links)]
    population = rng.normal(size=(3, n_x))
    l_values = rng.normal(size=n_l)
    found = pose_jacobian(Chain(links), population, l_values)
    for k, x in enumerate(population):
        pose = _poses(links, x, l_values[None])[0]
        if abs(np.cos(pose[4])) < 1e-3:
            continue  # near gimbal lock the differences themselves are ill-conditioned
        assert found is not None
        poses, jacobian = found
        np.testing.assert_allclose(poses[k], pose, atol=1e-10)
        expected = _central_differences(links, x, l_values)
        np.testing.assert_allclose(jacobian[k], expected, atol=1e-6 * max(1.0, np.abs(expected).max()))


def test_translation_and_rotation_columns_by_hand():
    # A prismatic L along x then a revolute L about z at distance 2 along y: moving the rotation
    # by d swings the end point (2 along x after the turn) about the axis.
    slide = LinkTransform((AffineParameter(0.0, (Term("l", 0),)),) + (AffineParameter(),) * 5)
    turn = LinkTransform(
        (AffineParameter(),) * 5 + (AffineParameter(0.0, (Term("l", 1),)),), tip=pose_to_matrix([2.0, 0, 0, 0, 0, 0])
    )
    poses, jacobian = pose_jacobian(Chain([(slide, True), (turn, True)]), np.zeros((1, 0)), np.array([0.5, 0.0]))
    np.testing.assert_allclose(poses[0], [2.5, 0, 0, 0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(jacobian[0, :, 0], [1, 0, 0, 0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(jacobian[0, :, 1], [0, 2, 0, 0, 0, 1], atol=1e-15)


def test_gimbal_lock_and_curvilinear_chains_are_left_to_differences():
    pitched = LinkTransform(
        (AffineParameter(),) * 4 + (AffineParameter(np.pi / 2),) + (AffineParameter(0.0, (Term("l", 0),)),)
    )
    assert pose_jacobian(Chain([(pitched, True)]), np.zeros((1, 0)), np.zeros(1)) is None
    plain = LinkTransform((AffineParameter(0.0, (Term("l", 0),)),) + (AffineParameter(),) * 5)
    assert pose_jacobian(Chain([(plain, True)], coordinates=lambda t: t), np.zeros((1, 0)), np.zeros(1)) is None


@pytest.mark.parametrize("name", ["rx90_face_on_face.yaml", "ur5_probe_face.yaml"])
def test_linearisation_of_the_examples_matches_central_differences(name):
    # The objective's linearisation (every chain, analytic where it can be) against central
    # differences of the batched chains on the L steps the linear model used before.
    from bcad.bayes.model import BayesModel

    compiled = compile_problem(load_problem(REPO / "problems" / name))
    linear = BayesModel(compiled).linear
    rng = np.random.default_rng(7)
    x = np.array(compiled.parameters.x_nominal)
    population = x + 0.05 * rng.standard_normal((20, len(x)))
    found = linear.linearise(population)
    n, h = len(linear.mean_l), linear.step
    rows = np.concatenate([linear.mean_l[None] + np.diag(h), linear.mean_l[None] - np.diag(h)])
    for k, chain in enumerate(linear.chains):
        poses = chain.evaluate_population(population, Samples(rows)).poses()
        difference = poses[:, :n] - poses[:, n:]
        difference[..., 3:] = (difference[..., 3:] + np.pi) % (2 * np.pi) - np.pi
        expected = np.swapaxes(difference / (2 * h)[None, :, None], 1, 2)
        got = found.jacobians[:, 6 * k : 6 * k + 6]
        np.testing.assert_allclose(got, expected, atol=1e-6 * np.abs(expected).max())
