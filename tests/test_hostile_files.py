"""Hostile and broken files: exit 2 with the best location, quickly, within bounded
memory, never a traceback: alias bombs, recursion, endless or special files, bad bytes,
bad tags, bad result files and command-line values."""

from __future__ import annotations

import json
import re

import pytest
from typer.testing import CliRunner

from bcad.cli import app

from conftest import ONE_LINK_GRAPH, REPO

runner = CliRunner()


def _alias_bomb() -> str:
    text, previous = "a: &a [x, x, x, x, x, x, x, x, x]\n", "a"
    for name in "bcdefghi":
        text += f"{name}: &{name} [" + ", ".join([f"*{previous}"] * 9) + "]\n"
        previous = name
    return text + "name: x\nframes: *i\n"


FILES = {
    "alias bomb": (_alias_bomb(), r":\d+:\d+: the aliases here expand to more than"),
    "recursive alias": ("name: x\nframes: &a [w, *a]\n", r":2:9: a recursive alias"),
    "5000 levels of nesting": (
        "name: x\nframes: " + "[" * 5000 + "]" * 5000 + "\n",
        r":2:\d+: (YAML syntax error: exceeded maximum nesting depth|nested more than 100 levels)|: nested too deeply",
    ),
    "500 levels of nesting": (
        "name: x\nframes: " + "[" * 500 + "]" * 500 + "\n",
        r":2:108: nested more than 100 levels",
    ),
    "a control character": ('name: "x\x07"\nframes: [a]\n', r":1:9: YAML error: the control character U\+0007"),
    # written as escapes, which YAML allows: a terminal would act on them where the name is printed
    "an escape sequence written as one": (
        'name: "planar\\x1b[31m"\nframes: [a]\n',
        r":1:7: the text holds the character U\+001B, which a terminal acts on rather than shows; expected",
    ),
    "a right-to-left override in a key": (
        'name: x\nframes: [a]\n"k\\u202e": 1\n',
        r":3:1: the text holds the character U\+202E",
    ),
    "a carriage return in a frame name": (
        'name: x\nframes: [a, "b\\rc"]\n',
        r":2:13: the text holds the character U\+000D",
    ),
    "a 5000-digit integer": (
        "name: x\nframes: [a]\nsolver: {population: " + "9" * 5000 + "}\n",
        r":3:22: cannot read the value",
    ),
    "!!float abc": ("name: x\nframes: [a]\ndescription: !!float abc\n", r":3:14: cannot read the value 'abc' as float"),
    "!!int 0x": ("name: x\nframes: [a]\ndescription: !!int 0x\n", r":3:14: cannot read the value '0x' as int"),
    "!!bool maybe": (
        "name: x\nframes: [a]\ndescription: !!bool maybe\n",
        r":3:14: cannot read the value 'maybe' as bool",
    ),
    "an edge reference unquoted in a flow mapping": (
        "name: x\nframes: [a]\nmeasurements:\n  - {name: m, frame: a, reference: plate.edge[0], parameters: ty}\n",
        r":4:46: YAML syntax error: .*expected ',' or '\}'.*must be quoted: reference: 'plate.edge\[0\]'",
    ),
    "an unclosed flow mapping": (
        "name: x\nframes: [a, b]\nlinks:\n  - {name: ab, parent: a, child: b\n",
        r":5:1: YAML syntax error: .*expected ',' or '\}' \(while parsing a flow mapping opened at line 4, column 5\)",
    ),
    "!!timestamp abc": (
        "name: x\nframes: [a]\ndescription: !!timestamp abc\n",
        r":3:14: cannot read the value 'abc' as timestamp",
    ),
}


@pytest.mark.parametrize("case", FILES)
def test_hostile_yaml(tmp_path, case):
    text, expected = FILES[case]
    path = tmp_path / "problem.yaml"
    path.write_text(text, encoding="utf-8")
    result = runner.invoke(app, ["validate", str(path)])
    assert result.exit_code == 2, result.output
    assert re.search(re.escape(str(path)) + expected, result.stderr), result.stderr


def test_non_utf8_bytes_are_located(tmp_path):
    path = tmp_path / "latin.yaml"
    path.write_bytes(b"name: x\nframes: [a\xe9]\n")
    result = runner.invoke(app, ["validate", str(path)])
    assert result.exit_code == 2 and f"{path}:2:11: not UTF-8" in result.stderr


@pytest.mark.parametrize("special", ["/dev/zero", "/dev/null"])
def test_endless_or_special_files_are_refused(special):
    result = runner.invoke(app, ["validate", special])
    assert result.exit_code == 2 and "not a regular file" in result.stderr


