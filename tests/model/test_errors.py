"""Every invalid problem: exit code 2, ``FILE:LINE:COL: message``, no traceback."""

from __future__ import annotations

import re

from typer.testing import CliRunner

from bcad.cli import app

from conftest import REPO, RX90_URDF, run_bcad

runner = CliRunner()

VALID = """\
name: t
frames: [a, b]
links:
  - name: ab
    parent: a
    child: b
    pose: [1, 0, 0, 0, 0, 0]
    status: FFFFFL
    distributions:
      rz: normal(0, 0.1)
"""


def _validate(path):
    result = runner.invoke(app, ["validate", str(path)])
    assert "Traceback" not in result.output + result.stderr
    return result


def _expect(path, line, column, *fragments):
    result = _validate(path)
    assert result.exit_code == 2, result.output
    message = result.stderr.strip()
    prefix = f"{path}:{line}:{column}: " if line is not None else f"{path}: "
    assert message.startswith(prefix), message
    for fragment in fragments:
        assert fragment in message, message
    return message


def test_the_valid_base_problem_passes(write_problem):
    result = _validate(write_problem(VALID))
    assert result.exit_code == 0
    assert "Integration space dimension" in result.stdout


def test_numbers_in_exponent_form_read_as_numbers(write_problem):
    """YAML 1.1 reads 1e5 (no dot, no exponent sign) as text; bcad reads it as YAML 1.2 does,
    so a count written as on the command line is accepted, and its fraction still refused."""
    import bcad

    text = VALID.replace("pose: [1, 0, 0, 0, 0, 0]", "pose: [1e3, 0, 2.5e-1, 0, 0, 0]")
    problem = bcad.load(write_problem(text + "solver: {posterior_samples: 1e5}\n"))
    assert problem.solver.posterior_samples == 100_000
    assert list(problem.links[0].pose[:3]) == [1000.0, 0.0, 0.25]
    _expect(write_problem(VALID + "solver: {posterior_samples: 1.5e0}\n"), 11, 29, "got 1.5; expected a whole number")
    assert _validate(write_problem(VALID.replace("name: t", "name: '1e5'"))).exit_code == 0  # quoted: text
    _expect(write_problem(VALID.replace("frames: [a, b]", "frames: [a, 2e3]")), 2, 13, "quote a name", "2000.0")


def test_a_count_that_is_not_a_whole_number_says_the_range_expected(write_problem):
    """A count too large to parse, with a fraction, or not a number: the value given and the
    field's range, whatever pydantic's own wording of each."""
    for given, shown in (("1e300", "1e+300"), ("1.5", "1.5"), ("many", "'many'")):
        _expect(
            write_problem(VALID + f"solver: {{posterior_samples: {given}}}\n"),
            11,
            29,
            f"solver.posterior_samples: got {shown}; expected a whole number in [1, 1e+09]",
        )
    _expect(
        write_problem(VALID + "solver: {search_starts: 2.5}\n"),
        11,
        25,
        "got 2.5; expected a whole number in [1, 10000]",
    )


def test_the_range_of_a_count_is_found_through_optional_fields_and_lists():
    """A camera's image size is an optional list of two counts, each in [1, 100000]: the range
    is the item's own, not the list's; a location that is not a count has none."""
    from bcad.model.problem import Problem
    from bcad.model.validation import _field_range

    assert _field_range(Problem, ("cameras", 0, "image_size", 1)) == (1, 100_000)
    assert _field_range(Problem, ("solver", "finalist_samples"))[0] >= 1
    assert _field_range(Problem, ("cameras", 0, "image_size")) is None  # the list, not a count
    assert _field_range(Problem, ("name",)) is None
    assert _field_range(Problem, ("no_such_key", 0)) is None


def test_a_bound_is_written_as_the_number_it_is(write_problem):
    # pydantic spells 1e-12 out as 0.000000000001
    message = _expect(
        write_problem(VALID.replace("normal(0, 0.1)", "normal(0, -0.05)")),
        10,
        11,
        "std: Input should be greater than or equal to 1e-12 (got -0.05)",
    )
    assert "0.000000000001" not in message


def test_a_choice_not_among_the_allowed_ones_echoes_what_was_given(write_problem):
    """'units.length: Input should be 'm', 'mm' or 'cm'' did not say what the file gave."""
    _expect(
        write_problem("units: {length: inch}\n" + VALID),
        1,
        17,
        "units.length: Input should be 'm', 'mm' or 'cm' (got 'inch')",
    )


def test_yaml_syntax_error(write_problem):
    path = write_problem("name: t\nframes: [a, b\nlinks: []\n")
    _expect(path, 3, 6, "YAML syntax error")


def test_empty_file(write_problem):
    _expect(write_problem(""), 1, 1, "empty")


