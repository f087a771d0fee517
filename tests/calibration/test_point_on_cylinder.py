"""point_on_cylinder: a point on a cylinder's lateral surface, in cylindrical
coordinates, as a relation to plan with and as a measurement reading to calibrate with."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from bcad.relations.geometry import cartesian_from_cylindrical, cylindrical_coordinates
from bcad.relations.point_on_cylinder import constraint as point_on_cylinder

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
    np.testing.assert_allclose(
        cartesian_from_cylindrical(cylindrical_coordinates(point, RADIUS), RADIUS), point, atol=1e-15
    )
    relation = point_on_cylinder(RADIUS, LENGTH)
    assert relation.constrained == ("tz",) and relation.inequality_count == 2
    # Between the end discs, and above the top one (z = 1.2 > L): the second inequality is positive.
    np.testing.assert_allclose(
        relation.inequalities(np.array([[0.1, 0.3, 0.0, 0, 0, 0], [0.1, 1.2, 0.0, 0, 0, 0]])),
        [[-0.3, -0.7], [-1.2, 0.2]],
        atol=1e-12,
    )


def test_the_arm_puts_its_tip_on_the_shaft(write_problem):
    """Solved (linear estimator, so the check is of X*, not of noise): the tip, by the arm's
    closed-form kinematics at X*, lies where its expected distance to the axis is the radius. A
    lateral error t moves that distance by t^2 / (2 R) (the surface is curved), so the nominal tip
    stands Var(t | the score) / (2 R) inside it, about 2.7e-4 here: by the closed form, to 1e-5."""
    planning = DH_ARM.replace(
        "joints: {default: {status: X}}", "joints: {default: {status: X, dh_error: {theta: 'normal(0, 0.002)'}}}"
    )
    path = write_problem(planning + RELATION + "solver: {estimator: linear, posterior_samples: 20000}\n")
    run = run_bcad("solve", path, "--quiet", "--seed", "0")
    assert run.returncode == 0, run.stderr
    solution = json.loads(run.stdout)["solution"]
    q1, q2 = (value for name, value in sorted(solution.items()))
    offset = _tip(q1, q2) - CENTRE
    distance = float(np.linalg.norm(offset))
    normal = offset / distance
    lateral = np.array([-normal[1], normal[0]])
    # the tip's covariance about the axis: the axis's tx, ty (0.01 each) and the joints' theta errors
    # (0.002 each) through the arm's Jacobian; the lateral variance given the score (0.001) on rho
    jacobian = np.array(
        [
            [-math.sin(q1) - 0.8 * math.sin(q1 + q2), -0.8 * math.sin(q1 + q2)],
            [math.cos(q1) + 0.8 * math.cos(q1 + q2), 0.8 * math.cos(q1 + q2)],
        ]
    )
    covariance = 0.01**2 * np.eye(2) + 0.002**2 * jacobian @ jacobian.T
    radial, across = normal @ covariance @ normal, lateral @ covariance @ normal
    lateral_variance = lateral @ covariance @ lateral - across**2 / (radial + 0.001**2)
    assert RADIUS - distance > 2e-4  # on the surface itself is the first order's answer
    assert distance == pytest.approx(RADIUS - lateral_variance / (2 * RADIUS), abs=1e-5)


def test_touches_of_a_shaft_calibrate_its_axis(write_problem, tmp_path):
    """Cylinder readings: the arm touches the shaft at 12 joint configurations (computed in closed
    form on the true axis, 3 mm off the file's nominal one); tz = 0 in each. bcad calibrate
    finds the axis's tx, ty within 3 std of the truth, and its std below 1 mm."""
    true_centre = np.array([CENTRE[0] + 0.003, CENTRE[1] - 0.002])
    rows = _touches(true_centre, RADIUS)
    assert len(rows) >= 8
    measurements = (
        "measurements:\n  - {name: touches, frame: tip, reference: shaft, parameters: tz, "
        "noise: 'normal(0, 0.0001)', rows: " + json.dumps(rows) + "}\n"
    )
    path = write_problem(DH_ARM + measurements)
    run = run_bcad("calibrate", path, "--json", "--quiet")
    assert run.returncode == 0, run.stderr
    parameters = json.loads(run.stdout)["parameters"]
    for name, truth in (("shaft_mount.tx", 0.003), ("shaft_mount.ty", -0.002)):
        entry = parameters[name]
        assert abs(entry["estimate"] - truth) <= 3 * entry["std"] + 1e-6, (name, entry)
        assert entry["std"] < 1e-3


def _touches(true_centre: np.ndarray, radius: float) -> list[dict]:
    """Joint angles of the DH arm's tip on a shaft of ``radius`` about ``true_centre``, 12 touches."""
    rows = []
    for q1 in np.concatenate([np.linspace(-0.38, -0.03, 6), np.linspace(1.11, 1.46, 6)]):

        def gap(q2):
            return float(np.linalg.norm(_tip(q1, q2) - true_centre)) - radius

        grid = np.linspace(-3.0, 3.0, 6001)
        values = np.array([gap(q2) for q2 in grid])
        crossings = np.flatnonzero(np.sign(values[:-1]) != np.sign(values[1:]))
        if not len(crossings):
            continue
        low, high = grid[crossings[0]], grid[crossings[0] + 1]
        for _ in range(60):
            middle = 0.5 * (low + high)
            low, high = (middle, high) if np.sign(gap(middle)) == np.sign(gap(low)) else (low, middle)
        rows.append({"joints": {"arm/joint_1": float(q1), "arm/joint_2": float(0.5 * (low + high))}, "values": [0.0]})
    return rows


def test_touches_calibrate_the_shaft_radius(write_problem):
    """Shape calibration: the shaft's radius given as normal(0.2, 0.01) is an L
    parameter 'shaft.radius'; touches of a shaft 5 mm thicker (0.205), on an axis known exactly,
    identify it within 3 std, std below 1e-4 (the prior's 0.01 a hundred times narrowed)."""
    rows = _touches(np.array(CENTRE), 0.205)
    assert len(rows) >= 8
    problem = DH_ARM.replace(
        "status: LLFFFF,\n     distributions: {tx: 'normal(0, 0.01)', ty: 'normal(0, 0.01)'}", "status: FFFFFF"
    ).replace("radius: 0.2,", "radius: 'normal(0.2, 0.01)',")
    assert "normal(0.2, 0.01)" in problem and "LLFFFF" not in problem
    measurements = (
        "measurements:\n  - {name: touches, frame: tip, reference: shaft, parameters: tz, "
        "noise: 'normal(0, 0.0001)', rows: " + json.dumps(rows) + "}\n"
    )
    run = run_bcad("calibrate", write_problem(problem + measurements), "--json", "--quiet")
    assert run.returncode == 0, run.stderr
    entry = json.loads(run.stdout)["parameters"]["shaft.radius"]
    # the deviation from the nominal 0.2
    assert abs(entry["estimate"] - 0.005) <= 3 * entry["std"] + 1e-7 and entry["std"] < 1e-4, entry


def test_an_uncertain_radius_where_the_geometry_needs_it_exact_is_refused(write_problem):
    problem = """
name: ball-in-socket
frames: [a, b]
links:
  - {name: free, parent: a, child: b, status: LLLFFF, distributions: {tx: 'normal(0, 0.1)', ty: 'normal(0, 0.1)', tz: 'normal(0, 0.1)'}}
entities:
  - {name: socket, type: sphere, frame: a, radius: 'normal(10, 0.1)'}
  - {name: ball, type: sphere, frame: b, radius: 9}
relations:
  - {name: seat, type: sphere_in_sphere, parent: socket, child: ball}
"""
    run = run_bcad("validate", write_problem(problem))
    assert run.returncode == 2 and "exactly known" in run.stderr and "Traceback" not in run.stderr
    near_zero = problem.replace("radius: 'normal(10, 0.1)'", "radius: 'normal(0.3, 0.1)'").split("relations:")[0]
    run = run_bcad("validate", write_problem(near_zero))
    assert run.returncode == 2 and "may reach 0" in run.stderr


def test_solve_integrates_an_uncertain_radius(write_problem):
    """At the same X, the prior-propagated std of the closing tz (rho - R) with R ~ N(0.2, 0.01^2)
    is the root sum of squares of the arm's part (the same problem with R exact) and 0.01: R is
    independent of the joint zeros."""
    planning = DH_ARM.replace(
        "joints: {default: {status: X}}", "joints: {default: {status: X, dh_error: {theta: 'normal(0, 0.002)'}}}"
    )
    planning = planning.replace(
        "status: LLFFFF,\n     distributions: {tx: 'normal(0, 0.01)', ty: 'normal(0, 0.01)'}", "status: FFFFFF"
    )
    relation = RELATION.replace("normal(0, 0.001)", "normal(0, 0.02)")
    values = ["--value", "arm/joint_1.rz=-0.2", "--value", "arm/joint_2.rz=1.4635", "--samples", "2e5", "--json"]
    stds = []
    for radius in ("0.2", "'normal(0.2, 0.01)'"):
        run = run_bcad(
            "posterior", write_problem(planning.replace("radius: 0.2,", f"radius: {radius},") + relation), *values
        )
        assert run.returncode in (0, 3), run.stderr
        stds.append(json.loads(run.stdout)["posterior"]["links"]["touch"]["std"][2])
    assert stds[1] == pytest.approx(math.hypot(stds[0], 0.01), rel=0.02), stds


def test_an_uncertain_radius_is_a_length_in_every_unit_system(write_problem):
    """In a problem in mm and degrees, 'shaft.radius' is a length: it is not scaled as an angle
    (the compile's internal units, the result's units and a calibration result's conversion)."""
    from bcad.compiler import compile_problem
    from bcad.compiler.units import parameter_scale, parameter_scales
    from bcad.model import load_problem
    from bcad.model.problem import Units
    from bcad.report import parameter_unit

    units = Units(length="mm", angle="deg")
    assert parameter_scale("radius", units) == 1.0 and parameter_scale("rz", units) == pytest.approx(math.pi / 180)
    assert parameter_unit("radius", units) == "mm"
    problem = (
        DH_ARM.replace("name: calibrate-shaft", "name: calibrate-shaft\nunits: {length: mm, angle: deg}")
        .replace("radius: 0.2,", "radius: 'normal(200, 2)',")
        .replace("limits: [-3.1, 3.1]", "limits: [-170, 170]")
    )
    compiled = compile_problem(load_problem(write_problem(problem)))
    names = compiled.parameters.l_names
    assert "shaft.radius" in names and parameter_scales(compiled, ["shaft.radius"])[0] == 1.0
    run = run_bcad("validate", write_problem(problem.replace("'normal(200, 2)'", "'disc(2)'")))
    assert run.returncode == 2 and "one number" in run.stderr