def test_too_large_files_are_refused(tmp_path, monkeypatch):
    import bcad.model.source as source

    monkeypatch.setattr(source, "MAX_BYTES", 100)
    path = tmp_path / "big.yaml"
    path.write_text(ONE_LINK_GRAPH)
    result = runner.invoke(app, ["validate", str(path)])
    assert result.exit_code == 2 and "limited to 100 bytes" in result.stderr


def test_a_device_as_urdf_is_refused(tmp_path):
    path = tmp_path / "robot.yaml"
    path.write_text("name: r\nframes: [w]\nrobots:\n  - {name: arm, urdf: /dev/zero, parent: w}\n")
    result = runner.invoke(app, ["validate", str(path)])
    assert result.exit_code == 2 and f"{path}:4:23: '/dev/zero' is not a regular file" in result.stderr


LONG_NAME = "x" * 300  # beyond the file system's 255 characters: stat fails with ENAMETOOLONG


@pytest.mark.parametrize(
    "text, position, expected",
    [
        (
            f"name: r\nframes: [w]\nrobots:\n  - {{name: arm, urdf: {LONG_NAME}, parent: w}}\n",
            "4:23",
            "cannot be read (File name too long); expected a URDF file",
        ),
        ("name: r\nframes: [w]\nrobots:\n  - {name: arm, urdf: ., parent: w}\n", "4:23", "is a folder"),
        (
            f"name: c\nchain: {{urdf: {LONG_NAME}, q: [0]}}\nclearance: {{rot_xy: 1.0e-4}}\n",
            "2:15",
            "cannot be read (File name too long); expected a URDF file",
        ),
        (
            f"name: r\nframes: [w, v]\nlinks:\n  - {{name: l, parent: w, child: v}}\ncalibration: [{LONG_NAME}]\n",
            "5:15",
            "cannot be read (File name too long); expected a bcad calibrate result",
        ),
    ],
    ids=["urdf-name-too-long", "urdf-a-folder", "maxerror-urdf-name-too-long", "calibration-name-too-long"],
)
def test_a_path_the_file_system_refuses_is_bad_input_at_its_key(tmp_path, text, position, expected):
    """A URDF or calibration path whose name is too long, or that is a folder: exit 2 at the key
    that gives it, its name shortened, never an internal error."""
    path = tmp_path / "problem.yaml"
    path.write_text(text)
    command = "maxerror" if "chain:" in text else "validate"
    result = runner.invoke(app, [command, str(path)])
    assert result.exit_code == 2, result.stderr
    assert f"{path}:{position}: '" in result.stderr and expected in result.stderr, result.stderr
    assert len(result.stderr) < 500  # the 300-character name is not printed whole


@pytest.mark.parametrize(
    "content, expected",
    [
        ("[" * 100000 + "]" * 100000, "nested too deeply"),
        ('{"solution": {"unknown.tx": null}}', "expected a finite number"),
        ('{"solution": {"unknown.tx": "abc"}}', "expected a finite number"),
        ('{"solution": [1, 2]}', "not a mapping"),
        ("not json", "not valid JSON"),
    ],
)
def test_bad_result_files_for_posterior(write_problem, tmp_path, content, expected):
    problem = write_problem(ONE_LINK_GRAPH)
    at = tmp_path / "result.json"
    at.write_text(content)
    result = runner.invoke(app, ["posterior", str(problem), "--at", str(at)])
    assert result.exit_code == 2 and expected in result.stderr, result.output


@pytest.mark.parametrize(
    "arguments",
    [
        ["solve", "{problem}", "--seed", "-1"],
        ["solve", "{problem}", "--samples", "inf"],
        ["posterior", "{problem}", "--value", "unknown.tx=nan"],
        ["posterior", "{problem}", "--at", "{folder}"],
    ],
)
def test_bad_command_line_values(write_problem, tmp_path, arguments):
    problem = write_problem(ONE_LINK_GRAPH)
    args = [a.format(problem=problem, folder=tmp_path) for a in arguments]
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output


def test_strict_json_and_finite_solutions(write_problem):
    result = runner.invoke(
        app,
        ["posterior", str(write_problem(ONE_LINK_GRAPH)), "--value", "unknown.tx=2.8", "--json", "--samples", "2e4"],
    )
    assert result.exit_code == 0
    json.loads(result.stdout, parse_constant=lambda name: pytest.fail(f"non-strict JSON constant {name}"))


