"""The Python API: the guide's and the README's examples run, and the API gives what the commands give."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest

import bcad

from conftest import ONE_LINK_GRAPH, REPO, run_bcad, rx90_solved

README = (REPO / "README.md").read_text(encoding="utf-8")
API_GUIDE = (REPO / "docs" / "guide" / "api.md").read_text(encoding="utf-8")


def test_the_api_guide_example_runs():
    block = re.search(r"# Python API\n.*?```python\n(.*?)```", API_GUIDE, re.S).group(1)
    run = subprocess.run([sys.executable, "-c", block], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    assert "<dict>:1:1: missing key 'frames'" in run.stdout


def test_the_readme_python_example_runs():
    """The README's example: a trusted solve of the planar arm, the reach's weighted std about
    the 4.8 mm its table shows, and a calibration's parameter as an estimate with its std."""
    block = re.search(r"## From Python\n.*?```python\n(.*?)```", README, re.S).group(1)
    run = subprocess.run([sys.executable, "-c", block], cwd=REPO, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    # the README's table: log p(X) I(X) = -0.5342 ± 0.0032 at seed 0 (the same run), so within 1e-4
    trusted, value = re.fullmatch(r"(True|False) \((\S+), (\S+)\)", lines[0]).group(1, 2)
    shown = float(re.search(r"log p\(X\) I\(X\) = (\S+) ±", README).group(1))
    assert trusted == "True" and abs(float(value) - shown) < 1e-4
    assert "0.004" in lines[1] and "'estimate'" in lines[2] and "'std'" in lines[2]


def test_solve_gives_the_commands_document(write_problem, tmp_path):
    path = write_problem(ONE_LINK_GRAPH)
    result = bcad.solve(bcad.load(path), seed=3, samples=20000)
    run = run_bcad("solve", path, "--seed", "3", "--samples", "2e4", "-o", tmp_path / "r.json", "--quiet")
    assert run.returncode == 0
    document = json.loads((tmp_path / "r.json").read_text())
    for key in ("solution", "objective", "posterior", "warnings"):
        _close(result.document[key], document[key])  # equal but for the BLAS threads' rounding (the CLI uses one)
    # One link Q = X + L scored by N(3, 0.4^2) with L ~ N(0, 0.3^2): the closed form of the
    # posterior of the closing link's tx is N(3, (0.3 x 0.4 / 0.5)^2) at X* = 3 (conftest).
    link = result.links["measured"]
    assert abs(link.weighted_std[0] - 0.24) < 0.01 and json.loads(result.to_json()) == result.document
    assert "Table 2" in result._repr_html_()


def _close(a, b) -> None:
    if isinstance(a, dict):
        assert set(a) == set(b)
        for key in a:
            _close(a[key], b[key])
    elif isinstance(a, list):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            _close(x, y)
    elif isinstance(a, float):
        assert a == pytest.approx(b, rel=1e-9, abs=1e-12)
    else:
        assert a == b


def test_errors_raise_input_error_and_never_exit(tmp_path):
    with pytest.raises(bcad.InputError) as error:
        bcad.load(tmp_path / "missing.yaml")
    assert "missing.yaml" in str(error.value)
    with pytest.raises(bcad.InputError, match="no value for X parameter"):
        bcad.posterior(
            {
                "name": "x",
                "frames": ["a", "m", "b"],
                "links": [
                    {"name": "u", "parent": "a", "child": "m", "status": "XFFFFF", "bounds": {"tx": [-1, 1]}},
                    {
                        "name": "c",
                        "parent": "a",
                        "child": "b",
                        "close": True,
                        "status": "LFFFFF",
                        "distributions": {"tx": "normal(0, 1)"},
                    },
                    {"name": "f", "parent": "m", "child": "b"},
                ],
            },
            values={},
        )


def test_a_broken_result_file_raises_input_error(write_problem, tmp_path):
    (tmp_path / "broken.json").write_text("{not json")
    with pytest.raises(bcad.InputError, match="not valid JSON"):
        bcad.posterior(write_problem(ONE_LINK_GRAPH), at=tmp_path / "broken.json")


def test_compile_is_a_function_beside_the_compiler_package():
    import bcad.compiler

    compiled = bcad.compile(REPO / "problems" / "rx90_face_on_face.yaml")
    assert compiled.stats.as_dict()["cycles"] == 1
    assert callable(bcad.compile) and bcad.compiler.compile_problem.__module__ == "bcad.compiler.problem"
    assert np.array_equal(bcad.compile(compiled).parameters.x_nominal, compiled.parameters.x_nominal)


def test_samples_out_writes_the_posterior_samples(tmp_path_factory, tmp_path):
    """--samples-out: the samples behind Table 2's plain mean and std (the document's numbers,
    recomputed from the file), their weights, in the problem's units; bounded in size."""
    path = REPO / "problems" / "rx90_face_on_face.yaml"
    solved = rx90_solved(tmp_path_factory)  # bcad solve --samples 2e4 -o result.json --samples-out samples.npz
    document = json.loads(solved.read_text())
    data = np.load(solved.parent / "samples.npz")
    poses = data["contact/poses"]
    assert poses.shape == (20000, 6) and data["log_weights"].shape == (20000,)
    assert list(data["units"]) == ["mm", "rad"]
    link = document["posterior"]["links"]["contact"]
    np.testing.assert_allclose(poses.mean(axis=0), link["mean"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(poses.std(axis=0), link["std"], rtol=1e-6)
    # The same from bcad posterior at that solution, with the same seed.
    run = run_bcad(
        "posterior",
        path,
        "--at",
        solved,
        "--samples",
        "2e4",
        "--json",
        "--samples-out",
        tmp_path / "p.npz",
    )
    assert run.returncode in (0, 3), run.stderr
    np.testing.assert_allclose(np.load(tmp_path / "p.npz")["contact/poses"], poses, rtol=0, atol=1e-9)
    run = run_bcad("solve", path, "--samples", "3e6", "--samples-out", tmp_path / "big.npz")
    assert run.returncode == 2 and "at most" in run.stderr


@pytest.mark.parametrize(
    "order",
    [
        "bcad.calibrate(P); bcad.calibrate(P); bcad.compile(P); bcad.compile(P); bcad.calibrate(P)",
        "import bcad.calibration; bcad.calibrate(P); import bcad.calibration.model; bcad.calibrate(P)",
        "from bcad.calibration import solve; bcad.compile(P); bcad.calibrate(P); bcad.calibrate(P)",
    ],
)
def test_calibrate_and_compile_stay_callable_in_any_order(order):
    """bcad.calibrate and bcad.compile are the API's functions whatever was imported before
    them (their packages are bcad.calibration and bcad.compiler): each call returns its result
    and the packages import by their names."""
    code = (
        f"import bcad\nP = {str(REPO / 'problems' / 'calibration' / 'ur5_tracker.yaml')!r}\n"
        + order.replace("; ", "\n")
        + "\nassert callable(bcad.calibrate) and callable(bcad.compile)"
        + "\nassert bcad.calibrate(P).document['parameters']['smr_mount.tx']['std'] > 0"
        + "\nassert bcad.compile(P).stats.cycles == 0\nimport bcad.calibration.check as check\nimport bcad.calibration.check"
        + "\nassert check.__name__ == 'bcad.calibration.check' and bcad.calibration.model.__name__ == 'bcad.calibration.model'"
        + "\nprint('ok')\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO)
    assert run.returncode == 0 and run.stdout.strip() == "ok", run.stderr[-2000:]


P_RX90 = REPO / "problems" / "rx90_face_on_face.yaml"
P_2R = REPO / "problems" / "clearance" / "2r.yaml"


@pytest.mark.parametrize(
    "call, fragment",
    [
        (lambda: bcad.load(None), "a problem is NoneType"),
        (lambda: bcad.load(42), "a problem is int 42"),
        (lambda: bcad.load([1, 2]), "a problem is list"),
        (lambda: bcad.load(b"name: x"), "a problem is bytes"),
        (lambda: bcad.compile(None), "a problem is NoneType"),
        (lambda: bcad.solve(P_RX90, samples=-1), "samples is -1"),
        (lambda: bcad.solve(P_RX90, samples=2.5), "samples is 2.5"),
        (lambda: bcad.solve(P_RX90, samples="x"), "samples is 'x'"),
        (lambda: bcad.solve(P_RX90, seed="x"), "seed is 'x'"),
        (lambda: bcad.solve(P_RX90, seed=True), "seed is True"),
        (lambda: bcad.solve(P_RX90, backend="bogus"), "backend is 'bogus'"),
        (lambda: bcad.solve(P_RX90, estimator="guess"), "estimator is 'guess'"),
        (lambda: bcad.posterior(P_RX90, at=42), "at is 42; expected a result"),
        (lambda: bcad.posterior(P_RX90, values={"x": float("nan")}), "finite numbers"),
        (lambda: bcad.posterior(P_RX90, values={"x": int("9" * 4000)}), "finite numbers"),
        (lambda: bcad.posterior(P_RX90, at={"solution": {"x": 10**400}}), "finite numbers"),
        (lambda: bcad.load({"name": "x", "frames": {"a", "b"}}), "holds a set, not plain data"),
        (
            lambda: bcad.load({"name": "x", "frames": ["a"], "relations": ({"name": "r"},)}),
            "holds a tuple, not plain data",
        ),
        (lambda: bcad.maxerror(P_2R, tol=-1), "tol is -1"),
        (lambda: bcad.maxerror(None), "problem is None"),
        (lambda: bcad.maxerror(P_2R, model="cubic"), "model is 'cubic'"),
        (lambda: bcad.calibrate(42), "a problem is int 42"),
        (
            lambda: bcad.calibrate(REPO / "problems" / "calibration" / "ur5_tracker.yaml", check_samples=-5),
            "check_samples is -5",
        ),
        (
            lambda: bcad.calibrate(REPO / "problems" / "calibration" / "ur5_tracker.yaml", propose=2),
            "propose: needs candidates",
        ),
        # the checks that need the problem name the argument as a Python caller writes it too
        (
            lambda: bcad.calibrate(REPO / "problems" / "calibration" / "ur5_tracker.yaml", check_samples=5),
            "bcad.calibrate: check_samples is 5; expected 0 (no check) or at least 100",
        ),
        # a NUL in a path, which no file name holds (the operating system raises ValueError)
        (lambda: bcad.load("a\0b.yaml"), "a\\x00b.yaml: the path has a NUL character"),
        (lambda: bcad.maxerror("a\0b"), "the path has a NUL character"),
        (lambda: bcad.posterior(P_RX90, at="r\0.json"), "the path has a NUL character"),
        (lambda: bcad.solve(P_RX90, samples_out="x\0.npz"), "the path has a NUL character"),
        (lambda: bcad.solve(P_RX90, calibration=["c\0.json"]), "has a NUL character"),
        (lambda: bcad.confined("a\0b").__enter__(), "the path has a NUL character"),
        (lambda: bcad.confined(42).__enter__(), "confined: 42 is given; expected a folder's path"),
        (lambda: bcad.load("name: x\nframes: [a]\n"), "no such file: a text of 2 lines, which looks like YAML"),
        # a mapping holds printable text as a file does
        (lambda: bcad.load({"name": "\x1bevil", "frames": ["a"]}), "has a text that holds the character U+001B"),
        (lambda: bcad.load({"name": "ok", "frames": ["a\0b"]}), "has a text that holds the character U+0000"),
        (lambda: bcad.load({"name": "ok", "frames": ["a"], "\x1bkey": 1}), "has a key that holds the character U+001B"),
        (
            lambda: bcad.maxerror({"name": "\x1b", "chain": {"dh": [{"a": 1, "alpha": 0, "d": 0, "theta": 0}]}}),
            "has a text that holds the character U+001B",
        ),
    ],
)
def test_api_arguments_raise_input_error_saying_what_was_expected(call, fragment):
    """A wrong argument to the Python API is an InputError naming it and what was
    expected, never a TypeError, ZeroDivisionError or ValueError from deep inside."""
    with pytest.raises(bcad.InputError, match=re.escape(fragment)):
        call()


#: the command's options that shape what it prints or writes beside the result, which the API
#: returns as a Result instead (its document, table, URDF texts, cameras); every other option is an argument
PRESENTATION = {"output", "as_json", "quiet", "contributors", "plot_dir", "urdf", "camera_info"}
DEPRECATED = {"old_assignments"}  # posterior's former --set, the same values as --value
RENAMED = {"file": "problem", "assignments": "values"}


@pytest.mark.parametrize("command", ["solve", "posterior", "maxerror", "calibrate"])
def test_every_option_of_the_command_is_an_argument_of_the_api(command):
    import inspect

    import typer.main

    from bcad.cli import app

    options = {parameter.name for parameter in typer.main.get_command(app).commands[command].params}
    from bcad import api

    arguments = set(inspect.signature(getattr(api, command)).parameters)
    assert {RENAMED.get(name, name) for name in options - PRESENTATION - DEPRECATED} <= arguments


def test_the_api_takes_calibrations_samples_out_and_a_spec(tmp_path, write_problem):
    """Each as the command does: the calibration's posterior replaces the prior (std of a + b
    from the calibration's closed form), the samples are written, the spec's yield is reported."""
    problem = write_problem(ONE_LINK_GRAPH + "solver: {search_starts: 2, posterior_samples: 20000}\n")
    calibration = tmp_path / "calibration.json"
    calibration.write_text(json.dumps({"parameters": {"free.tx": {"map": 0.0, "laplace_std": 0.1}}}))
    plain = bcad.solve(problem, seed=1)
    calibrated = bcad.solve(problem, seed=1, calibration=[calibration], samples_out=tmp_path / "s.npz")
    assert plain.links["measured"].std[0] == pytest.approx(0.3, rel=0.03)
    assert calibrated.links["measured"].std[0] == pytest.approx(0.1, rel=0.03)
    assert np.load(tmp_path / "s.npz")["measured/poses"].shape == (20000, 6)
    at = bcad.posterior(
        problem, values={"unknown.tx": 2.9}, calibration=[calibration], samples=5000, samples_out=tmp_path / "p.npz"
    )
    assert at.links["measured"].std[0] == pytest.approx(0.1, rel=0.05) and (tmp_path / "p.npz").exists()
    with pytest.raises(bcad.InputError, match="expected a list of result paths"):
        bcad.solve(problem, calibration=str(calibration))
    worst = bcad.maxerror(P_2R, spec={"translation": 1e9}, allocate="translation=0.001", weights=[1, 2])
    assert worst.document["statistics"]["yield"]["value"] == 1.0 and worst.document["allocation"]["lambda_low"] > 0
    with pytest.raises(bcad.InputError, match="weights scale the clearances of allocate"):
        bcad.maxerror(P_2R, weights=[1, 2])


@pytest.mark.parametrize(
    "call", ["posterior_samples", "solve_seed", "maxerror_tol", "maxerror_samples", "calibrate_seed"]
)
def test_an_integer_too_long_for_python_to_print_is_an_input_error(call, write_problem):
    """An argument of 5000 digits: Python cannot even turn it into text (ValueError past 4300
    digits); the API says what it is and what it expected."""
    big = 10**5000
    problem = write_problem(ONE_LINK_GRAPH)
    calls = {
        "posterior_samples": lambda: bcad.posterior(problem, values={"unknown.tx": 1.0}, samples=big),
        "solve_seed": lambda: bcad.solve(problem, seed=big),
        "maxerror_tol": lambda: bcad.maxerror(REPO / "problems" / "clearance" / "2r.yaml", tol=big),
        "maxerror_samples": lambda: bcad.maxerror(REPO / "problems" / "clearance" / "2r.yaml", samples=big),
        "calibrate_seed": lambda: bcad.calibrate(REPO / "problems" / "calibration" / "ur5_tracker.yaml", seed=big),
    }
    with pytest.raises(bcad.InputError, match="an integer of about 5,000 digits"):
        calls[call]()


def test_posterior_names_an_unknown_x_parameter():
    """A value for a name the problem does not have as X is an InputError naming it (it was a
    NameError from the message's own formatting)."""
    with pytest.raises(bcad.InputError, match="'nope' is not an X parameter"):
        bcad.posterior(
            str(REPO / "problems" / "studies" / "planar_2r.yaml"),
            values={"nope": 1.0, "joint1.rz": 0.1, "joint2.rz": 0.2},
            samples=1000,
        )


def test_load_reads_a_clearance_problem_as_the_model_maxerror_takes():
    """bcad.load of a clearance problem (a path or a mapping) gives the model bcad.maxerror takes,
    with the same result as the path."""
    import yaml

    from bcad.model.clearance import ChainProblem

    path = REPO / "problems" / "clearance" / "2r.yaml"
    loaded = bcad.load(path)
    assert isinstance(loaded, ChainProblem)
    assert isinstance(bcad.load(yaml.safe_load(path.read_text())), ChainProblem)
    assert bcad.maxerror(loaded).document["rotation"]["max"] == bcad.maxerror(path).document["rotation"]["max"]


def test_no_calibration_may_be_said_with_none():
    """calibration=None is no calibration, as None is for the other optional arguments."""
    problem = REPO / "problems" / "studies" / "planar_2r.yaml"
    values = {"joint1.rz": 0.3, "joint2.rz": 0.9}
    plain = bcad.posterior(problem, values=values, samples=2000, calibration=())
    none = bcad.posterior(problem, values=values, samples=2000, calibration=None)
    assert none.document["objective"] == plain.document["objective"]
