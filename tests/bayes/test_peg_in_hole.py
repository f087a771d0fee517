"""The peg-in-hole example: `bcad solve` reports the insertion's success probability,
and a plain Monte Carlo of the same cell with 4e5 samples, through an independent forward
kinematics (the URDF's joints multiplied out with numpy), agrees within 3 standard errors."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yourdfpy

from bcad.bayes.estimators import search_budget
from bcad.bayes.model import BayesModel
from bcad.compiler import compile_problem
from bcad.model import load_problem
from bcad.relations.cylinder_in_cylinder import constraint as cylinder_in_cylinder

from conftest import REPO, RX90_URDF, run_bcad

EXAMPLE = REPO / "problems" / "relations" / "rx90_peg_in_hole.yaml"


def _rz(angles: np.ndarray) -> np.ndarray:
    T = np.zeros((len(angles), 4, 4))
    c, s = np.cos(angles), np.sin(angles)
    T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1] = c, -s, s, c
    T[:, 2, 2] = T[:, 3, 3] = 1.0
    return T


def plain_monte_carlo(q: np.ndarray, count: int, seed: int) -> tuple[float, float]:
    """P(insertion) with the example's uncertainties: joint zeros N(0, 5e-5 rad), the fixture's
    tx, ty N(0, 0.02 mm); the cell's geometry as the problem file states it."""
    rng = np.random.default_rng(seed)
    urdf = yourdfpy.URDF.load(str(RX90_URDF), build_scene_graph=False, load_meshes=False)
    joints = [j for j in urdf.robot.joints if j.type == "revolute"]
    successes = 0
    chunk = 200_000
    peg_in_gripper = np.eye(4)
    peg_in_gripper[:3, 3] = [0.0, 0.0, 60.0]
    peg_in_gripper[:3, :3] = np.diag([1.0, -1.0, -1.0])  # Rx(pi)
    relation = cylinder_in_cylinder(5.0, 20.0, 4.95)
    for start in range(0, count, chunk):
        n = min(chunk, count - start)
        zeros = rng.normal(0.0, 5e-5, (n, 6))
        T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        for k, joint in enumerate(joints):
            origin = joint.origin.copy()
            origin[:3, 3] *= 1000.0  # mm
            T = T @ origin @ _rz(q[k] + zeros[:, k])
        gripper = T.copy()
        gripper[:, :3, 3] += 90.0 * T[:, :3, 2]
        peg = gripper @ peg_in_gripper
        hole = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        hole[:, :3, 3] = np.column_stack([550.0 + rng.normal(0, 0.02, n), rng.normal(0, 0.02, n), np.full(n, 100.0)])
        Q = np.linalg.inv(hole) @ peg
        columns = np.transpose(Q[:, :3, :3], (2, 1, 0))
        distances = relation.inequalities_from(columns, Q[:, :3, 3].T)
        successes += int(np.sum(np.all(distances <= 0.0, axis=0)))
    p = successes / count
    return p, math.sqrt(p * (1 - p) / count)


def test_the_success_probability_agrees_with_a_plain_monte_carlo(tmp_path):
    run = run_bcad("solve", EXAMPLE, "-o", tmp_path / "result.json", "--quiet")
    assert run.returncode == 0, run.stderr
    result = json.loads((tmp_path / "result.json").read_text())
    # Its maxima lie on ridges, where every climb stops at a place of its own: walked to the
    # ridges' tops, two of the first climbs reach the best top within 0.02 (replicated), and the
    # search stops there, without the further rounds (three times the climbs)
    model = BayesModel(compile_problem(load_problem(EXAMPLE)))
    starts, climbs = search_budget(model.compiled.problem.solver, len(model.objective.bounds), len(model.linear.mean_l))
    search = result["diagnostics"]["search"]
    # (the screened starts and the nominal solution)
    assert search["verdict"]["reached_best"] >= 2 and (search["starts"], search["climbs"]) == (starts + 1, climbs)
    solution = result["solution"]
    q = np.array([solution[f"arm/joint_{k}.rz"] for k in range(1, 6)] + [0.0])
    run = run_bcad("posterior", EXAMPLE, "--at", tmp_path / "result.json", "--samples", "1e6", "--json")
    assert run.returncode == 0, run.stderr
    insertion = json.loads(run.stdout)["posterior"]["links"]["insertion"]
    satisfied, bcad_se = insertion["satisfied"], insertion["satisfied_se"]
    assert bcad_se == pytest.approx(math.sqrt(satisfied * (1 - satisfied) / 1e6), rel=1e-9)  # a binomial share's
    p, se = plain_monte_carlo(q, 400_000, seed=7)
    assert 0.2 < p < 0.95  # an insertion that may fail: the example is not trivial
    assert abs(satisfied - p) < 3 * math.hypot(se, bcad_se), (satisfied, p, se)


def test_the_readme_shows_the_example_commands():
    from conftest import documentation

    readme = documentation()
    assert "bcad solve problems/relations/rx90_peg_in_hole.yaml -o peg.json" in readme
    assert "bcad posterior problems/relations/rx90_peg_in_hole.yaml --at peg.json --samples 1e6 --json" in readme
