"""A solution on the bound of an X is named (finding ``x_at_bound``, exit 0): the most robust
configuration may lie beyond the range the problem allows, and the user decides whether the bound
is the cell's real limit."""

from __future__ import annotations

import json

from conftest import ONE_LINK_GRAPH, REPO, run_bcad


def _solve(write_problem, bounds: str):
    problem = write_problem(ONE_LINK_GRAPH.replace("bounds: {tx: [-10, 10]}", f"bounds: {{tx: {bounds}}}"))
    run = run_bcad("solve", problem, "--samples", "5e3", "--quiet")
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout)


def test_a_solution_held_by_its_bound_is_named(write_problem):
    """X + L scored at 3: the optimum is X* = 3 (conftest's closed form); bounds [-10, 2] hold it at 2."""
    document = _solve(write_problem, "[-10, 2]")
    assert abs(document["solution"]["unknown.tx"] - 2.0) < 1e-6
    codes = [finding["code"] for finding in document["findings"]]
    assert codes == ["x_at_bound"] and "unknown.tx is at its upper bound (2)" in document["findings"][0]["message"]


def test_a_goal_missed_because_of_a_bound_names_the_bound(write_problem):
    """Bounds [-10, 0] hold X 3 short of its goal (spread 0.5): the miss is named, and the bound
    first among what pulls X away from it."""
    document = _solve(write_problem, "[-10, 0]")
    findings = {finding["code"]: finding["message"] for finding in document["findings"]}
    assert "unknown.tx is at its upper bound (0)" in findings["x_at_bound"]
    assert "a bound that holds X (x_at_bound) or a prior on X may pull X away" in findings["goal_missed"]


def test_an_interior_solution_is_not_named(write_problem):
    document = _solve(write_problem, "[-10, 10]")
    assert 2.5 < document["solution"]["unknown.tx"] < 3.0  # the prior N(1, 2) on X pulls it below 3
    assert "x_at_bound" not in [finding["code"] for finding in document["findings"]]


#: an arm of length 1 turned by rz (bounded by +-{bound}) to reach (-1, 0): the optimum is the half turn
TURN = """
name: turn
frames: [a, m, b]
links:
  - {{name: spin, parent: a, child: m, status: FFFFFX, bounds: {{rz: [-{bound}, {bound}]}}}}
  - {{name: arm, parent: m, child: b, pose: [1, 0, 0, 0, 0, 0], status: LFFFFF, distributions: {{tx: 'normal(0, 0.01)'}}}}
  - {{name: reach, parent: a, child: b, pose: [-1, 0, 0, 0, 0, 0], close: true, status: LLFFFF,
     distributions: {{tx: 'normal(0, 0.01)', ty: 'normal(0, 0.01)'}}}}
"""


def test_a_whole_turn_is_not_a_bound(write_problem):
    """An angle whose bounds span a whole turn is periodic: its bounds are the same angle."""
    problem = write_problem(TURN.format(bound="3.141592653589793"))
    run = run_bcad("solve", problem, "--samples", "5e3", "--quiet")
    assert run.returncode == 0, run.stderr
    document = json.loads(run.stdout)
    assert abs(abs(document["solution"]["spin.rz"]) - 3.141592653589793) < 1e-3  # the optimum is the half turn
    assert "x_at_bound" not in [finding["code"] for finding in document["findings"]]


def test_bounds_just_short_of_a_whole_turn_are_named_as_such(write_problem):
    """Bounds of +-3.14159 were meant as a whole turn, but fall 5.3e-6 rad short of one: the angle
    is not periodic, the search stops at the bound, and the finding says the bounds are short of a
    turn rather than that the answer may lie beyond them (where the angle simply goes on round)."""
    from bcad.bayes.trust import bound_findings
    from bcad.compiler import compile_problem
    from bcad.model import load_problem

    text = TURN.format(bound="3.14159")
    compiled = compile_problem(load_problem(write_problem(text)))
    (finding,) = bound_findings(compiled, [3.14159])
    assert (
        "spin.rz is at its upper bound (3.14159), and its bounds fall 5.3e-06 rad short of a whole turn"
        in (finding["message"])
    )
    assert "widen them" not in finding["message"]
    # 0.36 deg short of a turn is a bound as written; a whole turn is no bound at all
    assert (
        "widen them"
        in bound_findings(compile_problem(load_problem(write_problem(text.replace("3.14159", "3.13")))), [3.13])[0][
            "message"
        ]
    )
    assert not bound_findings(
        compile_problem(load_problem(write_problem(text.replace("3.14159", "3.141592653589793")))),
        [3.141592653589793],
    )


