"""Certified worst-case clearance errors (Berger et al. 2010) against independent checks."""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest
from typer.testing import CliRunner

from bcad.cli import app
from bcad.model.clearance import ChainProblem, load_chain_problem
from bcad.worstcase.branch_and_bound import BLOCKS, SCREW_SLOTS, certified_maximum, error_value
from bcad.worstcase.error_map import build_error_map
from bcad.worstcase.exact import exact_errors

from conftest import REPO, RX90_URDF

runner = CliRunner()
CLEARANCE = REPO / "problems" / "clearance"
PROBLEMS = sorted(CLEARANCE.glob("*.yaml"))


def _rr(**clearance) -> ChainProblem:
    return ChainProblem.model_validate(
        {
            "name": "rr",
            "chain": {
                "dh": [{"a": 0.5, "alpha": 0, "d": 0, "theta": 0.3}, {"a": 0.4, "alpha": 0, "d": 0, "theta": -0.8}]
            },
            "clearance": clearance,
        }
    )


def _extreme_points(error_map, problem: str, count: int, rng) -> np.ndarray:
    """Random points of the feasible set's extreme boundary: disc circles and interval ends."""
    n = error_map.joints
    screws = np.zeros((count, n, 6))
    for (_rows, column, kind), slots in zip(BLOCKS[problem], SCREW_SLOTS[problem]):
        radius = error_map.clearance[:, column]
        if kind == "disc":
            angle = rng.uniform(0, 2 * np.pi, size=(count, n))
            screws[:, :, slots[0]] = radius * np.cos(angle)
            screws[:, :, slots[1]] = radius * np.sin(angle)
        else:
            screws[:, :, slots[0]] = radius * rng.choice([-1.0, 1.0], size=(count, n))
    return screws


@pytest.mark.parametrize("path", PROBLEMS, ids=[p.stem for p in PROBLEMS])
@pytest.mark.parametrize("problem", ["rotation", "translation"])
def test_brute_force_never_exceeds_the_certified_bound(path, problem):
    error_map = build_error_map(load_chain_problem(path))
    result = certified_maximum(error_map, problem, 1e-6)
    assert result.upper_bound >= result.max > 0
    assert result.gap <= 1e-6
    points = _extreme_points(error_map, problem, 20000, np.random.default_rng(0))
    values = np.array([error_value(error_map, x, problem) for x in points[:2000]])
    # Vectorised for the rest: dp = sum over blocks of M_j[row]^T x_j[slot].
    assert values.max() <= result.upper_bound
    assert result.max >= values.max() * (1 - 1e-6)


@pytest.mark.parametrize("path", PROBLEMS, ids=[p.stem for p in PROBLEMS])
def test_argmax_is_feasible_and_attains_max(path):
    error_map = build_error_map(load_chain_problem(path))
    for problem in ("rotation", "translation"):
        result = certified_maximum(error_map, problem)
        x = result.argmax
        rot_xy, rot_z, trans_xy, trans_z = error_map.clearance.T
        assert np.all(np.hypot(x[:, 0], x[:, 1]) <= rot_xy)
        assert np.all(np.abs(x[:, 2]) <= rot_z)
        assert np.all(np.hypot(x[:, 3], x[:, 4]) <= trans_xy)
        assert np.all(np.abs(x[:, 5]) <= trans_z)
        assert error_value(error_map, x, problem) == pytest.approx(result.max, rel=1e-12)


def test_planar_rr_maxima_derived_by_hand():
    # Every R_j is a rotation about z: the xy discs add up, and so do the z intervals.
    rotation = certified_maximum(build_error_map(_rr(rot_xy=1e-3, rot_z=5e-4, trans_xy=1e-4, trans_z=5e-5)), "rotation")
    expected = np.hypot(2e-3, 1e-3)
    assert rotation.max <= expected <= rotation.upper_bound
    assert rotation.max == pytest.approx(expected, rel=1e-12)
    # Without rotational clearance the translation error is the same sum of discs and intervals.
    translation = certified_maximum(build_error_map(_rr(trans_xy=1e-4, trans_z=5e-5)), "translation")
    expected = np.hypot(2e-4, 1e-4)
    assert translation.max <= expected <= translation.upper_bound
    # With only rot_z = c, joint j turns the tip about its axis by d_j in [-c, c]: the tip
    # moves by d_1 z x (o_2 + r_2) + d_2 z x r_2 (o_2 = joint 2, r_2 = joint 2 to tip), whose
    # largest norm is c max(|o_2 + 2 r_2|, |o_2|). In joint 1's rotated frame o_2 = (0.5, 0)
    # and r_2 = 0.4 (cos -0.8, sin -0.8).
    turn = certified_maximum(build_error_map(_rr(rot_z=1e-3)), "translation")
    expected = 1e-3 * max(np.hypot(0.5 + 0.8 * np.cos(-0.8), 0.8 * np.sin(-0.8)), 0.5)
    assert turn.max <= expected * (1 + 1e-15) and expected <= turn.upper_bound
    assert turn.max == pytest.approx(expected, rel=1e-12)