def test_missing_file(tmp_path):
    _expect(tmp_path / "absent.yaml", None, None, "no such file")


def test_unknown_key_suggests_the_closest(write_problem):
    _expect(write_problem(VALID.replace("status:", "stauts:")), 8, 5, "unknown key 'stauts'", "did you mean 'status'")


def test_unquoted_shorthand_in_a_flow_mapping_gets_a_hint(write_problem):
    text = VALID.replace("    distributions:\n      rz: normal(0, 0.1)\n", "    distributions: {rz: normal(0, 0.1)}\n")
    _expect(write_problem(text), 9, 25, "quote a distribution")


def test_status_letter_other_than_xlf(write_problem):
    _expect(write_problem(VALID.replace("FFFFFL", "FFFFQL")), 8, 13, "'Q'", "expected only X")


def test_status_not_six_long(write_problem):
    _expect(write_problem(VALID.replace("FFFFFL", "FFFL")), 8, 13, "4 letters", "expected 6")


def test_l_without_distribution(write_problem):
    text = VALID.split("    distributions:")[0]
    _expect(write_problem(text), 8, 13, "rz is L", "no distribution")


CLOSING_X = """\
name: t
frames: [a, b]
links:
  - {name: placed, parent: a, child: b, status: LFFFFF, distributions: {tx: 'normal(0, 1)'}}
  - {name: reach, parent: a, child: b, close: true, status: LFXFFF, distributions: {tx: 'normal(0, 1)'}}
"""


def test_a_closing_link_with_an_x_is_refused_for_that_before_its_bounds(write_problem):
    """Its missing bounds are not what is wrong: a closing link's pose is the cycle's, with no X."""
    _expect(write_problem(CLOSING_X), 5, 61, "'reach' closes a cycle (close: true)", "cannot have X parameters")
    bounded = CLOSING_X.replace("close: true,", "close: true, bounds: {tz: [-1, 1]},")
    _expect(write_problem(bounded), 5, 84, "'reach' closes a cycle", "cannot have X parameters (status LFXFFF)")


def test_distribution_on_a_fixed_parameter(write_problem):
    _expect(write_problem(VALID + "      tx: normal(0, 1)\n"), 11, 7, "tx is F", "has a distribution")


def test_non_positive_standard_deviation(write_problem):
    _expect(
        write_problem(VALID.replace("normal(0, 0.1)", "normal(0, -0.1)")), 10, 11, "std", "greater than or equal to"
    )


def test_unknown_distribution(write_problem):
    _expect(write_problem(VALID.replace("normal(0, 0.1)", "gauss(0, 0.1)")), 10, 11, "unknown distribution 'gauss'")


def test_x_without_bounds(write_problem):
    _expect(write_problem(VALID.replace("FFFFFL", "XFFFFL")), 8, 13, "tx is X", "bounds")


def test_unknown_frame(write_problem):
    _expect(write_problem(VALID.replace("child: b", "child: c")), 6, 12, "unknown frame 'c'")


def test_unknown_entity(write_problem):
    text = (
        VALID
        + """\
entities:
  - {name: fa, type: face, frame: a, size: [1, 1]}
relations:
  - {name: r, type: point_on_face, parent: fa, child: tip}
"""
    )
    _expect(write_problem(text), 14, 55, "unknown entity 'tip'")


def test_relation_with_the_wrong_entity_type(write_problem):
    text = (
        VALID
        + """\
entities:
  - {name: fa, type: face, frame: a, size: [1, 1]}
  - {name: pb, type: point, frame: b}
relations:
  - {name: r, type: face_on_face, parent: fa, child: pb}
"""
    )
    _expect(write_problem(text), 15, 54, "face_on_face needs a face as child", "'pb' is a point")


def test_missing_urdf(write_problem):
    text = VALID + "robots:\n  - {name: arm, urdf: nowhere.urdf, parent: a}\n"
    _expect(write_problem(text), 12, 23, "URDF file", "not found")


def test_unparsable_urdf(write_problem, tmp_path):
    broken = tmp_path / "broken.urdf"
    broken.write_text('<robot name="x">\n  <link name="a"/>\n  <joint name="j" type="revolute">\n')
    text = VALID + f"robots:\n  - {{name: arm, urdf: {broken}, parent: a}}\n"
    result = _validate(write_problem(text))
    assert result.exit_code == 2
    assert re.match(rf"{re.escape(str(broken))}:\d+:\d+: cannot parse the URDF", result.stderr), result.stderr