def test_joint_bounds_given_in_a_configuration_are_named(tmp_path):
    """Bounds a configuration gives one joint are the problem's, as the robot's joints: settings' are."""
    import numpy as np

    from bcad.bayes.trust import bound_findings
    from bcad.compiler import compile_problem
    from bcad.model import load_problem

    source = REPO / "problems" / "studies" / "ur5_workcell_design.yaml"
    text = source.read_text(encoding="utf-8").replace("../../robots/ur5.urdf", str(REPO / "robots" / "ur5.urdf"))
    old = "{name: c1, joints: {ur5: {}}"
    assert old in text
    text = text.replace(old, "{name: c1, joints: {ur5: {shoulder_lift_joint: {bounds: [-2.0, 0.5]}}}", 1)
    path = tmp_path / "cell.yaml"
    path.write_text(text, encoding="utf-8")
    compiled = compile_problem(load_problem(path))
    column = compiled.parameters.x_names.index("ur5/shoulder_lift_joint@c1.ry")
    x = np.array(compiled.parameters.x_nominal, dtype=float)
    x[column] = compiled.parameters.x_bounds[column][1]
    names = [finding["message"].split(" is at")[0] for finding in bound_findings(compiled, x)]
    assert "ur5/shoulder_lift_joint@c1.ry" in names


def test_a_robot_joint_at_its_own_limit_is_not_named_but_at_given_bounds_is(tmp_path):
    """A joint's URDF limits are the end of its travel, not a choice to revisit: an X there is not
    named. The same joint with bounds the problem gives is."""
    import numpy as np

    from bcad.bayes.trust import bound_findings
    from bcad.compiler import compile_problem
    from bcad.model import load_problem

    from conftest import RX90_EXAMPLE

    text = RX90_EXAMPLE.read_text(encoding="utf-8").replace(
        "../robots/rx90.urdf", str(RX90_EXAMPLE.parent.parent / "robots" / "rx90.urdf")
    )
    given = text.replace(
        """      default:
        status: X
        zero: normal(0, 0.05)
""",
        """      default:
        status: X
        zero: normal(0, 0.05)
      joint_3: {bounds: [-2.48709, 2.48709]}
""",
        1,
    )
    assert given != text
    for source, expected in ((text, []), (given, ["x_at_bound"])):
        path = tmp_path / "cell.yaml"
        path.write_text(source, encoding="utf-8")
        compiled = compile_problem(load_problem(path))
        names = compiled.parameters.x_names
        x = np.array(compiled.parameters.x_nominal, dtype=float)
        column = names.index("arm1/joint_3.rz")
        x[column] = compiled.parameters.x_bounds[column][1]  # at the upper limit
        assert [finding["code"] for finding in bound_findings(compiled, x)] == expected


def test_angle_bounds_of_many_turns_in_radians_are_named(write_problem):
    """Bounds of +-180 with the default radians (degrees meant): 57 turns, named; +-2 pi is not."""
    from bcad.bayes.trust import bound_findings
    from bcad.compiler import compile_problem
    from bcad.model import load_problem

    compiled = compile_problem(load_problem(write_problem(TURN.format(bound="180"))))
    (finding,) = [f for f in bound_findings(compiled, [0.5]) if f["code"] == "angle_in_turns"]
    assert "spin.rz's bounds [-180, 180] rad span 57.3 turns: degrees written as radians?" in finding["message"]
    two_turns = compile_problem(load_problem(write_problem(TURN.format(bound="6.283185307179586"))))
    assert not bound_findings(two_turns, [0.5])
    in_degrees = compile_problem(load_problem(write_problem("units: {angle: deg}\n" + TURN.format(bound="180"))))
    assert not bound_findings(in_degrees, [0.5])


def test_an_x_that_enters_no_cycle_is_named_unused_not_at_bound(write_problem):
    """An X on a branch of the tree that closes nothing: the objective is flat in it, so wherever the
    search leaves it (here its upper bound), it is named ``x_unused``, not ``x_at_bound``."""
    problem = write_problem(
        ONE_LINK_GRAPH.replace("frames: [a, m, b]", "frames: [a, m, b, dangling]").replace(
            "links:\n",
            "links:\n  - {name: branch, parent: a, child: dangling, status: FXFFFF, bounds: {ty: [-1, 1]}}\n",
        )
    )
    run = run_bcad("solve", problem, "--samples", "5e3", "--quiet")
    assert run.returncode == 0, run.stderr
    document = json.loads(run.stdout)
    findings = {finding["code"]: finding["message"] for finding in document["findings"]}
    assert "branch.ty enters no cycle and no relation" in findings.get("x_unused", "")
    assert not any("branch.ty" in message for code, message in findings.items() if code != "x_unused")
    assert 2.5 < document["solution"]["unknown.tx"] < 3.0  # the other X as without the branch
