"""maxerror on degenerate, extreme and malformed input: exact zeros, a bounded search
that says when it stops short, and refusals with exit 2."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

import bcad
from bcad.cli import app

from conftest import REPO

runner = CliRunner()
CHAIN = (REPO / "problems" / "clearance" / "2r.yaml").read_text()
HEAD = CHAIN.split("clearance:")[0]


def _maxerror(path, *extra):
    result = runner.invoke(app, ["maxerror", str(path), "--json", *extra])
    return result, (json.loads(result.stdout) if result.exit_code in (0, 3) else None)


@pytest.mark.parametrize(
    "clearance",
    ["clearance: {}\n", "clearance: {rot_xy: 0, rot_z: 0, trans_xy: 0, trans_z: 0}\n"],
)
def test_no_clearance_gives_exact_zeros(tmp_path, clearance):
    path = tmp_path / "chain.yaml"
    path.write_text(HEAD + clearance)
    result, document = _maxerror(path, "--model", "exact")
    assert result.exit_code == 0, result.output
    for kind in ("rotation", "translation"):
        assert document[kind]["max"] == 0.0 and document[kind]["upper_bound"] == 0.0
        # the exact model's too: no bound rounded up from 0 to 5e-324, no gap of 1 warned about
        assert document[kind]["exact"]["max"] == 0.0 and document[kind]["exact"]["bound"] == 0.0
        assert document[kind]["exact"]["gap"] == 0.0
    assert document["units"] == {"length": "m", "angle": "rad"}


def test_translation_only_clearances(tmp_path):
    path = tmp_path / "chain.yaml"
    path.write_text(HEAD + "clearance: {trans_xy: 1.0e-4, trans_z: 5.0e-5}\n")
    result, document = _maxerror(path, "--model", "exact")
    assert result.exit_code == 0, result.output
    assert document["rotation"]["upper_bound"] == 0.0 and document["rotation"]["exact"]["bound"] == 0.0
    # Two joints, each moving the tip by at most |(1e-4, 5e-5)| in the plane and across it.
    assert document["translation"]["max"] == pytest.approx(2 * (1e-4**2 + 5e-5**2) ** 0.5, rel=1e-6)


@pytest.mark.parametrize("angle", ["rad", "deg"])
def test_a_tool_on_its_joints_axis_has_no_translation_error(tmp_path, angle):
    """A tool point on the one joint's axis turns in place: its translation error is 0 (the
    certified maximum is 0, never the -5e-324 a rounded-down norm gave, and a bound of 8e-323 is
    a gap reached, not a warning and exit 3)."""
    path = tmp_path / "chain.yaml"
    clearance = 0.01 if angle == "rad" else 0.5
    path.write_text(
        f"name: axial\nunits: {{angle: {angle}}}\nchain:\n  dh:\n    - {{a: 0.0, alpha: 0.0, d: 0.3, theta: 0.3}}\n"
        f"clearance: {{rot_z: {clearance}}}\n"
    )
    result, document = _maxerror(path)
    assert result.exit_code == 0, result.output
    translation = document["translation"]
    assert translation["max"] == 0.0 and 0.0 <= translation["upper_bound"] < 1e-300
    assert translation["gap"] == 0.0 and translation["converged"] is True
    assert document["rotation"]["max"] == pytest.approx(clearance, rel=1e-12)


def test_a_tolerance_doubles_cannot_certify_is_refused(tmp_path):
    path = tmp_path / "chain.yaml"
    path.write_text(CHAIN)
    result = runner.invoke(app, ["maxerror", str(path), "--tol", "1e-12"])
    assert result.exit_code == 2 and "--tol" in result.output


def test_a_search_stopped_short_says_so(tmp_path, monkeypatch):
    import bcad.worstcase.branch_and_bound as maxerror

    monkeypatch.setattr(maxerror, "MAX_OPEN_CELLS", 8)
    path = tmp_path / "chain.yaml"
    path.write_text(CHAIN)
    result, document = _maxerror(path, "--tol", "1e-9")
    assert result.exit_code == 3
    assert [w["code"] for w in document["warnings"]] == ["gap_not_reached", "gap_not_reached"]
    assert "above --tol 1e-09" in document["warnings"][0]["message"]
    for kind in ("rotation", "translation"):
        entry = document[kind]
        assert entry["converged"] is False and entry["upper_bound"] >= entry["max"] > 0
    # the Python API names its own argument
    worst = bcad.maxerror(path, tol=1e-9)
    assert "above tol 1e-09" in worst.warnings[0]["message"]


@pytest.mark.parametrize("value", ["1.0e-300", "1.0e300", ".nan"])
def test_absurd_clearances_are_refused(tmp_path, value):
    path = tmp_path / "chain.yaml"
    path.write_text(HEAD + f"clearance: {{rot_xy: {value}}}\n")
    result = runner.invoke(app, ["maxerror", str(path)])
    assert result.exit_code == 2 and str(path) in result.stderr


@pytest.mark.parametrize(
    ("units", "value", "refused"),
    [
        ("deg", "2", False),
        ("deg", "57", False),
        ("deg", "58", True),
        ("deg", "1e+308", True),
        ("rad", "0.9", False),
        ("rad", "1.5", True),
        ("rad", "1e+308", True),  # the same message as 1.5, not another field limit
    ],
)
def test_the_rotation_clearance_limit_is_one_radian_in_the_problems_angle_unit(tmp_path, units, value, refused):
    """1 rad is 57.3 deg: 2 deg is a small clearance, 58 deg is past the limit."""
    path = tmp_path / "chain.yaml"
    path.write_text(
        f"name: c\nunits: {{angle: {units}}}\nchain:\n  dh:\n    - {{a: 0.5, alpha: 0, d: 0, theta: 0.2}}\n"
        f"clearance: [{{rot_z: {value}}}]\n"
    )
    result = runner.invoke(app, ["maxerror", str(path), "--quiet"])
    if refused:
        assert result.exit_code == 2
        assert f"{path}:6:21: clearance.0.rot_z: {value} {units} is too large a rotation clearance" in result.stderr
        assert "expected at most 1 rad (57.3 deg)" in result.stderr
    else:
        assert result.exit_code == 0, result.stderr


def test_a_clearance_problem_made_in_python_is_held_to_the_same_limit():
    import bcad
    from bcad.errors import InputError
    from bcad.model.clearance import ChainProblem

    problem = ChainProblem.model_validate(
        {"name": "c", "chain": {"dh": [{"a": 0.5, "alpha": 0, "d": 0, "theta": 0.3}]}, "clearance": {"rot_xy": 5.0}}
    )
    with pytest.raises(InputError, match="clearance.rot_xy: 5 rad is too large a rotation clearance"):
        bcad.maxerror(problem)


def test_a_clearance_list_of_another_length_than_the_chain_is_refused_in_words(tmp_path):
    path = tmp_path / "chain.yaml"
    path.write_text(HEAD + "clearance: [{rot_z: 1.0e-4}]\n")  # the 2R chain has two joints
    result = runner.invoke(app, ["maxerror", str(path)])
    assert result.exit_code == 2 and "clearance lists 1 joint but the chain has 2" in result.stderr, result.stderr


@pytest.mark.parametrize(
    ("problem", "command"),
    [("problems/rx90_face_on_face.yaml", "bcad solve"), ("problems/calibration/ur5_tracker.yaml", "bcad calibrate")],
)
def test_maxerror_on_another_kind_of_problem_names_the_command_for_it(problem, command):
    result = runner.invoke(app, ["maxerror", str(REPO / problem)])
    assert result.exit_code == 2 and f"run '{command}' or 'bcad validate' on it" in result.stderr, result.stderr


def test_too_many_dh_rows_are_refused(tmp_path):
    rows = "".join("    - {a: 0.1, alpha: 0.3, d: 0.0, theta: 0.2}\n" for _ in range(70))
    path = tmp_path / "chain.yaml"
    path.write_text(f"name: long\nchain:\n  dh:\n{rows}clearance: {{rot_xy: 1.0e-3}}\n")
    result = runner.invoke(app, ["maxerror", str(path)])
    assert result.exit_code == 2 and "20" in result.stderr


def test_a_urdf_whose_joints_form_a_cycle(tmp_path):
    (tmp_path / "loop.urdf").write_text(
        '<robot name="loop"><link name="a"/><link name="b"/>'
        '<joint name="j1" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/><limit lower="-1" upper="1"/></joint>'
        '<joint name="j2" type="revolute"><parent link="b"/><child link="a"/><axis xyz="0 0 1"/><limit lower="-1" upper="1"/></joint>'
        "</robot>"
    )
    path = tmp_path / "chain.yaml"
    path.write_text("name: loop\nchain: {urdf: loop.urdf, q: [0, 0], tip: b}\nclearance: {rot_xy: 1.0e-3}\n")
    result = runner.invoke(app, ["maxerror", str(path)])
    assert result.exit_code == 2 and "cycle" in result.stderr, result.output


def test_more_samples_than_time_and_memory_allow_are_refused_at_once():
    import time

    from conftest import REPO, run_bcad

    started = time.perf_counter()
    run = run_bcad("maxerror", REPO / "problems" / "clearance" / "7r.yaml", "--samples", "1e9")
    assert run.returncode == 2 and "at most 2,857,142" in run.stderr, run.stderr
    assert time.perf_counter() - started < 20


def test_validate_reads_a_clearance_problem_as_maxerror_does(tmp_path):
    """validate refused every clearance problem ('run bcad maxerror on it'): it validates one, its
    chain built as maxerror builds it, counts its joints and clearances, and refuses a bad one at
    its position."""
    seven = runner.invoke(app, ["validate", str(REPO / "problems" / "clearance" / "7r.yaml"), "--json"])
    assert seven.exit_code == 0 and json.loads(seven.stdout) == {"stats": {"joints": 7, "clearances": 28}}, seven.output
    table = runner.invoke(app, ["validate", str(REPO / "problems" / "clearance" / "2r.yaml")])
    assert table.exit_code == 0 and "Number of joints" in table.stdout and "│     2 │" in table.stdout, table.output
    bad = tmp_path / "bad.yaml"
    bad.write_text((REPO / "problems" / "clearance" / "2r.yaml").read_text().replace("rot_z: 5.0e-4", "rot_z: -1"))
    refused = runner.invoke(app, ["validate", str(bad)])
    line = next(i for i, text in enumerate(bad.read_text().splitlines(), 1) if "rot_z: -1" in text)
    assert refused.exit_code == 2 and refused.stderr.startswith(f"{bad}:{line}:"), refused.output


@pytest.mark.parametrize("chain", ["{}", "null", "3"])
def test_a_chain_that_is_neither_dh_nor_urdf_names_both(tmp_path, chain):
    """chain: {} said "missing key 'urdf'", as if a URDF were the only kind of chain."""
    path = tmp_path / "chain.yaml"
    path.write_text(f"name: c\nchain: {chain}\nclearance: {{rot_xy: 0.001}}\n")
    result = runner.invoke(app, ["maxerror", str(path)])
    assert result.exit_code == 2
    assert f"{path}:2:8: chain: expected a mapping with dh: [rows] or urdf: FILE" in result.stderr