def test_urdf_joint_with_a_zero_axis(write_problem, tmp_path):
    """Oblique axes are folded into the links (tests/compiler/test_robot_models.py); a zero axis is no axis."""
    urdf = tmp_path / "zero.urdf"
    urdf.write_text(
        '<robot name="x"><link name="a"/><link name="b"/>'
        '<joint name="j" type="continuous"><parent link="a"/><child link="b"/><axis xyz="0 0 0"/></joint></robot>'
    )
    text = VALID + f"robots:\n  - {{name: arm, urdf: {urdf}, parent: a}}\n"
    result = _validate(write_problem(text))
    assert result.exit_code == 2
    assert "has a zero axis" in result.stderr and str(urdf) in result.stderr


def test_duplicate_frame_names(write_problem):
    _expect(write_problem(VALID.replace("[a, b]", "[a, b, a]")), 2, 16, "duplicate frame name 'a'")


def test_duplicate_link_names(write_problem):
    text = VALID + "  - {name: ab, parent: b, child: a}\n"
    _expect(write_problem(text), 11, 12, "duplicate link or relation name 'ab'")


def test_duplicate_yaml_key(write_problem):
    _expect(
        write_problem(VALID.replace("    child: b\n", "    child: b\n    child: a\n")), 7, 5, "duplicate key 'child'"
    )


def test_disconnected_graph(write_problem):
    _expect(write_problem(VALID.replace("[a, b]", "[a, b, c]")), 2, 16, "disconnected", "'c'")


def test_x_on_a_closing_link(write_problem):
    text = VALID + "  - {name: back, parent: b, child: a, status: XFFFFF, bounds: {tx: [0, 1]}}\n"
    _expect(write_problem(text), 11, 47, "closes a cycle", "cannot have X")


def test_unknown_robot_joint(write_problem):
    text = (
        VALID
        + f"robots:\n  - name: arm\n    urdf: {RX90_URDF}\n    parent: a\n    joints:\n      joint_9: {{status: F}}\n"
    )
    _expect(write_problem(text), 16, 7, "no joint 'joint_9'")


def test_real_entry_point_exits_2_without_traceback(write_problem):
    path = write_problem(VALID.replace("FFFFFL", "FFFFQL"))
    result = run_bcad("validate", path)
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert result.stderr.startswith(f"{path}:8:13: ")
    assert result.stdout == ""


def test_bad_command_line_exits_2():
    assert run_bcad("validate").returncode == 2


def test_each_command_names_the_other_for_the_wrong_kind_of_problem():
    clearance = REPO / "problems" / "clearance" / "2r.yaml"
    result = runner.invoke(app, ["solve", str(clearance)])
    assert result.exit_code == 2 and "run 'bcad maxerror'" in result.stderr
    bayesian = REPO / "problems" / "rx90_face_on_face.yaml"
    result = runner.invoke(app, ["maxerror", str(bayesian)])
    assert result.exit_code == 2 and "run 'bcad solve'" in result.stderr


def test_a_misspelt_robot_link_names_the_robots_links(tmp_path):
    text = (REPO / "problems" / "rx90_face_on_face.yaml").read_text()
    text = text.replace("parent: arm1/link_6", "parent: arm1/link_7").replace("../robots/rx90.urdf", str(RX90_URDF))
    path = tmp_path / "problem.yaml"
    path.write_text(text)
    result = _validate(path)
    assert result.exit_code == 2
    assert "unknown frame 'arm1/link_7'" in result.stderr and "robot 'arm1' has the links" in result.stderr
    assert "declare it under frames" not in result.stderr


FACE = VALID + "entities:\n  - {name: f, type: face, frame: a, pose: [0, 0, 0, 0, 0, 0], size: SIZE}\n"


def test_a_bad_list_item_names_its_field_once(write_problem):
    message = _expect(
        write_problem(FACE.replace("SIZE", "[-1, 2]")), 12, 70, "entities[0].size[0]: Input should be greater"
    )
    assert "size: size" not in message and "]: size:" not in message


def test_an_unquoted_distribution_in_a_flow_sequence_gets_a_hint(write_problem):
    _expect(
        write_problem(FACE.replace("SIZE", "[normal(1, 0.1), 2]")),
        12,
        69,
        "at most 2 items",
        "inside a flow sequence [...], quote a distribution",
    )


def test_a_clearance_list_names_the_joint_and_the_limit(tmp_path):
    """The list form of clearance (one mapping per joint): a value below 1e-12 is named with its
    joint's entry and the limit, not the union's other member."""
    text = (REPO / "problems" / "clearance" / "2r.yaml").read_text()
    start = text.index("clearance:")
    path = tmp_path / "list.yaml"
    path.write_text(text[:start] + "clearance:\n  - {rot_xy: 5.0e-13, rot_z: 5.0e-4}\n  - {rot_xy: 1.0e-3}\n")
    result = runner.invoke(app, ["maxerror", str(path)])
    assert result.exit_code == 2, result.output
    assert (
        f"{path}:" in result.output
        and "clearance[0]: rot_xy = 5e-13: a clearance is 0 or at least 1e-12" in result.output
    )


