"""Measure, then plan (issue 19): a calibration result's joint posterior as a planning problem's
prior on L, correlations kept, checked against closed forms."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from bcad.compile import compile_problem
from bcad.errors import InputError
from bcad.model import load_problem

from conftest import run_bcad

# Q = X + a + b: two L in series, the closing link scores Q - 3 ~ N(0, 0.1^2); X has no prior.
TWO_L = """
name: two-l
units: {length: mm, angle: rad}
frames: [o, m, n, p]
links:
  - {name: unknown, parent: o, child: m, status: XFFFFF, bounds: {tx: [-10, 10]}}
  - {name: a, parent: m, child: n, status: LFFFFF, distributions: {tx: 'normal(0, 5)'}}
  - {name: b, parent: n, child: p, status: LFFFFF, distributions: {tx: 'normal(0, 5)'}}
  - {name: measured, parent: o, child: p, pose: [3, 0, 0, 0, 0, 0], status: LFFFFF, close: true,
     distributions: {tx: 'normal(0, 0.1)'}}
solver: {estimator: linear, posterior_samples: 200000}
"""
MEAN = {"a.tx": 0.4, "b.tx": -0.1}  # mm
STD = {"a.tx": 0.3, "b.tx": 0.2}
RHO = -0.9


def _result(folder, length="mm", scale=1.0, extra=None):
    """A bcad calibrate result (the keys solve reads) for a and b, in ``length`` units."""
    parameters = {name: {"kind": "L", "map": MEAN[name] * scale, "laplace_std": STD[name] * scale,
                         "estimate": 99.0, "std": 99.0} for name in MEAN}
    names = list(MEAN)
    if extra:
        parameters[extra] = {"kind": "L", "map": 0.0, "laplace_std": 1.0}
        names.append(extra)
    matrix = np.eye(len(names))
    matrix[0, 1] = matrix[1, 0] = RHO
    document = {"units": {"length": length, "angle": "rad"}, "parameters": parameters,
                "correlation": {"names": names, "matrix": matrix.tolist()}}
    path = folder / f"calibration_{length}.json"
    path.write_text(json.dumps(document))
    return path


def test_the_calibrated_posterior_replaces_the_prior_with_its_correlation(tmp_path, write_problem):
    """Closed forms: a + b ~ N(0.3, 0.3^2 + 0.2^2 + 2 (-0.9)(0.3)(0.2)) = N(0.3, 0.0220) (std
    0.1483; independent, the stds alone would give 0.3606; the file's own 5 mm priors, 7.07).
    The prior-propagated Table 2 std of the closing link is that std; the linear estimator's
    X* is 3 - 0.3 and its log p(X) I(X) -log(20) + log N(0; 0, 0.0220 + 0.01)."""
    result = _result(tmp_path, "m", 0.001)  # in metres: converted to the problem's mm
    problem = write_problem(TWO_L + f"calibration: ['{result}']\n")
    run = run_bcad("solve", problem, "--seed", "1", "--quiet")
    assert run.returncode == 0, run.stderr
    document = json.loads(run.stdout)
    variance = 0.3**2 + 0.2**2 + 2 * RHO * 0.3 * 0.2
    assert document["solution"]["unknown.tx"] == pytest.approx(3.0 - 0.3, abs=1e-6)
    expected = -math.log(20.0) - 0.5 * math.log(2 * math.pi * (variance + 0.01))
    assert document["objective"]["log_value"] == pytest.approx(expected, abs=1e-9)
    link = document["posterior"]["links"]["measured"]
    assert link["std"][0] == pytest.approx(math.sqrt(variance), rel=0.01)
    assert document["calibration"][0]["applied"] == ["a.tx", "b.tx"] and document["calibration"][0]["not_applied"] == []


def test_the_command_line_flag_and_a_parameter_the_problem_lacks(tmp_path, write_problem):
    """--calibration on posterior does what calibration: does; a name that is not L here is
    listed in a note on stderr and in the result, and the rest still applies (exit 0)."""
    result = _result(tmp_path, extra="c.tx")
    problem = write_problem(TWO_L)
    run = run_bcad("posterior", problem, "--set", "unknown.tx=2.7", "--calibration", result, "--json")
    assert run.returncode == 0, run.stderr
    document = json.loads(run.stdout)
    assert "note:" in run.stderr and "c.tx" in run.stderr
    assert document["calibration"][0]["not_applied"] == ["c.tx"]
    assert document["posterior"]["links"]["measured"]["std"][0] == pytest.approx(math.sqrt(0.022), rel=0.01)


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d.update(parameters=[1, 2]), "no 'parameters' mapping"),
    (lambda d: d["parameters"]["a.tx"].update(laplace_std=-1.0), "expected a positive number"),
    (lambda d: d["parameters"]["a.tx"].update(map=float("nan")), "finite number"),
    (lambda d: d["correlation"].update(matrix=[[1, 2], [2, 1]]), "entries in [-1, 1]"),
    (lambda d: d["correlation"].update(matrix=[[1, 1], [-1, 1]]), "not symmetric"),
    (lambda d: d.update(units={"length": "furlong"}), "units"),
])
def test_a_bad_calibration_result_is_an_input_error(tmp_path, write_problem, mutate, message):
    path = _result(tmp_path)
    document = json.loads(path.read_text())
    mutate(document)
    path.write_text(json.dumps(document).replace("NaN", "NaN"))
    problem = write_problem(TWO_L + f"calibration: ['{path}']\n")
    with pytest.raises(InputError, match=message.replace("[", r"\[").replace("]", r"\]")):
        compile_problem(load_problem(problem))
    run = run_bcad("validate", problem)
    assert run.returncode == 2 and "Traceback" not in run.stderr


def test_an_output_never_replaces_a_calibration_result(tmp_path, write_problem):
    result = _result(tmp_path)
    before = result.read_bytes()
    run = run_bcad("solve", write_problem(TWO_L), "--calibration", result, "-o", result, "--quiet")
    assert run.returncode == 2 and result.read_bytes() == before
