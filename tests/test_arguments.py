"""One argument path: the command line and the Python API check each argument once, in its
family, and name it as their caller spells it (``--seed`` on the command line, ``bcad.maxerror:
samples`` in Python); a value is blamed on the argument it came from."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

import bcad
from bcad.cli import app

from conftest import REPO

runner = CliRunner()
CLEARANCE = REPO / "problems" / "clearance"

#: two X (the placement's tx and ty, in [-10, 10]) scored through one closing link
TWO_X = """\
name: two-x
frames: [a, m, b]
links:
  - {name: unknown, parent: a, child: m, status: XXFFFF, bounds: {tx: [-10, 10], ty: [-10, 10]},
     distributions: {tx: 'normal(1, 2)', ty: 'normal(1, 2)'}}
  - {name: free, parent: m, child: b, status: LFFFFF, distributions: {tx: 'normal(0, 0.3)'}}
  - {name: measured, parent: a, child: b, pose: [3, 0, 0, 0, 0, 0], status: LLFFFF, close: true,
     distributions: {tx: 'normal(0, 0.4)', ty: 'normal(0, 0.4)'}}
solver: {posterior_samples: 2000}
"""


@pytest.fixture
def two_x(tmp_path):
    problem = tmp_path / "two.yaml"
    problem.write_text(TWO_X, encoding="utf-8")
    return problem


def _result(folder, solution: dict):
    path = folder / "at.json"
    path.write_text(json.dumps({"solution": solution, "seed": 0}), encoding="utf-8")
    return path


@pytest.mark.parametrize(
    "command",
    [
        ["maxerror", str(CLEARANCE / "2r.yaml"), "--samples", "1e3"],
        ["plot", str(CLEARANCE / "2r.yaml"), "--what", "error", "--samples", "1e3", "-o", "{tmp}/e.png"],
        ["batch", str(CLEARANCE / "2r.yaml"), "--out", "{tmp}/out"],
    ],
    ids=["maxerror", "plot", "batch"],
)
def test_every_command_refuses_a_seed_beyond_64_bits(command, tmp_path):
    """solve, posterior and calibrate refused it; maxerror, plot and batch took it."""
    args = [word.replace("{tmp}", str(tmp_path)) for word in command] + ["--seed", str(2**64)]
    result = runner.invoke(app, args)
    assert result.exit_code == 2, result.output
    assert "--seed" in result.output and "whole number" in result.output
    assert not (tmp_path / "out").exists() and not (tmp_path / "e.png").exists()


@pytest.mark.parametrize("command", ["solve", "posterior", "calibrate", "maxerror", "plot", "batch"])
def test_a_negative_seed_is_one_line_naming_the_option(command, tmp_path):
    """Every command checks its seed in one place (no usage block from the option parser)."""
    required = {"plot": ["--what", "graph"], "batch": ["--out", str(tmp_path / "out")]}.get(command, [])
    result = runner.invoke(app, [command, str(tmp_path / "none.yaml"), *required, "--seed", "-1"])
    assert result.exit_code == 2
    assert "--seed: '-1' is given; expected a whole number in [0, 9223372036854775807]" in result.output
    assert "Usage:" not in result.output


def test_a_value_out_of_bounds_is_blamed_on_where_it_came_from(two_x, tmp_path):
    at = _result(tmp_path, {"unknown.tx": 50.0, "unknown.ty": 0.0})
    from_file = runner.invoke(app, ["posterior", str(two_x), "--at", str(at), "--value", "unknown.ty=1"])
    assert from_file.exit_code == 2
    assert "at.json" in from_file.output and "unknown.tx is 50" in from_file.output
    assert "--value" not in from_file.output.split("unknown.tx")[0]
    from_value = runner.invoke(
        app, ["posterior", str(two_x), "--at", str(at), "--value", "unknown.tx=1", "--value", "unknown.ty=20"]
    )
    assert from_value.exit_code == 2
    assert "--value" in from_value.output and "unknown.ty is 20" in from_value.output


def test_a_value_given_twice_is_refused(two_x):
    """--value unknown.tx=1 --value unknown.tx=2: which was meant is not for bcad to guess."""
    result = runner.invoke(app, ["posterior", str(two_x), "--value", "unknown.tx=1", "--value", "unknown.tx=2"])
    assert result.exit_code == 2
    assert "--value: 'unknown.tx' is given twice; give each X once" in result.output


def test_plot_checks_a_result_as_posterior_does(two_x, tmp_path):
    """A result naming a parameter the problem does not have is another problem's: refused."""
    pytest.importorskip("matplotlib")
    at = _result(tmp_path, {"unknown.tx": 1.0, "unknown.ty": 0.0, "other.tz": 2.0})
    for command in (
        ["posterior", str(two_x), "--at", str(at)],
        ["plot", str(two_x), "--what", "arms", "--at", str(at), "-o", str(tmp_path / "a.png")],
    ):
        result = runner.invoke(app, command)
        assert result.exit_code == 2, (command, result.output)
        assert "'other.tz' is not an X parameter" in result.output
    assert not (tmp_path / "a.png").exists()


