"""I_lin's second-order terms for a point scored in a sphere's curvilinear coordinates, against a
brute-force integral over the prior (numpy only, no bcad chain)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bcad.bayes.linear import LinearModel, coordinate_hessians
from bcad.compiler import compile_problem
from bcad.model import load_problem
from bcad.relations.geometry import SurfaceCoordinates, cylindrical_coordinates, spherical_coordinates

RADIUS = 5.0
LATERAL, SCORE = 0.3, 0.05  # mm: the probe's lateral errors' std, the score's

# A probe above a sphere's pole, its height X, its position uncertain laterally by more than the
# score's width. Its distance to the surface is (h - R) + |e|^2 / (2 R) to second order in the
# lateral error e: a bias of LATERAL^2 / R = 0.018 mm, a third of the score's std, and as much spread.
SPHERE = f"""
name: probe-over-sphere
units: {{length: mm, angle: rad}}
frames: [world, probe]
links:
  - name: probe_height
    parent: world
    child: probe
    pose: [0, 0, {RADIUS}, 0, 0, 0]
    status: LLXFFF
    bounds: {{tz: [{RADIUS - 1}, {RADIUS + 1}]}}
    distributions:
      tx: normal(0, {LATERAL})
      ty: normal(0, {LATERAL})
entities:
  - {{name: ball, type: sphere, frame: world, center: [0, 0, 0], radius: {RADIUS}}}
  - {{name: tip, type: point, frame: probe, at: [0, 0, 0]}}
relations:
  - name: touch
    type: point_on_sphere
    parent: ball
    child: tip
    status: FFLFFF
    distributions:
      tz: normal(0, {SCORE})
"""


def brute_force_log_integral(height: float, draws: int = 2_000_000, seed: int = 0) -> tuple[float, float]:
    """log of E over the prior of N(rho - R; 0, SCORE^2), rho the probe's distance to the centre, and
    its standard error: the integral I(X) by plain Monte Carlo."""
    rng = np.random.default_rng(seed)
    lateral = rng.normal(0.0, LATERAL, (draws, 2))
    rho = np.sqrt(np.sum(lateral**2, axis=1) + height**2)
    density = np.exp(-0.5 * ((rho - RADIUS) / SCORE) ** 2) / (SCORE * math.sqrt(2 * math.pi))
    return math.log(density.mean()), density.std() / (density.mean() * math.sqrt(draws))


@pytest.fixture
def sphere_model(write_problem):
    return LinearModel(compile_problem(load_problem(write_problem(SPHERE))))


def test_second_order_terms_follow_the_integral_where_first_order_misses_it(sphere_model):
    heights = np.array([RADIUS, RADIUS - 0.02, RADIUS - 0.05])
    values, _ = sphere_model.log_integral(heights[:, None])
    # first order: the distance is h - R alone, N(h - R; 0, SCORE^2) (the lateral errors have no slope)
    first_order = -0.5 * ((heights - RADIUS) / SCORE) ** 2 - math.log(SCORE * math.sqrt(2 * math.pi))
    exact = [brute_force_log_integral(h) for h in heights]
    assert all(se < 1e-3 for _, se in exact)
    errors = values - [value for value, _ in exact]
    assert np.max(np.abs(first_order - [value for value, _ in exact])) > 0.2  # what the terms are for
    assert np.max(np.abs(errors)) < 0.02


def test_the_maximum_moves_below_the_pole_by_the_bias(sphere_model):
    """Where the height is free, the best X puts the mean distance on the surface, h = R - LATERAL^2 / R
    to this order, 0.018 mm below the first order's maximum; the brute force's agrees within 0.004 mm."""
    heights = RADIUS + np.linspace(-0.05, 0.01, 61)
    values, _ = sphere_model.log_integral(heights[:, None])
    exact = np.array([brute_force_log_integral(h, 400_000)[0] for h in heights])
    assert abs(heights[np.argmax(values)] - heights[np.argmax(exact)]) <= 0.004
    assert abs(heights[np.argmax(values)] - (RADIUS - LATERAL**2 / RADIUS)) <= 0.002


@pytest.mark.parametrize("to_coordinates", [spherical_coordinates, cylindrical_coordinates])
def test_coordinate_hessians_match_the_closed_form_of_the_distance(to_coordinates):
    rng = np.random.default_rng(3)
    points = rng.normal(0.0, 10.0, (5, 3))
    hessians = coordinate_hessians(lambda t: to_coordinates(t, RADIUS), points)
    for point, hessian in zip(points, hessians):
        # rho = |p| (sphere) or |p_xy| (cylinder): its Hessian is (I - n n^T) / rho on its own axes
        axes = [0, 1, 2] if to_coordinates is spherical_coordinates else [0, 1]
        radial = np.zeros(3)
        radial[axes] = point[axes]
        rho = np.linalg.norm(radial)
        expected = np.zeros((3, 3))
        expected[np.ix_(axes, axes)] = (np.eye(len(axes)) - np.outer(radial[axes], radial[axes]) / rho**2) / rho
        np.testing.assert_allclose(hessian[2], expected, rtol=1e-4, atol=1e-9)


def test_coordinate_hessians_across_the_longitude_cut():
    """A point at longitude pi (its neighbours' longitudes jump to -pi): the arc length's Hessian is
    the smooth one, as at longitude 0 turned by pi about the axis."""
    coordinates = SurfaceCoordinates(spherical_coordinates, RADIUS)
    at_cut = coordinate_hessians(coordinates, np.array([[-7.0, 0.0, 2.0]]))[0]
    turned = coordinate_hessians(coordinates, np.array([[7.0, 0.0, 2.0]]))[0]
    flip = np.diag([-1.0, -1.0, 1.0])  # the turn by pi about z, applied to both sides of the Hessian
    np.testing.assert_allclose(at_cut[0], flip @ turned[0] @ flip, rtol=1e-4, atol=1e-9)


def test_coordinate_hessians_far_along_a_cylinders_axis():
    """The step follows the distance to the axis, not to the frame's origin: a point 1000 radii up a
    cylinder of radius 1 has the distance's Hessian diag(0, 1, 0) (in x, y, z at (1, 0, 1000))."""
    coordinates = SurfaceCoordinates(cylindrical_coordinates, 1.0)
    hessian = coordinate_hessians(coordinates, np.array([[1.0, 0.0, 1000.0]]))[0]
    np.testing.assert_allclose(hessian[2], np.diag([0.0, 1.0, 0.0]), atol=1e-5)
