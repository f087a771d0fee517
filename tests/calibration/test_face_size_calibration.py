"""Shape calibration of a face's size from probe touches on its sides: a measurement
read in a face's edge frame (``reference: FACE.edge[k]``), where a touch of the side at that
edge reads ty = 0, identifies the face's uncertain ``size``.

The touches are synthesised here from a planar 2R arm in closed form and a plate of known true
width (independent of bcad: bisection on the arm's own formula)."""

from __future__ import annotations

import json
import math

import numpy as np
from test_point_on_cylinder import _tip  # the same planar 2R (a 1.0, a 0.8), in closed form

import bcad

from conftest import run_bcad

CENTRE = (1.0, 0.6)
TRUE_WIDTH = 0.41  # nominal 0.4 +- 0.01

PLATE = """
name: plate-size
frames: [base, part]
robots:
  - name: arm
    parent: base
    dh:
      - {a: 1.0, alpha: 0, d: 0, theta: 0, limits: [-3.1, 3.1]}
      - {a: 0.8, alpha: 0, d: 0, theta: 0, limits: [-3.1, 3.1]}
    joints: {default: {status: X}}
links:
  - {name: plate_mount, parent: base, child: part, pose: [1.0, 0.6, 0, 0, 0, 0], status: FFFFFF}
entities:
  - {name: plate, type: face, frame: part, size: ['normal(0.4, 0.01)', 0.3]}
  - {name: tip, type: point, frame: arm/link_2, at: [0, 0, 0]}
"""


def _side_touches(x_side: float, rng: np.random.Generator, noise: float) -> list[dict]:
    """Joint angles putting the tip on the line x = x_side at 10 heights within the plate's y
    range (the 2R's inverse kinematics in closed form, checked by its forward formula), each
    row's reading 0 plus the sensor's noise."""
    rows = []
    for y in CENTRE[1] + np.linspace(-0.12, 0.12, 10):
        c2 = (x_side**2 + y**2 - 1.0 - 0.64) / (2 * 0.8)
        q2 = -math.acos(c2)
        q1 = math.atan2(y, x_side) - math.atan2(0.8 * math.sin(q2), 1.0 + 0.8 * math.cos(q2))
        assert np.allclose(_tip(q1, q2), [x_side, y], atol=1e-12)
        rows.append({"joints": {"arm/joint_1": q1, "arm/joint_2": q2}, "values": [float(rng.normal(0.0, noise))]})
    return rows


def _problem(seed: int, noise: float = 1e-4) -> str:
    rng = np.random.default_rng(seed)
    right = _side_touches(CENTRE[0] + TRUE_WIDTH / 2, rng, noise)
    left = _side_touches(CENTRE[0] - TRUE_WIDTH / 2, rng, noise)
    assert len(right) >= 4 and len(left) >= 4
    return (
        PLATE + "measurements:\n"
        f"  - {{name: right, frame: tip, reference: 'plate.edge[1]', parameters: ty, noise: 'normal(0, {noise})', rows: {json.dumps(right)}}}\n"
        f"  - {{name: left, frame: tip, reference: 'plate.edge[3]', parameters: ty, noise: 'normal(0, {noise})', rows: {json.dumps(left)}}}\n"
    )


def test_side_touches_identify_the_width(write_problem):
    """The width's deviation (0.01 from the nominal 0.4) within 3 std, the std far below the
    prior's 0.01; the height, never touched, stays at its number (no L)."""
    run = run_bcad("calibrate", write_problem(_problem(0)), "--json", "--quiet")
    assert run.returncode == 0, run.stderr
    entry = json.loads(run.stdout)["parameters"]["plate.size[0]"]
    assert abs(entry["estimate"] - (TRUE_WIDTH - 0.4)) <= 3 * entry["std"] and entry["std"] < 1e-4, entry
    assert entry["identified"] is True


def test_the_width_has_honest_z_scores_over_20_seeds(write_problem):
    z = []
    for seed in range(20):
        result = bcad.calibrate(str(write_problem(_problem(seed), f"p{seed}.yaml")), seed=seed)
        entry = result.document["parameters"]["plate.size[0]"]
        z.append((entry["estimate"] - (TRUE_WIDTH - 0.4)) / entry["std"])
    z = np.array(z)
    assert abs(z.mean()) < 0.7 and 0.6 < z.std(ddof=1) < 1.5, z


