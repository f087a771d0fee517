"""Entity dimensions that are not exactly known: a position's coordinates and a radius
as distributions, integrated by posterior and identified by calibrate with honest z-scores."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml
from test_point_on_cylinder import CENTRE, DH_ARM, RADIUS, _touches

import bcad
from bcad.compiler import compile_problem
from bcad.model import load_problem

from conftest import run_bcad

# A point q whose x is normal(0, 0.3) touches a point p: the relation's computed pose is q in p's
# frame, so its tx spreads by 0.3 (and by nothing else: every other parameter is fixed).
TWO_POINTS = """
name: uncertain-point
units: {length: mm, angle: rad}
frames: [a, b]
links:
  - {name: fixture, parent: a, child: b, pose: [10, 0, 0, 0, 0, 0]}
entities:
  - {name: p, type: point, frame: a, at: [10, 0, 0]}
  - {name: q, type: point, frame: b, at: ['normal(0, 0.3)', 0, 'uniform(-1, 1)']}
relations:
  - {name: touch, type: point_on_point, parent: p, child: q, status: LLLFFF,
     distributions: {tx: 'normal(0, 1)', ty: 'normal(0, 1)', tz: 'normal(0, 1)'}}
solver: {posterior_samples: 200000}
"""


def test_an_uncertain_coordinate_is_an_l_parameter_named_after_the_entity(write_problem):
    compiled = compile_problem(load_problem(write_problem(TWO_POINTS)))
    assert compiled.parameters.l_names == ["q.at[0]", "q.at[2]"]
    assert "b/q.at" in compiled.graph.frames


def test_posterior_integrates_an_uncertain_position(write_problem):
    """tx's std is the coordinate's 0.3, tz's the uniform's 1/sqrt(3), both at mean 0."""
    run = run_bcad("posterior", write_problem(TWO_POINTS), "--json", "--seed", "2")
    assert run.returncode == 0, run.stderr
    link = json.loads(run.stdout)["posterior"]["links"]["touch"]
    assert link["std"][0] == pytest.approx(0.3, rel=0.01)
    assert link["std"][2] == pytest.approx(1 / math.sqrt(3), rel=0.01)
    assert link["std"][1] == pytest.approx(0.0, abs=1e-12)
    assert abs(link["mean"][0]) < 3 * link["mean_se"][0] + 1e-12


@pytest.mark.parametrize(
    "value, message",
    [
        ("'disc(0.1)'", "a coordinate takes a distribution of one number"),
    ],
)
def test_a_position_takes_a_one_number_distribution(write_problem, value, message):
    run = run_bcad("validate", write_problem(TWO_POINTS.replace("'normal(0, 0.3)'", value)))
    assert run.returncode == 2 and message in run.stderr and "Traceback" not in run.stderr


def _touch_rows(true_centre: np.ndarray, radius: float, noise: float, rng: np.random.Generator) -> list[dict]:
    rows = _touches(true_centre, radius)
    for row in rows:
        row["values"] = [float(rng.normal(0.0, noise))]  # the reading of a touch: 0, plus the sensor's noise
    return rows


def _calibrate(problem: str, rows: list[dict], reference: str, noise: float) -> dict:
    source = yaml.safe_load(problem)
    source["measurements"] = [
        {
            "name": "touches",
            "frame": "tip",
            "reference": reference,
            "parameters": "tz",
            "noise": f"normal(0, {noise})",
            "rows": rows,
        }
    ]
    return bcad.calibrate(source).document["parameters"]


NOISE = 2e-4


def test_touches_identify_a_sphere_centre_with_honest_z_scores():
    """A ball of radius 0.2 whose centre's x and y are normal(0, 0.01) about the post: the arm
    touches the true ball, 3 mm and -2 mm off, at 12 configurations (closed-form kinematics),
    each reading noisy (2e-4). Over 20 noise seeds the z-scores (estimate - truth) / std of both
    coordinates have mean within 0.6 of 0 and spread 0.6-1.5 (20 draws of a unit normal)."""
    problem = DH_ARM.replace(
        "status: LLFFFF,\n     distributions: {tx: 'normal(0, 0.01)', ty: 'normal(0, 0.01)'}", "status: FFFFFF"
    ).replace(
        "{name: shaft, type: cylinder, frame: post, radius: 0.2, length: 1.0}",
        "{name: ball, type: sphere, frame: post, radius: 0.2, center: ['normal(0, 0.01)', 'normal(0, 0.01)', 0.5]}",
    )
    assert "ball" in problem and "LLFFFF" not in problem
    truth = {"ball.center[0]": 0.003, "ball.center[1]": -0.002}
    rng = np.random.default_rng(4)
    z = {name: [] for name in truth}
    for _ in range(20):
        rows = _touch_rows(np.array(CENTRE) + [0.003, -0.002], RADIUS, NOISE, rng)
        parameters = _calibrate(problem, rows, "ball", NOISE)
        for name, value in truth.items():
            z[name].append((parameters[name]["estimate"] - value) / parameters[name]["std"])
    for name, scores in z.items():
        assert abs(np.mean(scores)) < 0.6 and 0.6 < np.std(scores) < 1.5, (name, np.mean(scores), np.std(scores))


def test_touches_identify_a_shaft_radius_with_honest_z_scores():
    """The shaft's radius normal(0.2, 0.01) and a true shaft of 0.205: over 20 noise seeds the
    z-score of the radius has mean within 0.6 of 0 and spread 0.6-1.5."""
    problem = DH_ARM.replace(
        "status: LLFFFF,\n     distributions: {tx: 'normal(0, 0.01)', ty: 'normal(0, 0.01)'}", "status: FFFFFF"
    ).replace("radius: 0.2,", "radius: 'normal(0.2, 0.01)',")
    rng = np.random.default_rng(8)
    scores = []
    for _ in range(20):
        parameters = _calibrate(problem, _touch_rows(np.array(CENTRE), 0.205, NOISE, rng), "shaft", NOISE)
        entry = parameters["shaft.radius"]
        scores.append((entry["estimate"] - 0.005) / entry["std"])
    assert abs(np.mean(scores)) < 0.6 and 0.6 < np.std(scores) < 1.5, (np.mean(scores), np.std(scores))