def test_user_text_is_printed_literally(write_problem):
    # Rich markup, emoji codes and a line 100 (":100:" is the emoji code of a symbol).
    name = "[/] [bold]x :100: :1234:"
    path = write_problem(
        f'name: "{name}"\nframes: [a, b]\nlinks:\n'
        '  - {name: "[red]ab", parent: a, child: b, status: FFFFFL, distributions: {rz: "normal(0, 0.1)"}}\n'
        + "\n" * 95
        + "bogus: 1\n"
    )
    result = runner.invoke(app, ["validate", str(path)])
    assert result.exit_code == 2 and f"{path}:100:1: unknown key 'bogus'" in result.stderr
    path.write_text(path.read_text().replace("bogus: 1\n", ""))
    for command in (["validate", str(path)], ["graph", str(path)], ["graph", str(path), "--dot"]):
        result = runner.invoke(app, command)
        assert result.exit_code == 0, result.output
        assert name in result.stdout
    assert "[red]ab" in runner.invoke(app, ["graph", str(path)]).stdout
    assert '"[red]ab\\nFFFFFL"' in runner.invoke(app, ["graph", str(path), "--dot"]).stdout


URDF = """<robot name="r"><link name="a"/><link name="b"/>
<joint name="j" type="revolute"><parent link="a"/><child link="b"/>
<origin xyz="{xyz}" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="{lower}" upper="{upper}"/></joint></robot>
"""


@pytest.mark.parametrize(
    "xyz, lower, upper, expected",
    [
        ("nan 0 0", "-1", "1", "must be finite"),
        ("1e400 0 0", "-1", "1", "must be finite"),
        ("0 0 0", "1", "-1", "must be below"),
        ("0 0 0", "0.5", "0.5", "must be below"),
        ("0 0 0", "-inf", "1", "must be finite"),
    ],
)
def test_hostile_urdf_numbers(tmp_path, xyz, lower, upper, expected):
    (tmp_path / "r.urdf").write_text(URDF.format(xyz=xyz, lower=lower, upper=upper))
    path = tmp_path / "p.yaml"
    path.write_text("name: p\nframes: [w]\nrobots:\n  - {name: arm, urdf: r.urdf, parent: w}\n")
    result = runner.invoke(app, ["validate", str(path)])
    assert result.exit_code == 2 and expected in result.stderr, result.output
    assert re.search(r"r\.urdf:\d+:\d+: ", result.stderr), result.stderr


def test_a_urdf_on_one_line_of_many_joints_names_the_column_of_the_last(tmp_path):
    """Every element on one line (a minified file), 3000 joints, the last one's origin at fault:
    the column is that tag's, found in one pass over the text (a search per element took 49 s on
    such a file)."""
    joints = [
        f'<link name="l{k}"/><joint name="j{k}" type="revolute"><parent link="l{k - 1}"/><child link="l{k}"/>'
        f'<origin xyz="{"nan" if k == 2999 else "0"} 0 0.1"/><axis xyz="0 0 1"/>'
        '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
        for k in range(1, 3000)
    ]
    text = '<robot name="r"><link name="l0"/>' + "".join(joints) + "</robot>"
    (tmp_path / "r.urdf").write_text(text)
    path = tmp_path / "p.yaml"
    path.write_text("name: p\nframes: [w]\nrobots:\n  - {name: arm, urdf: r.urdf, parent: w}\n")
    result = runner.invoke(app, ["validate", str(path)])
    column = text.index('xyz="nan') + 1
    assert result.exit_code == 2 and f"r.urdf:1:{column}: " in result.stderr, result.stderr


@pytest.mark.parametrize("written", ["&#x202E;", "&#x200B;", "&#x85;"])
def test_urdf_names_a_terminal_would_act_on_are_refused(tmp_path, written):
    """A link or joint name with a right-to-left override, a zero-width space or a C1 control
    (XML allows them as character references) is refused where it is written, not printed."""
    text = URDF.format(xyz="0 0 0", lower="-1", upper="1").replace('joint name="j"', f'joint name="j{written}k"')
    (tmp_path / "r.urdf").write_text(text)
    path = tmp_path / "p.yaml"
    path.write_text("name: p\nframes: [w]\nrobots:\n  - {name: arm, urdf: r.urdf, parent: w}\n")
    result = runner.invoke(app, ["graph", str(path)])
    assert result.exit_code == 2, result.output
    assert re.search(r"r\.urdf:2:8: <joint name=\.\.\.> holds the character U\+", result.stderr), result.stderr


def test_printable_escapes_what_a_terminal_acts_on_and_nothing_else():
    from bcad.errors import printable, unprintable

    kept = [
        "plain",
        "über ünïcode 日本 é",
        "[bold] :100:",
        "",
        "👨\u200d👩\u200d👧",
        "soft\u00adhyphen",
        "flag\U000e0067",
    ]
    for text in kept:  # the zero-width joiner, a soft hyphen and tag characters are shown as text
        assert printable(text) == text and unprintable(text) is None
    escaped = [  # (text, as printed on one line, the first character a terminal acts on)
        ("g\x1b]0;pwned\x07", "g\\x1b]0;pwned\\x07", "\x1b"),
        ("\u202eplanar", "\\u202eplanar", "\u202e"),
        ("a\rb", "a\\x0db", "\r"),
        ("\x85\x7f", "\\x85\\x7f", "\x85"),
        ("zero\u200bwidth\u2028", "zero\\u200bwidth\\u2028", "\u200b"),
        ("p\nwarning [fake]: forged", "p\\x0awarning [fake]: forged", "\n"),
        ("tab\tbed", "tab\\x09bed", "\t"),
    ]
    for text, shown, first in escaped:
        assert printable(text) == shown and unprintable(text) == first
    # a value's lines (a description) are text; a key's or a name's are not
    assert unprintable("two\nlines\tand a tab", lines=True) is None
    assert unprintable("a\u202e\n", lines=True) == "\u202e"