def test_first_order_agrees_with_exact_model_for_tiny_clearances():
    for scale, tolerance in ((1e-7, 1e-6), (1e-2, None)):
        error_map = build_error_map(_rr(rot_xy=scale, rot_z=scale / 2, trans_xy=scale, trans_z=scale / 2))
        for problem, index in (("rotation", 0), ("translation", 1)):
            result = certified_maximum(error_map, problem)
            exact = exact_errors(error_map, result.argmax)[index]
            if tolerance is not None:
                assert exact == pytest.approx(result.max, rel=tolerance)
            elif problem == "translation":
                assert abs(exact / result.max - 1) > 1e-6  # large clearances: the models part


def test_urdf_chain_matches_pinocchio_forward_kinematics():
    q = [0.3, 0.5, 1.2, 0.1, -0.8, 0.4]
    problem = ChainProblem.model_validate(
        {"name": "rx90", "chain": {"urdf": str(RX90_URDF), "q": q}, "clearance": {"rot_xy": 1e-4}}
    )
    error_map = build_error_map(problem)
    P = np.linalg.multi_dot(list(error_map.S))
    model = pin.buildModelFromUrdf(str(RX90_URDF))
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.array(q))
    np.testing.assert_allclose(P, data.oMf[model.getFrameId("link_6")].homogeneous, atol=1e-12)
    # The certified enclosure of M is tight: well below any clearance's effect.
    assert np.max(error_map.M.hi - error_map.M.lo) < 1e-12


def test_cli_json_output_and_statistics():
    result = runner.invoke(app, ["maxerror", str(CLEARANCE / "2r.yaml"), "--json", "--samples", "2e4"])
    assert result.exit_code == 0, result.stderr
    document = json.loads(result.stdout)
    assert set(document) == {
        "kind",
        "schema_version",
        "problem",
        "bcad_version",
        "model",
        "units",
        "rotation",
        "translation",
        "statistics",
        "warnings",
    }
    assert document["warnings"] == [] and document["rotation"]["converged"] is True
    assert document["model"] == "first-order"
    for kind in ("rotation", "translation"):
        assert set(document[kind]) == {"max", "upper_bound", "argmax", "seconds", "gap", "converged", "model"}
        assert document[kind]["model"] == "first-order"  # the linearised model's figures, said so
        assert 0 <= document[kind]["gap"] <= 1e-6
        assert len(document[kind]["argmax"]) == 2 and len(document[kind]["argmax"][0]) == 6
        typical = document["statistics"][kind]
        # Uniform clearances: typically well below the worst case, never (to first order) above it.
        assert typical["median"] < 0.8 * document[kind]["max"]
        assert typical["max_sampled"] <= document[kind]["upper_bound"] * (1 + 1e-3)


def test_cli_exact_model_and_units():
    result = runner.invoke(app, ["maxerror", str(CLEARANCE / "5r.yaml"), "--json", "--model", "exact"])
    assert result.exit_code == 0, result.stderr
    document = json.loads(result.stdout)
    assert document["model"] == "exact"
    # The 5R file is in degrees and millimetres; its worst rotation is of the order of
    # the summed clearances (5 x 0.01 deg), not of radians.
    assert 0.01 < document["rotation"]["max"] < 0.1
    assert document["rotation"]["exact"]["max"] >= document["rotation"]["exact"]["at_first_order_argmax"]
    assert abs(document["rotation"]["exact"]["relative_to_first_order"]) < 1e-3


@pytest.mark.parametrize(
    "text, line, fragment",
    [
        ("name: x\nchain: {dh: []}\nclearance: {rot_xy: 1e-3}\n", 2, "at least 1"),
        (
            "name: x\nchain: {dh: [{a: 1, alpha: 0, d: 0, theta: 0}]}\nclearance: {rot_xy: -1e-3}\n",
            3,
            "greater than or equal to 0",
        ),
        (
            "name: x\nchain: {dh: [{a: 1, alpha: 0, d: 0, thetta: 0}]}\nclearance: {rot_xy: 1e-3}\n",
            2,
            "did you mean 'theta'",
        ),
        (
            "name: x\nchain: {dh: [{a: 1, alpha: 0, d: 0, theta: 0}]}\nclearance: [{rot_xy: 1e-3}, {rot_xy: 1e-3}]\n",
            3,
            "lists 2 joints",
        ),
        (f"name: x\nchain: {{urdf: {RX90_URDF}, q: [0, 0]}}\nclearance: {{rot_xy: 1e-3}}\n", 2, "6 actuated joints"),
    ],
)
def test_invalid_clearance_problems_exit_2(write_problem, text, line, fragment):
    path = write_problem(text)
    result = runner.invoke(app, ["maxerror", str(path)])
    assert result.exit_code == 2, result.output
    assert result.stderr.startswith(f"{path}:{line}:")
    assert fragment in result.stderr


