"""point_on_cylinder (issue 19): a point on a cylinder's lateral surface, in cylindrical
coordinates, as a relation to plan with and as a measurement reading to calibrate with."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from bcad.compile.relations import cartesian_from_cylindrical, cylindrical_coordinates, point_on_cylinder

from conftest import run_bcad

RADIUS, LENGTH = 0.2, 1.0
CENTRE = (1.0, 0.6)  # the shaft's axis, vertical, through (1.0, 0.6); its base at z = -0.5

RELATION = """
relations:
  - {name: touch, type: point_on_cylinder, parent: shaft, child: tip, status: FFLFFF,
     distributions: {tz: 'normal(0, 0.001)'}}
"""


# The same arm as DH rows (measurement rows name robot joints), the shaft's axis L in x and y.
DH_ARM = """
name: calibrate-shaft
frames: [base, post]
robots:
  - name: arm
    parent: base
    dh:
      - {a: 1.0, alpha: 0, d: 0, theta: 0, limits: [-3.1, 3.1]}
      - {a: 0.8, alpha: 0, d: 0, theta: 0, limits: [-3.1, 3.1]}
    joints: {default: {status: X}}
links:
  - {name: shaft_mount, parent: base, child: post, pose: [1.0, 0.6, -0.5, 0, 0, 0], status: LLFFFF,
     distributions: {tx: 'normal(0, 0.01)', ty: 'normal(0, 0.01)'}}
entities:
  - {name: shaft, type: cylinder, frame: post, radius: 0.2, length: 1.0}
  - {name: tip, type: point, frame: arm/link_2, at: [0, 0, 0]}
"""


def _tip(q1: float, q2: float) -> np.ndarray:
    """The planar 2R's tool in closed form."""
    return np.array([math.cos(q1) + 0.8 * math.cos(q1 + q2), math.sin(q1) + 0.8 * math.sin(q1 + q2)])


def test_cylindrical_coordinates_in_closed_form():
    theta, height, out = 0.7, 0.3, 0.05
    point = np.array([(RADIUS + out) * math.cos(theta), (RADIUS + out) * math.sin(theta), height])
    np.testing.assert_allclose(cylindrical_coordinates(point, RADIUS), [RADIUS * theta, height, out], atol=1e-15)
    np.testing.assert_allclose(cartesian_from_cylindrical(cylindrical_coordinates(point, RADIUS), RADIUS), point, atol=1e-15)
    relation = point_on_cylinder(RADIUS, LENGTH)
    assert relation.constrained == ("tz",) and relation.inequality_count == 2
    # Between the end discs, and above the top one (z = 1.2 > L): the second inequality is positive.
    np.testing.assert_allclose(relation.inequalities(np.array([[0.1, 0.3, 0.0, 0, 0, 0], [0.1, 1.2, 0.0, 0, 0, 0]])),
                               [[-0.3, -0.7], [-1.2, 0.2]], atol=1e-12)


def test_the_arm_puts_its_tip_on_the_shaft(write_problem):
    """Solved (linear estimator, so the check is of X*, not of noise): the tip, by the arm's
    closed-form kinematics at X*, lies on the shaft's surface, 0.2 from its axis, to 1e-4."""
    planning = DH_ARM.replace("joints: {default: {status: X}}", "joints: {default: {status: X, dh_error: {theta: 'normal(0, 0.002)'}}}")
    path = write_problem(planning + RELATION + "solver: {estimator: linear, posterior_samples: 20000}\n")
    run = run_bcad("solve", path, "--quiet", "--seed", "0")
    assert run.returncode == 0, run.stderr
    solution = json.loads(run.stdout)["solution"]
    tip = _tip(*(value for name, value in sorted(solution.items())))
    assert float(np.linalg.norm(tip - CENTRE)) == pytest.approx(RADIUS, abs=1e-4)


def test_touches_of_a_shaft_calibrate_its_axis(write_problem, tmp_path):
    """Cylinder readings: the arm touches the shaft at 12 joint configurations (computed in closed
    form on the true axis, 3 mm off the file's nominal one); tz = 0 in each. bcad calibrate
    finds the axis's tx, ty within 3 std of the truth, and its std below 1 mm."""
    true_centre = np.array([CENTRE[0] + 0.003, CENTRE[1] - 0.002])
    rows = []
    # the elbow within 0.8 +- 0.2 of the axis: joint 1 in [-0.41, 0] or [1.08, 1.49]
    for q1 in np.concatenate([np.linspace(-0.38, -0.03, 6), np.linspace(1.11, 1.46, 6)]):
        # the elbow angle that puts the tip at distance RADIUS from the true axis (bisection)
        def gap(q2):
            return float(np.linalg.norm(_tip(q1, q2) - true_centre)) - RADIUS
        grid = np.linspace(-3.0, 3.0, 6001)
        values = np.array([gap(q2) for q2 in grid])
        crossings = np.flatnonzero(np.sign(values[:-1]) != np.sign(values[1:]))
        if not len(crossings):
            continue
        low, high = grid[crossings[0]], grid[crossings[0] + 1]
        for _ in range(60):
            middle = 0.5 * (low + high)
            low, high = (middle, high) if np.sign(gap(middle)) == np.sign(gap(low)) else (low, middle)
        rows.append({"joints": {"joint1": float(q1), "joint2": float(0.5 * (low + high))}, "values": [0.0]})
    assert len(rows) >= 8
    measurements = ("measurements:\n  - {name: touches, frame: tip, reference: shaft, parameters: tz, "
                    "noise: 'normal(0, 0.0001)', rows: " + json.dumps(rows) + "}\n")
    path = write_problem(DH_ARM + measurements.replace('"joint1"', '"arm/joint_1"').replace('"joint2"', '"arm/joint_2"'))
    run = run_bcad("calibrate", path, "--json", "--quiet")
    assert run.returncode == 0, run.stderr
    parameters = json.loads(run.stdout)["parameters"]
    for name, truth in (("shaft_mount.tx", 0.003), ("shaft_mount.ty", -0.002)):
        entry = parameters[name]
        assert abs(entry["estimate"] - truth) <= 3 * entry["std"] + 1e-6, (name, entry)
        assert entry["std"] < 1e-3