def test_a_name_with_a_newline_cannot_forge_a_line_of_output(write_problem):
    """Names written with YAML's escape for a newline are printed on one line, the newline as
    its escape: a problem file cannot print a line of its own (a forged warning)."""
    path = write_problem(
        'name: "p\\nwarning [fake]: forged"\nframes: [w, "a\\nb"]\nlinks:\n  - {name: l, parent: w, child: "a\\nb"}\n'
    )
    result = runner.invoke(app, ["graph", str(path)])
    assert result.exit_code == 0, result.output
    assert "p\\x0awarning [fake]: forged" in result.stdout and "a\\x0ab" in result.stdout
    assert not any(line.startswith("warning") for line in result.stdout.splitlines())


def test_a_file_name_a_terminal_would_act_on_is_shown_escaped(tmp_path):
    """A command-line path with an escape sequence is named in its message, escaped."""
    result = runner.invoke(app, ["validate", str(tmp_path / "no\x1b[31mfile.yaml")])
    assert result.exit_code == 2 and "no\\x1b[31mfile.yaml: no such file" in result.stderr, result.stderr
    assert "\x1b" not in result.stderr


@pytest.mark.parametrize(
    "entity, expected",
    [
        ("{name: rail, type: edge, frame: w, start: [0, 0, 0], end: [1.0e-300, 0, 0]}", "an edge of length 1e-300"),
        ("{name: rail, type: edge, frame: w, start: [1.0e6, 0, 0], end: [1000000.0001, 0, 0]}", "at least 0.001"),
        (
            "{name: top, type: face, frame: w, vertices: [[0, 0], [1.0e-170, 0], [1.0e-170, 1.0e-170], [0, 1.0e-170]]}",
            "a face side of length 1e-170",
        ),
    ],
    ids=["edge-1e-300", "edge-short-beside-its-coordinates", "face-1e-170"],
)
def test_an_edge_or_face_too_small_to_have_a_direction_is_bad_input(tmp_path, entity, expected):
    """Lengths whose squares underflow (or lost to rounding beside the coordinates) are refused at
    the entity, exit 2: the solve ended in an internal error (numpy's SVD did not converge)."""
    path = tmp_path / "tiny.yaml"
    path.write_text(f"name: t\nframes: [w]\nentities:\n  - {entity}\n")
    result = runner.invoke(app, ["validate", str(path)])
    assert result.exit_code == 2 and f"{path}:4:5: entities[0]: " in result.stderr, result.stderr
    assert expected in result.stderr, result.stderr


@pytest.mark.parametrize(
    "problem, old, new, position",
    [
        ("rx90_sphere_touches.yaml", "data: rx90_sphere_touches.csv", "data: missing.csv", "58:11"),
        ("ur5_tracker.yaml", "data: ur5_tracker.csv", "data: .", "89:11"),
        (
            "ur5_eye_in_hand.yaml",
            "    frame: camera_optical\n",
            "    frame: camera_optical\n    camera_info: missing.yaml\n",
            "69:18",
        ),
    ],
    ids=["data-missing", "data-a-folder", "camera-info-missing"],
)
def test_a_measurement_s_or_camera_s_file_that_is_not_there_is_bad_input_at_its_key(
    tmp_path, problem, old, new, position
):
    """As a missing URDF is: the error points at the key that names the file, not at the file."""
    source = REPO / "problems" / "calibration" / problem
    text = source.read_text()
    assert old in text
    for other in source.parent.iterdir():  # the problem's neighbours (its CSV), where the copy can reach them
        if other.suffix in (".csv", ".yaml") and other.name != problem:
            (tmp_path / other.name).write_bytes(other.read_bytes())
    path = tmp_path / problem
    path.write_text(text.replace(old, new).replace("../../robots/", f"{REPO}/robots/"))
    if "missing" in new:
        (tmp_path / new.split(": ")[1].strip()).unlink(missing_ok=True)
    result = runner.invoke(app, ["calibrate", str(path), "--quiet"])
    assert result.exit_code == 2, result.stderr
    assert f"{path}:{position}: '" in result.stderr, result.stderr
