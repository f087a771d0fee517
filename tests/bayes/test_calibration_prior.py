"""Measure, then plan: a calibration result's joint posterior as a planning problem's
prior on L, correlations kept, checked against closed forms."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml

from bcad.compiler import compile_problem
from bcad.errors import InputError
from bcad.model import load_problem

from conftest import REPO, assert_committed_calibration, run_bcad

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
    parameters = {
        name: {"kind": "L", "map": MEAN[name] * scale, "laplace_std": STD[name] * scale, "estimate": 99.0, "std": 99.0}
        for name in MEAN
    }
    names = list(MEAN)
    if extra:
        parameters[extra] = {"kind": "L", "map": 0.0, "laplace_std": 1.0}
        names.append(extra)
    matrix = np.eye(len(names))
    matrix[0, 1] = matrix[1, 0] = RHO
    document = {
        "units": {"length": length, "angle": "rad"},
        "parameters": parameters,
        "correlation": {"names": names, "matrix": matrix.tolist()},
    }
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
    run = run_bcad("posterior", problem, "--value", "unknown.tx=2.7", "--calibration", result, "--json")
    assert run.returncode == 0, run.stderr
    document = json.loads(run.stdout)
    assert "note:" in run.stderr and "c.tx" in run.stderr
    assert document["calibration"][0]["not_applied"] == ["c.tx"]
    assert document["posterior"]["links"]["measured"]["std"][0] == pytest.approx(math.sqrt(0.022), rel=0.01)


def test_a_parameter_calibrated_twice_is_refused_at_the_problem_s_entry(tmp_path, write_problem):
    """The same result in calibration: and again with --calibration was refused naming the result
    file alone, with no line: now at the problem's calibration: entry (exit 2), said to be given
    twice; two results of one parameter are named both; given twice on the command line, where no
    problem line names it, at the result file."""
    result, other = _result(tmp_path), _result(tmp_path, "m", 0.001)
    problem = write_problem(TWO_L + f"calibration: ['{result}']\n")
    line = next(k for k, text in enumerate(problem.read_text().splitlines(), 1) if text.startswith("calibration:"))
    run = run_bcad("posterior", problem, "--value", "unknown.tx=2.7", "--calibration", result)
    assert run.returncode == 2 and "Traceback" not in run.stderr
    assert run.stderr.startswith(f"{problem}:{line}:15: ") and " is given twice; " in run.stderr, run.stderr
    assert "give each parameter one result" in run.stderr
    run = run_bcad("posterior", problem, "--value", "unknown.tx=2.7", "--calibration", other)
    assert run.returncode == 2
    assert run.stderr.startswith(f"{problem}:{line}:15: 'a.tx' is calibrated by both "), run.stderr
    bare = write_problem(TWO_L)
    run = run_bcad("posterior", bare, "--value", "unknown.tx=2.7", "--calibration", result, "--calibration", result)
    assert run.returncode == 2 and run.stderr.startswith(f"{result.absolute()}: "), run.stderr
    assert " is given twice; give each parameter one result" in run.stderr


def test_the_nominal_answer_takes_the_calibrated_robot(tmp_path, write_problem):
    """The nominal backend ignores uncertainty but not what was measured: a calibrated L is at its
    MAP (a + b = 0.3 mm), so X closes Q = 3 at 2.7 (at 3.0 it took the file's poses, and the
    closing link missed by 0.3 mm, 3 of its std); an L no calibration names stays at the file's."""
    result = _result(tmp_path)
    problem = write_problem(TWO_L + f"calibration: ['{result}']\n")
    run = run_bcad("solve", problem, "--backend", "nominal", "--quiet", "--samples", "20000")
    assert run.returncode == 0, run.stderr
    document = json.loads(run.stdout)
    assert document["solution"]["unknown.tx"] == pytest.approx(2.7, abs=1e-6)
    assert document["posterior"]["links"]["measured"]["mean"][0] == pytest.approx(3.0, abs=0.01)
    plain = run_bcad("solve", write_problem(TWO_L), "--backend", "nominal", "--quiet", "--samples", "20000")
    assert json.loads(plain.stdout)["solution"]["unknown.tx"] == pytest.approx(3.0, abs=1e-6)


