"""A chain in a sphere's or a cylinder's curvilinear coordinates, linearised by the chain rule on
its Cartesian Jacobian, against central differences of the whole chain in L (the path the
linearisation takes at gimbal lock): poses, Jacobians (an uncertain radius's column included),
the position's Jacobian and the coordinates' Hessians."""

from __future__ import annotations

import numpy as np
import pytest

from bcad.bayes.linear import LinearModel, coordinate_hessians
from bcad.compiler import compile_problem
from bcad.model import load_problem
from bcad.relations.geometry import SurfaceCoordinates, cylindrical_coordinates, spherical_coordinates
from tests.conftest import REPO

# A UR5 touching a ball whose radius is not exactly known and the side of a shaft whose radius is
# not either, at two configurations; the probe's mount and the post's placement uncertain.
CELL = """
name: ur5-sphere-and-shaft
units: {length: mm, angle: rad}
frames: [table, post, probe]
robots:
  - name: ur5
    urdf: ROBOTS/ur5.urdf
    parent: table
    joints:
      default: {status: X, zero: 'normal(0, 0.0002)'}
links:
  - name: probe_mount
    parent: ur5/tool0
    child: probe
    pose: [0, 0, 150, 0, 0, 0]
    status: LLLLLF
    distributions: {tx: 'normal(0, 0.02)', ty: 'normal(0, 0.02)', tz: 'normal(0, 0.02)', rx: 'normal(0, 0.001)', ry: 'normal(0, 0.001)'}
  - name: post_placement
    parent: table
    child: post
    pose: [450, 100, 150, 0, 0, 0.3]
    status: LLLFFL
    distributions: {tx: 'normal(0, 0.05)', ty: 'normal(0, 0.05)', tz: 'normal(0, 0.05)', rz: 'normal(0, 0.002)'}
entities:
  - {name: ball, type: sphere, frame: post, center: [0, 0, 0], radius: 'normal(12.7, 0.01)'}
  - {name: shaft, type: cylinder, frame: post, pose: [0, 60, -100, 0.2, 0, 0], radius: 'normal(8, 0.02)', length: 200}
  - {name: tip, type: point, frame: probe, at: [0, 0, 0]}
configurations:
  - {name: ball, joints: {ur5: {}}, relations: [touch_ball]}
  - {name: shaft, joints: {ur5: {}}, relations: [touch_shaft]}
relations:
  - {name: touch_ball, type: point_on_sphere, parent: ball, child: tip, status: FFLFFF, distributions: {tz: 'normal(0, 0.02)'}}
  - {name: touch_shaft, type: point_on_cylinder, parent: shaft, child: tip, status: FFLFFF, distributions: {tz: 'normal(0, 0.02)'}}
"""


@pytest.fixture
def model(write_problem):
    return LinearModel(compile_problem(load_problem(write_problem(CELL.replace("ROBOTS", str(REPO / "robots"))))))


def test_the_chain_rule_matches_central_differences_of_the_chain(model):
    curvilinear = [chain for chain in model.chains if chain.coordinates is not None]
    assert len(curvilinear) == 2
    # the radius's L enters each of the two chains through its coordinates
    assert all(chain.coordinates.column is not None for chain in curvilinear)
    bounds = model.objective.bounds
    population = np.random.default_rng(3).uniform(bounds[:, 0], bounds[:, 1], (16, len(bounds)))
    for chain in curvilinear:
        exact = model._chain_linearisation(chain, population)
        differenced = model._differenced_linearisation(chain, population)
        assert len(exact) == len(differenced) == 4
        poses, jacobians, positions, hessians = exact
        assert np.allclose(poses, differenced[0], rtol=0.0, atol=1e-9)
        # central differences at a thousandth of each L's std: truncation below 1e-6 of a column
        scale = np.max(np.abs(jacobians), axis=(0, 1))
        scale[scale == 0.0] = 1.0  # an L this chain does not depend on (the other surface's radius)
        assert np.max(np.abs(jacobians - differenced[1]) / scale) < 1e-6
        assert np.max(np.abs(positions - differenced[2]) / scale) < 1e-6
        radius = chain.coordinates.column
        assert np.max(np.abs(jacobians[:, 2, radius] + 1.0)) < 1e-9  # the distance to the surface moves by -1
        assert np.allclose(hessians, differenced[3], rtol=1e-6, atol=1e-12)


@pytest.mark.parametrize("to_coordinates", [spherical_coordinates, cylindrical_coordinates])
def test_coordinate_gradients_and_radius_rates_against_differences(to_coordinates):
    coordinates = SurfaceCoordinates(to_coordinates, 7.0)
    points = np.random.default_rng(5).normal(0.0, 10.0, (3, 40))
    h = 1e-6
    differenced = np.stack(
        [(coordinates(points + h * e[:, None]) - coordinates(points - h * e[:, None])) / (2 * h) for e in np.eye(3)],
        axis=1,
    )
    assert np.max(np.abs(coordinates.gradients(points) - differenced)) < 1e-7
    rate = (to_coordinates(points, 7.0 + h) - to_coordinates(points, 7.0 - h)) / (2 * h)
    assert np.max(np.abs(coordinates.radius_rates(points) - rate)) < 1e-7


def test_hessians_of_the_distance_to_a_sphere_are_the_closed_form():
    """rho = |p|: its Hessian (I - p p^T / rho^2) / rho, against the batched second differences."""
    points = np.random.default_rng(8).normal(0.0, 10.0, (20, 3))
    hessians = coordinate_hessians(SurfaceCoordinates(spherical_coordinates, 5.0), points)
    rho = np.linalg.norm(points, axis=1)
    closed = (np.eye(3)[None] - points[:, :, None] * points[:, None, :] / rho[:, None, None] ** 2) / rho[:, None, None]
    assert np.max(np.abs(hessians[:, 2] - closed)) < 1e-6