def test_a_result_in_other_units_is_refused(two_x, tmp_path):
    """A result in mm read by a problem in m took its X (0.3 mm) as 0.3 m: the posterior of
    another configuration, exit 0. Refused by the command line, the plot and the Python API."""
    pytest.importorskip("matplotlib")
    at = tmp_path / "mm.json"
    at.write_text(
        json.dumps(
            {"solution": {"unknown.tx": 1.0, "unknown.ty": 0.5}, "seed": 0, "units": {"length": "mm", "angle": "rad"}}
        )
    )
    for command in (
        ["posterior", str(two_x), "--at", str(at)],
        ["plot", str(two_x), "--what", "arms", "--at", str(at), "-o", str(tmp_path / "a.png")],
    ):
        result = runner.invoke(app, command)
        assert result.exit_code == 2, (command, result.output)
        assert f"{at}:1:74: a result in mm and rad, and this problem is in m and rad" in result.stderr
    with pytest.raises(bcad.InputError, match="its X would be read in the wrong units"):
        bcad.posterior(two_x, at=json.loads(at.read_text()))
    # another problem's result in other units: named as another problem's first
    other = {"solution": {"joint1.rz": 1.0}, "units": {"length": "mm", "angle": "rad"}}
    with pytest.raises(bcad.InputError, match="'joint1.rz' is not an X parameter of this problem"):
        bcad.posterior(two_x, at=other)
    # the same result in the problem's units is read as it was
    at.write_text(json.dumps({**json.loads(at.read_text()), "units": {"length": "m", "angle": "rad"}}))
    assert bcad.posterior(two_x, at=at, samples=500).solution == {"unknown.tx": 1.0, "unknown.ty": 0.5}


def test_the_api_names_its_own_arguments_where_the_chain_refuses_them():
    with pytest.raises(bcad.InputError, match=r"bcad\.maxerror: samples.*samples of a 7-joint chain"):
        bcad.maxerror(CLEARANCE / "7r.yaml", samples=100_000_000)
    with pytest.raises(bcad.InputError, match=r"bcad\.maxerror: weights.*gives 1 weights for a chain of 2"):
        bcad.maxerror(CLEARANCE / "2r.yaml", allocate={"translation": 1e-3}, weights=[1.0])


def test_posterior_at_a_result_without_a_solution_says_what_it_takes(two_x):
    worst = bcad.maxerror(CLEARANCE / "2r.yaml")
    with pytest.raises(bcad.InputError, match="a result of kind 'maxerror'; expected a solve or posterior result"):
        bcad.posterior(two_x, at=worst)


def test_posterior_takes_numpy_numbers_as_values(two_x):
    result = bcad.posterior(two_x, values={"unknown.tx": np.float32(2.5), "unknown.ty": np.int64(0)}, samples=500)
    assert result.solution == {"unknown.tx": 2.5, "unknown.ty": 0.0}


def test_a_result_follows_its_document():
    worst = bcad.maxerror(CLEARANCE / "2r.yaml")
    assert worst.trusted
    worst.document["warnings"].append({"code": "added", "message": "a warning added by hand"})
    assert not worst.trusted and worst.warnings[0]["code"] == "added"


@pytest.mark.parametrize(
    "args, expected",
    [
        (["plot", "{file}", "--what", "nonsense"], "--what: 'nonsense' is not a picture; expected arms"),
        (["posterior", "{file}", "--value", "abc"], "--value: 'abc' is not NAME=VALUE with a number"),
        (["plot", "{file}", "--what", "graph", "-o", "{out}.gif"], "-o: "),
        (["detect", "{file}", "--checkerboard", "2x2", "-o", "{out}.csv"], "--checkerboard: '2x2' is given; expected"),
    ],
)
def test_option_values_bcad_checks_are_one_line_naming_the_option(args, expected, tmp_path):
    """As the seed's: no usage block from the option parser, exit 2."""
    problem = tmp_path / "p.yaml"
    problem.write_text("name: p\nframes: [a]\n")
    words = [word.format(file=problem, out=tmp_path / "out") for word in args]
    result = runner.invoke(app, words)
    assert result.exit_code == 2, result.output
    assert expected in result.output and "Usage:" not in result.output, result.output