@pytest.mark.parametrize(
    "mutate, message, at",
    [
        (lambda d: d.update(parameters=[1, 2]), "no 'parameters' mapping", None),
        (
            lambda d: d["parameters"]["a.tx"].update(laplace_std=-1.0),
            "expected a positive number",
            '"laplace_std": -1.0',
        ),
        (lambda d: d["parameters"]["a.tx"].update(map=float("nan")), "finite number", '"map": NaN'),
        (lambda d: [d["parameters"]["a.tx"].pop(k) for k in ("map", "estimate")], "map of 'a.tx' is None", '"a.tx": {'),
        (lambda d: d["correlation"].update(matrix=[[1, 2], [2, 1]]), "entries in [-1, 1]", '"matrix": ['),
        (lambda d: d["correlation"].update(matrix=[[1, 1], [-1, 1]]), "not symmetric", '"matrix": ['),
        (lambda d: d["correlation"].update(matrix=[[1, "x"], ["x", 1]]), "a correlation is 'x'", '"x"'),
        (lambda d: d["correlation"].update(names=["a.tx", "c.tx"]), "the correlation names 'c.tx'", '"c.tx"'),
        (lambda d: d.update(units={"length": "furlong"}), "units", '"units": {'),
        (lambda d: d.update(units="mm"), "units", '"units": "mm"'),
        (lambda d: d.update(parameters={}), "names no parameters", '"parameters": {}'),
        (
            lambda d: d["parameters"]["a.tx"].update(laplace_std=1e-300),
            "positive number that is in [1e-12, ",
            '"laplace_std": 1e-300',
        ),
        # without its correlations the parameters would be taken as independent (0.361 for 0.148)
        (lambda d: d.pop("correlation"), "names 2 parameters and no 'correlation'", None),
        (lambda d: d.update(kind="solve"), "is a result of kind 'solve'", '"kind": "solve"'),
    ],
)
def test_a_bad_calibration_result_is_an_input_error(tmp_path, write_problem, mutate, message, at):
    """Refused, at the line and column of the value that is wrong where the file has it."""
    path = _result(tmp_path)
    document = json.loads(path.read_text())
    mutate(document)
    path.write_text(json.dumps(document, indent=1))
    problem = write_problem(TWO_L + f"calibration: ['{path}']\n")
    with pytest.raises(InputError, match=message.replace("[", r"\[").replace("]", r"\]")) as refused:
        compile_problem(load_problem(problem))
    if at is None:
        assert refused.value.line is None
    else:
        line = path.read_text().splitlines()[refused.value.line - 1]
        assert at in line, line
        value = at.split(": ", 1)[-1]  # the column is where the value starts
        assert line[refused.value.column - 1 :].startswith(value), (line, refused.value.column)
    run = run_bcad("validate", problem)
    assert run.returncode == 2 and "Traceback" not in run.stderr


def test_an_output_never_replaces_a_calibration_result(tmp_path, write_problem):
    result = _result(tmp_path)
    before = result.read_bytes()
    run = run_bcad("solve", write_problem(TWO_L), "--calibration", result, "-o", result, "--quiet")
    assert run.returncode == 2 and result.read_bytes() == before


# --- Measure, then plan, end to end: problems/calibration/ur5_drill_plan.yaml -----------------

CALIBRATION = REPO / "problems" / "calibration"


def _rotation(rx: float, ry: float, rz: float) -> np.ndarray:
    """URDF rpy: Rz(rz) Ry(ry) Rx(rx), for each of N draws (arrays broadcast)."""
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    return np.stack(
        [
            np.stack([cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx], -1),
            np.stack([sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx], -1),
            np.stack([-sy, cy * sx, cy * cx], -1),
        ],
        -2,
    )


def _transform(translation, rotation) -> np.ndarray:
    n = len(rotation)
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = rotation
    T[:, :3, 3] = translation
    return T