def test_an_edge_the_face_lacks_is_refused(write_problem):
    text = _problem(0).replace("plate.edge[3]", "plate.edge[7]")
    run = run_bcad("calibrate", write_problem(text), "--json", "--quiet")
    assert run.returncode == 2
    assert "edges 0 to 3" in run.stderr and "Traceback" not in run.stderr


def _touches_on_line(points: np.ndarray, rng: np.random.Generator, noise: float, parameters: int = 1) -> list[dict]:
    """The 2R's joint angles at each point (x, y) (closed-form inverse kinematics), reading 0 + noise."""
    rows = []
    for x, y in points:
        c2 = (x**2 + y**2 - 1.0 - 0.64) / (2 * 0.8)
        q2 = -math.acos(c2)
        q1 = math.atan2(y, x) - math.atan2(0.8 * math.sin(q2), 1.0 + 0.8 * math.cos(q2))
        assert np.allclose(_tip(q1, q2), [x, y], atol=1e-12)
        rows.append(
            {
                "joints": {"arm/joint_1": q1, "arm/joint_2": q2},
                "values": [float(v) for v in rng.normal(0.0, noise, parameters)],
            }
        )
    return rows


def test_side_touches_identify_two_uncertain_vertices(write_problem):
    """A plate given by vertices whose two right corners' x are normal(0.2, 0.01) each, truly
    0.2025 (bottom) and 0.2005 (top): 12 touches along the tilted right side (edge 1) identify
    both (the edge frame moves and turns with them, to first order), with honest z-scores over 20
    noise seeds (the corners lie beyond the touched heights: std 6.4e-5 for a 1e-4 sensor)."""
    bottom, top = 0.2025, 0.2005
    heights = np.linspace(-0.12, 0.12, 12)
    xs = bottom + (top - bottom) * (heights + 0.15) / 0.3
    points = np.column_stack([CENTRE[0] + xs, CENTRE[1] + heights])
    plate = PLATE.replace(
        "size: ['normal(0.4, 0.01)', 0.3]",
        "vertices: [[-0.2, -0.15], ['normal(0.2, 0.01)', -0.15], ['normal(0.2, 0.01)', 0.15], [-0.2, 0.15]]",
    )
    z = {"plate.vertices[1][0]": [], "plate.vertices[2][0]": []}
    for seed in range(20):
        rows = _touches_on_line(points, np.random.default_rng(seed), 1e-4)
        problem = plate + (
            "measurements:\n"
            f"  - {{name: right, frame: tip, reference: 'plate.edge[1]', parameters: ty, noise: 'normal(0, 0.0001)', rows: {json.dumps(rows)}}}\n"
        )
        parameters = bcad.calibrate(str(write_problem(problem, f"v{seed}.yaml")), seed=0).document["parameters"]
        for name, truth in (("plate.vertices[1][0]", bottom - 0.2), ("plate.vertices[2][0]", top - 0.2)):
            entry = parameters[name]
            assert entry["std"] < 1e-4 and entry["identified"] is True
            z[name].append((entry["estimate"] - truth) / entry["std"])
    for name, scores in z.items():
        scores = np.array(scores)
        assert abs(scores.mean()) < 0.7 and 0.6 < scores.std(ddof=1) < 1.5, (name, scores)


def test_end_touches_identify_a_cylinder_length(write_problem):
    """A cylinder lying along x (its base at x = 0.9), its length normal(0.3, 0.01), truly 0.306:
    touches of its end face read in CYLINDER.top (tz = 0) identify the length within 3 std."""
    rng = np.random.default_rng(9)
    points = np.column_stack([np.full(8, 0.9 + 0.306), CENTRE[1] + np.linspace(-0.04, 0.04, 8)])
    rows = _touches_on_line(points, rng, 1e-4)
    problem = PLATE.replace(
        "  - {name: plate, type: face, frame: part, size: ['normal(0.4, 0.01)', 0.3]}",
        "  - {name: roller, type: cylinder, frame: base, pose: [0.9, 0.6, 0, 0, 1.5707963267948966, 0], "
        "radius: 0.05, length: 'normal(0.3, 0.01)'}",
    )
    problem += (
        "measurements:\n"
        f"  - {{name: end, frame: tip, reference: roller.top, parameters: tz, noise: 'normal(0, 0.0001)', rows: {json.dumps(rows)}}}\n"
    )
    run = run_bcad("calibrate", write_problem(problem), "--json", "--quiet")
    assert run.returncode == 0, run.stderr
    entry = json.loads(run.stdout)["parameters"]["roller.length"]
    assert abs(entry["estimate"] - 0.006) <= 3 * entry["std"] and entry["std"] < 1e-4, entry