MIMIC_URDF = """<robot name="t"><link name="l0"/><link name="l1"/><link name="l2"/><link name="l3"/>
  <joint name="j0" type="revolute"><parent link="l0"/><child link="l1"/><origin xyz="0.4 0 0" rpy="0 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="j1" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.4 0 0" rpy="0 0.3 0"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/>MIMIC</joint>
  <joint name="j2" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0.4 0 0" rpy="0 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
</robot>
"""


def test_a_mimic_joint_of_a_urdf_chain_follows_its_master(tmp_path):
    """j1 mimics j0 (multiplier -1, offset 0.1): q gives j0 and j2, and j1 turns by -q0 + 0.1. The
    chain's pose is Pinocchio's for the same URDF without the <mimic> at (q0, -q0 + 0.1, q2), and so
    is every figure of maxerror; three values of q (j1's own, which it ignored) are refused."""
    (tmp_path / "mimic.urdf").write_text(
        MIMIC_URDF.replace("MIMIC", '<mimic joint="j0" multiplier="-1" offset="0.1"/>')
    )
    (tmp_path / "plain.urdf").write_text(MIMIC_URDF.replace("MIMIC", ""))
    clearance = {"rot_xy": 0.001, "trans_xy": 0.001, "rot_z": 0.01}
    mimic = ChainProblem.model_validate(
        {"name": "m", "chain": {"urdf": str(tmp_path / "mimic.urdf"), "q": [0.4, 0.3]}, "clearance": clearance}
    )
    model = pin.buildModelFromUrdf(str(tmp_path / "plain.urdf"))
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.array([0.4, -0.3, 0.3]))
    P = np.linalg.multi_dot(list(build_error_map(mimic).S))
    first = np.eye(4)
    first[0, 3] = 0.4  # F_1: j0's frame before its turn (P = S_1 ... S_n starts there)
    np.testing.assert_allclose(first @ P, data.oMf[model.getFrameId("l3")].homogeneous, atol=1e-12)
    figures = []
    for urdf, q in (("mimic.urdf", "[0.4, 0.3]"), ("plain.urdf", "[0.4, -0.3, 0.3]")):
        path = tmp_path / f"{urdf}.yaml"
        path.write_text(f"name: m\nchain: {{urdf: {urdf}, q: {q}}}\nclearance: {json.dumps(clearance)}\n")
        result = runner.invoke(app, ["maxerror", str(path), "--json", "--samples", "2e4"])
        assert result.exit_code == 0, result.stderr
        document = json.loads(result.stdout)
        figures.append([document[kind]["max"] for kind in ("rotation", "translation")])
    assert figures[0] == pytest.approx(figures[1], rel=1e-12)
    path.write_text(f"name: m\nchain: {{urdf: mimic.urdf, q: [0.4, 0.1, 0.3]}}\nclearance: {json.dumps(clearance)}\n")
    result = runner.invoke(app, ["maxerror", str(path)])
    assert result.exit_code == 2
    assert "q has 3 values but the chain to 'l3' has 2 actuated joints that mimic none ('j1' follows another" in (
        result.stderr
    )
    # a master after its mimic on the chain: j0 follows j1 (q gives j1 and j2), as solve allows
    (tmp_path / "later.urdf").write_text(
        MIMIC_URDF.replace("MIMIC", "").replace(
            '<axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>\n  <joint name="j1"',
            '<axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/>'
            '<mimic joint="j1" multiplier="-1" offset="0.1"/></joint>\n  <joint name="j1"',
            1,
        )
    )
    later = ChainProblem.model_validate(
        {"name": "m", "chain": {"urdf": str(tmp_path / "later.urdf"), "q": [-0.3, 0.3]}, "clearance": clearance}
    )
    np.testing.assert_allclose(
        first @ np.linalg.multi_dot(list(build_error_map(later).S)),
        data.oMf[model.getFrameId("l3")].homogeneous,
        atol=1e-12,
    )