def drill_tip(problem: dict, joints: np.ndarray, deviation: dict[str, np.ndarray], n: int) -> np.ndarray:
    """The drill tip in the tracker frame for N draws of the L deviations: classic DH written out
    here, T_i = Rz(theta + q + dtheta) Trans(a + da, 0, d + dd) Ry(beta) Rx(alpha + dalpha), the
    base's pose and the tip's offset (independent of bcad's kinematics)."""

    def dev(name):
        return deviation.get(name, np.zeros(n))

    robot = problem["robots"][0]
    base = [robot["pose"][k] + dev(f"ur5/base.{p}") for k, p in enumerate(("tx", "ty", "tz", "rx", "ry", "rz"))]
    T = _transform(np.stack(base[:3], -1), _rotation(*base[3:]))
    for i, row in enumerate(robot["dh"]):
        joint = f"ur5/joint_{i + 1}"
        theta = row["theta"] + joints[i] + dev(f"{joint}/zero.rz")
        turn = _transform(np.zeros((n, 3)), _rotation(np.zeros(n), np.zeros(n), theta))
        offset = np.stack([row["a"] + dev(f"{joint}/dh.tx"), np.zeros(n), row["d"] + dev(f"{joint}/dh.tz")], -1)
        tilt = _transform(offset, _rotation(row["alpha"] + dev(f"{joint}/dh.rx"), dev(f"{joint}/dh.ry"), np.zeros(n)))
        T = T @ turn @ tilt
    tip = np.stack(
        [20.0 + dev("smr_mount.tx"), 40.0 + dev("smr_mount.ty"), 120.0 + dev("smr_mount.tz"), np.ones(n)], -1
    )
    return np.einsum("nij,nj->ni", T, tip)[:, :3]


def test_the_committed_calibration_is_what_calibrate_writes(tmp_path):
    out = tmp_path / "fresh.json"
    run = run_bcad("calibrate", CALIBRATION / "ur5_tracker.yaml", "-o", out, "--quiet")
    assert run.returncode == 0, run.stderr
    assert_committed_calibration(out, CALIBRATION / "ur5_calibration.json")


def test_calibrate_then_plan_matches_an_independent_propagation_of_the_full_covariance(tmp_path):
    """The plan's Table 2 std of the drill tip (prior propagation at X*) against a Monte Carlo of
    the calibration's joint posterior (map, laplace_std and correlation read here) through the
    DH chain written out above: within 3 se. The same propagation with the correlations dropped
    gives another answer, as do the file's own placeholder distributions."""
    out = tmp_path / "plan.json"
    run = run_bcad("solve", CALIBRATION / "ur5_drill_plan.yaml", "--seed", "0", "-o", out)
    assert run.returncode == 0, run.stderr
    document = json.loads(out.read_text())
    assert not document["calibration"][0]["not_applied"] and len(document["calibration"][0]["applied"]) == 29
    link = document["posterior"]["links"]["drill"]
    problem = yaml.safe_load((CALIBRATION / "ur5_drill_plan.yaml").read_text())
    joints = np.array([document["solution"][f"ur5/joint_{i}.rz"] for i in range(1, 7)])
    result = json.loads((CALIBRATION / "ur5_calibration.json").read_text())
    names = list(result["parameters"])
    nominal = {f"ur5/base.{p}": v for p, v in zip(("tx", "ty", "tz", "rx", "ry", "rz"), problem["robots"][0]["pose"])}
    mean = np.array([result["parameters"][k]["map"] - nominal.get(k, 0.0) for k in names])  # X there: a value
    std = np.array([result["parameters"][k]["laplace_std"] for k in names])
    order = [result["correlation"]["names"].index(k) for k in names]
    correlation = np.array(result["correlation"]["matrix"])[np.ix_(order, order)]
    n = 200_000
    rng = np.random.default_rng(11)

    def spread(covariance):
        draws = rng.multivariate_normal(mean, covariance, size=n, method="eigh")
        tip = drill_tip(problem, joints, {k: draws[:, j] for j, k in enumerate(names)}, n)
        return tip.std(axis=0)

    independent = spread(correlation * np.outer(std, std))
    for k in range(3):
        se = math.hypot(link["std_se"][k], independent[k] / math.sqrt(2 * n))
        assert abs(link["std"][k] - independent[k]) < 3 * se, (k, link["std"][k], independent[k])
    uncorrelated = spread(np.diag(std**2))
    assert np.max(np.abs(uncorrelated / independent[:3] - 1)) > 0.2  # the correlations matter here
    # The contributors' linearised std is J Sigma J^T with the calibration's correlations (it was
    # sum J^2 Var, 65 times too large: 1.59 mm for 0.024), and the shares still sum to 1.
    for k, parameter in enumerate(("tx", "ty", "tz")):
        entry = document["contributors"]["drill"][parameter]
        assert abs(entry["std"] / independent[k] - 1) < 0.03, (parameter, entry["std"], independent[k])
        assert sum(entry["by_robot"].values()) == pytest.approx(1.0, abs=1e-9)
        assert sum(entry["by_link"].values()) == pytest.approx(1.0, abs=1e-9)