def test_a_long_list_past_its_bound_is_counted_not_quoted(write_problem):
    names = ", ".join(f"c{k}" for k in range(40))
    message = _expect(
        write_problem(VALID + "configurations: [" + ", ".join(f"{{name: c{k}}}" for k in range(40)) + "]\n"),
        11,
        17,
        "at most 16 items",
    )
    assert names[:30] not in message and len(message) < 400


def test_a_short_bounds_list_is_named_short_not_missing(write_problem):
    """bounds: {tx: [0]} said "missing key 'tx'" though tx was there."""
    from conftest import ONE_LINK_GRAPH

    assert "bounds: {tx: [-10, 10]}" in ONE_LINK_GRAPH
    path = write_problem(ONE_LINK_GRAPH.replace("bounds: {tx: [-10, 10]}", "bounds: {tx: [0]}", 1))
    result = CliRunner().invoke(app, ["validate", str(path)])
    assert result.exit_code == 2
    assert "links[0].bounds.tx: got 1 item; expected 2 or more ([low, high] for bounds)" in result.stderr


def test_a_name_yaml_reads_as_a_yes_or_no_says_to_quote_it(tmp_path):
    path = tmp_path / "no.yaml"
    path.write_text("name: no\nframes: [a, b]\nlinks:\n  - {name: l, parent: a, child: b, pose: [1, 0, 0, 0, 0, 0]}\n")
    result = CliRunner().invoke(app, ["validate", str(path)])
    assert result.exit_code == 2
    assert (
        f"{path}:1:7: name: got false (YAML reads an unquoted yes, no, on or off so); expected a text" in result.stderr
    )


def test_a_number_where_a_mapping_belongs_names_the_keys_not_a_class(write_problem):
    """pydantic's "a valid dictionary or instance of ConfigurationJoint" names a class of bcad's
    code: the message says what the mapping may hold instead."""
    message = _expect(
        write_problem(VALID.replace("links:\n", "solver: 3\nlinks:\n")),
        3,
        9,
        "solver: got 3; expected a mapping with keys among estimator, search_starts",
    )
    assert "instance of" not in message and "SolverSettings" not in message
    _expect(
        write_problem(VALID.replace("links:\n  - name: ab", "links:\n  - 5\n  - name: ab")),
        4,
        5,
        "links[0]: got 5; expected a mapping with keys among pose, status, distributions",
    )


def test_a_distribution_where_a_number_may_stand_says_what_is_wrong_with_it(tmp_path):
    """A camera's fx (a number or a distribution) of normal(1100, -50): the std is at fault, not
    that the text is no number."""
    source = REPO / "problems" / "calibration" / "ur5_eye_in_hand.yaml"
    text = source.read_text().replace("fx: normal(1100, 50)", "fx: normal(1100, -50)")
    path = tmp_path / "eye.yaml"
    path.write_text(text.replace("../../robots/", f"{REPO}/robots/"))
    for name in ("ur5_camera_views.csv", "ur5_camera_info.yaml"):
        if (source.parent / name).exists():
            (tmp_path / name).write_text((source.parent / name).read_text())
    message = _expect(path, 71, 11, "cameras[0].intrinsics.fx: std: Input should be greater than or equal to 1e-12")
    assert "valid number" not in message


def test_a_distribution_in_a_position_says_what_is_wrong_with_it_and_names_are_not_empty(write_problem):
    """'normal(0, .nan)' in a point's position: the argument is at fault, not that the text is no
    number; an entity named '' is refused (nothing could refer to it); an edge takes 'an'."""
    points = VALID + "entities:\n  - {name: p, type: point, frame: a, at: [0, 'normal(0, .nan)', 0]}\n"
    message = _expect(write_problem(points), 12, 46, "entities[0].at[1]: argument '.nan' of normal is not a number")
    assert "valid number" not in message
    empty = VALID + "entities:\n  - {name: '', type: point, frame: a, at: [0, 0, 0]}\n"
    _expect(write_problem(empty), 12, 12, "an empty entity name; expected a name")
    edge = VALID + (
        "entities:\n  - {name: p, type: point, frame: a, at: [0, 0, 0]}\n  - {name: q, type: point, frame: b, at: [0, 0, 0]}\n"
        "relations:\n  - {name: r, type: point_on_edge, parent: p, child: q, status: FLLFFF, distributions: "
        "{ty: 'normal(0, 1)', tz: 'normal(0, 1)'}}\n"
    )
    _expect(write_problem(edge), 15, 44, "point_on_edge needs an edge as parent; 'p' is a point")
