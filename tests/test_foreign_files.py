"""A problem may name any file: one that is not of the expected kind (a CSV without the expected
header, a JSON that is not a bcad result) is refused with what was expected and no byte of it;
a bad cell of a file of the right kind is quoted, shortened."""

from __future__ import annotations

import json
import shutil

import pytest
from typer.testing import CliRunner

from bcad.cli import app

from conftest import ONE_LINK_GRAPH, REPO

runner = CliRunner()
SECRET = "s3cr3t-Token"
#: a file that is not a CSV of measurements: a password file's lines, each a secret
FOREIGN = f"root:x:0:0:{SECRET}:/root:/bin/bash\ndaemon:x:1:1:{SECRET}:/usr/sbin:/usr/sbin/nologin\n"


@pytest.fixture
def calibration_folder(tmp_path):
    """The UR5 tracker calibration example, copied with its data, and a foreign file beside it."""
    source = REPO / "problems" / "calibration"
    for name in ("ur5_tracker.yaml", "ur5_tracker.csv"):
        shutil.copy(source / name, tmp_path / name)
    text = (tmp_path / "ur5_tracker.yaml").read_text()
    (tmp_path / "ur5_tracker.yaml").write_text(text.replace("../../robots/", f"{REPO}/robots/"))
    (tmp_path / "foreign.txt").write_text(FOREIGN)
    return tmp_path


def _refused_quietly(result, expected: str) -> None:
    assert result.exit_code == 2, result.output
    assert expected in result.output, result.output
    assert SECRET not in result.output and "/bin/bash" not in result.output and "Traceback" not in result.output


def test_a_foreign_file_as_measurement_data(calibration_folder):
    problem = calibration_folder / "ur5_tracker.yaml"
    problem.write_text(problem.read_text().replace("data: ur5_tracker.csv", "data: foreign.txt"))
    result = runner.invoke(app, ["calibrate", str(problem)])
    _refused_quietly(
        result, "foreign.txt:1:1: not a CSV file of measurements: its first line names none of the columns"
    )


@pytest.mark.parametrize(
    "options",
    [
        ["--propose", "3", "--candidates", "{f}"],
        ["--predict", "{f}"],
        ["--propose", "3", "--candidates", "{csv}", "--for", "{f}"],
    ],
)
def test_a_foreign_file_as_configurations(calibration_folder, options):
    files = {"f": calibration_folder / "foreign.txt", "csv": calibration_folder / "ur5_tracker.csv"}
    args = [o.format(**files) for o in options]
    result = runner.invoke(app, ["calibrate", str(calibration_folder / "ur5_tracker.yaml"), *args])
    _refused_quietly(result, "not a CSV file of configurations, a column per joint")


def test_a_bad_cell_of_a_measurement_file_is_quoted_shortened(calibration_folder):
    data = calibration_folder / "ur5_tracker.csv"
    lines = data.read_text().splitlines()
    cells = lines[3].split(",")
    cells[-1] = "12x" + "9" * 100
    lines[3] = ",".join(cells)
    data.write_text("\n".join(lines) + "\n")
    result = runner.invoke(app, ["calibrate", str(calibration_folder / "ur5_tracker.yaml")])
    assert result.exit_code == 2
    column = len(lines[3]) - len(cells[-1]) + 1
    assert f"ur5_tracker.csv:4:{column}: '12x" + "9" * 21 + "…' in column 'tz' is not a number" in result.output, (
        result.output
    )


def test_a_json_that_is_not_a_result(write_problem, tmp_path):
    problem = write_problem(ONE_LINK_GRAPH)
    at = tmp_path / "keys.json"
    at.write_text(json.dumps({"solution": {f"{SECRET} root": 1.0}}))
    _refused_quietly(
        runner.invoke(app, ["posterior", str(problem), "--at", str(at)]),
        "not a bcad result: entry 1 of its 'solution' is not named LINK.PARAMETER",
    )


@pytest.mark.parametrize(
    "solution, seed, expected",
    [
        ({"link.tx": "abc"}, 0, "keys.json:3:14: solution value of 'link.tx' is \"abc\", expected a finite number"),
        ({"link.tx": 1.0}, -2, "keys.json:5:10: not a bcad result: its seed is -2, expected a non-negative integer"),
        # of this problem (ONE_LINK_GRAPH: unknown.tx in [-10, 10], in m)
        ({"unknown.tx": 50.0}, 0, "keys.json:3:17: the value of X parameter unknown.tx is 50, outside its bounds"),
        ({"unknwn.tx": 5.0}, 0, "keys.json:3:16: 'unknwn.tx' is not an X parameter of this problem"),
        ({"unknown.tx": 5.0, "units": "mm"}, 0, "keys.json:6:11: a result in mm and rad"),
        ({"other.tx": 5.0, "1 root": 1.0}, 0, "keys.json:4:13: not a bcad result: entry 2 of its 'solution'"),
    ],
)
def test_a_bad_value_of_a_result_is_refused_at_its_line(write_problem, tmp_path, solution, seed, expected):
    at = tmp_path / "keys.json"
    document = {"solution": solution, "seed": seed}
    if solution.pop("units", None):
        document["units"] = {"length": "mm", "angle": "rad"}
    at.write_text(json.dumps(document, indent=1))
    _refused_quietly(runner.invoke(app, ["posterior", str(write_problem(ONE_LINK_GRAPH)), "--at", str(at)]), expected)


@pytest.mark.parametrize(
    "document, expected",
    [
        (
            {"parameters": {f"{SECRET}:root": {"map": 1, "laplace_std": 1}}},
            "entry 1 of 'parameters' is not named LINK.PARAMETER",
        ),
        (
            {"parameters": {"free.tx": {"map": 0, "laplace_std": 0.1}}, "units": "mm"},
            "units 'mm': expected a length in",
        ),
    ],
)
def test_a_json_that_is_not_a_calibration_result(write_problem, tmp_path, document, expected):
    calibration = tmp_path / "calibration.json"
    calibration.write_text(json.dumps(document))
    problem = write_problem(ONE_LINK_GRAPH + "calibration: [calibration.json]\n")
    _refused_quietly(runner.invoke(app, ["solve", str(problem), "--quiet"]), expected)


def test_a_missing_calibration_result_names_its_line(write_problem):
    problem = write_problem(ONE_LINK_GRAPH + "calibration: [missing.json]\n")
    result = runner.invoke(app, ["solve", str(problem), "--quiet"])
    assert result.exit_code == 2
    assert "problem.yaml:7:15: calibration result 'missing.json' not found" in result.output, result.output
    result = runner.invoke(app, ["solve", str(problem), "--quiet", "--calibration", "also-missing.json"])
    assert result.exit_code == 2 and "also-missing.json: no such file (a bcad calibrate result)" in result.output, (
        result.output
    )
