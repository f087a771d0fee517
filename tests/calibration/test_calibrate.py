"""Calibration: synthetic measurements of a known RX90 cell, against the truth."""

from __future__ import annotations

import json
import sys
from dataclasses import replace

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from bcad.bayes.linear import free_parameter_moments
from bcad.calibration.model import CalibrationModel
from bcad.calibration.priors import parameter_priors
from bcad.calibration.solve import calibrate
from bcad.cli import app
from bcad.compiler import compile_problem
from bcad.kinematics import Samples
from bcad.model import load_problem
from bcad.model.pose import PARAMETERS

from conftest import REPO, RX90_URDF

runner = CliRunner()
NOISE = 0.05  # mm, a laser tracker's
CELL = {
    "name": "rx90-calibration",
    "units": {"length": "mm"},
    "frames": ["world", "tool"],
    "robots": [
        {
            "name": "arm",
            "urdf": str(RX90_URDF),
            "parent": "world",
            "status": "LLLLLL",
            "distributions": {
                "tx": "normal(0, 0.5)",
                "ty": "normal(0, 0.5)",
                "tz": "normal(0, 0.5)",
                "rx": "normal(0, 0.001)",
                "ry": "normal(0, 0.001)",
                "rz": "normal(0, 0.001)",
            },
            "joints": {"default": {"status": "X", "zero": "normal(0, 0.002)"}},
        }
    ],
    "links": [
        {
            "name": "mount",
            "parent": "arm/link_6",
            "child": "tool",
            "pose": [0, 0, 100, 0, 0, 0],
            "status": "LLLFFF",
            "distributions": {"tx": "normal(0, 0.2)", "ty": "normal(0, 0.2)", "tz": "normal(0, 0.2)"},
        }
    ],
}
JOINTS = [f"arm/joint_{k}" for k in range(1, 7)]


def _measurement(rows, noise=NOISE):
    return {
        "name": "tracker",
        "frame": "tool",
        "reference": "world",
        "parameters": "tx,ty,tz",
        "noise": f"normal(0, {noise})",
        "rows": rows,
    }


#: joint-origin errors of the RX90 (the URDF counterpart of DH errors)
ORIGIN_ERRORS = {
    "tx": "normal(0, 0.3)",
    "ty": "normal(0, 0.3)",
    "tz": "normal(0, 0.3)",
    "rx": "normal(0, 0.001)",
    "ry": "normal(0, 0.001)",
}


def _cell(origin_errors: bool) -> dict:
    if not origin_errors:
        return CELL
    robot = {
        **CELL["robots"][0],
        "joints": {"default": {"status": "X", "zero": "normal(0, 0.002)", "origin_error": ORIGIN_ERRORS}},
    }
    return {**CELL, "robots": [robot]}


def synthetic(
    tmp_path, seed: int, count: int = 30, noise: float = NOISE, stated_noise: float = NOISE, origin_errors: bool = False
):
    """A cell whose true L is drawn from the prior, measured at ``count`` random configurations."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(-1.5, 1.5, size=(count, 6))
    placeholder = [{"joints": dict.fromkeys(JOINTS, 0.0), "values": [0.0, 0.0, 0.0]}]
    path = tmp_path / f"cell{seed}.yaml"
    cell = _cell(origin_errors)
    path.write_text(yaml.safe_dump({**cell, "measurements": [_measurement(placeholder)]}))
    compiled = compile_problem(load_problem(path))
    mean, variance = free_parameter_moments(compiled)
    truth = mean + np.sqrt(variance) * rng.standard_normal(len(mean))
    chain = CalibrationModel(compiled).measurements[0].chain
    true_positions = chain.evaluate(q, Samples(np.repeat(truth[None], count, axis=0))).poses()[:, :3]
    measured = true_positions + rng.normal(0.0, noise, true_positions.shape)
    rows = [
        {"joints": dict(zip(JOINTS, map(float, q[r]))), "values": list(map(float, measured[r]))} for r in range(count)
    ]
    path.write_text(yaml.safe_dump({**cell, "measurements": [_measurement(rows, stated_noise)]}))
    return path, truth, q, measured


def test_estimates_are_within_three_std_of_the_truth_and_degeneracies_are_flagged(tmp_path):
    path, truth, _, _ = synthetic(tmp_path, 0)
    cal = calibrate(compile_problem(load_problem(path)))
    z = (cal.estimate - truth) / cal.std
    assert np.all(np.abs(z[cal.identified]) < 3.0)
    assert cal.identified.sum() >= 12
    # A position-only tracker cannot see joint 6's zero (the tool lies on its axis), nor tell the
    # base's rz from joint 1's zero: both combinations are flagged and stay at their prior.
    combinations = [set(combination) for _, combination in cal.unobservable]
    assert {"arm/joint_6/zero.rz"} in combinations
    assert {"arm/base.rz", "arm/joint_1/zero.rz"} in combinations
    names = cal.names
    assert not cal.identified[names.index("arm/joint_6/zero.rz")]
    assert abs(cal.estimate[names.index("arm/joint_6/zero.rz")]) < 1e-6
    # The residuals shrink to the noise.
    assert np.sqrt(np.mean(cal.residuals_after**2)) < 1.5
    assert np.sqrt(np.mean(cal.residuals_before**2)) > 5


@pytest.mark.parametrize("origin_errors", [False, True], ids=["zeros", "zeros-and-origin-errors"])
def test_reported_standard_deviations_are_honest(tmp_path, origin_errors):
    z = []
    for seed in range(50):
        path, truth, _, _ = synthetic(tmp_path, seed, count=60 if origin_errors else 30, origin_errors=origin_errors)
        cal = calibrate(compile_problem(load_problem(path)))
        z.extend(((cal.estimate - truth) / cal.std)[cal.identified])
    z = np.array(z)
    assert abs(z.mean()) < 0.15
    assert 0.8 < z.std() < 1.25


def test_csv_data_give_the_same_calibration(tmp_path):
    path, _, q, measured = synthetic(tmp_path, 3)
    inline = calibrate(compile_problem(load_problem(path)))
    lines = [",".join(JOINTS + ["tx", "ty", "tz"])] + [
        ",".join(repr(float(v)) for v in [*q[r], *measured[r]]) for r in range(len(q))
    ]
    (tmp_path / "tracker.csv").write_text("\n".join(lines) + "\n")
    document = yaml.safe_load(path.read_text())
    measurement = document["measurements"][0]
    del measurement["rows"]
    measurement["data"] = "tracker.csv"
    path.write_text(yaml.safe_dump(document))
    from_csv = calibrate(compile_problem(load_problem(path)))
    np.testing.assert_allclose(from_csv.estimate, inline.estimate, rtol=0, atol=1e-12)


def test_rows_inline_and_a_csv_together_are_refused_at_the_rows(tmp_path):
    """The inline rows were silently dropped where data: named a CSV too."""
    path, _, q, measured = synthetic(tmp_path, 5, count=3)
    (tmp_path / "tracker.csv").write_text(
        ",".join(JOINTS + ["tx", "ty", "tz"]) + "\n" + ",".join(repr(float(v)) for v in [*q[0], *measured[0]]) + "\n"
    )
    document = yaml.safe_load(path.read_text())
    document["measurements"][0]["data"] = "tracker.csv"
    path.write_text(yaml.safe_dump(document, sort_keys=False))
    line = next(k for k, text in enumerate(path.read_text().splitlines(), 1) if text.strip().startswith("rows:"))
    for command in ("calibrate", "validate"):
        result = runner.invoke(app, [command, str(path)])
        assert result.exit_code == 2, result.output
        assert f"{path}:{line + 1}:3: measurements[0].rows: " in result.stderr  # the rows themselves
        assert "both inline rows and data: 'tracker.csv'; expected one of them" in result.stderr


def test_a_noise_understated_by_a_few_times_is_a_misfit_though_the_rms_is_below_three(tmp_path):
    """The misfit warning fired on an RMS above 3 alone: 30 tracker rows (90 values) whose noise
    is stated 2.5 times too small end near an RMS of 2.5 with stds 2.5 times too small, and
    exited 0. Their chi-square (about 90 x 6) is far beyond the upper 1e-3 point of a chi-square
    on 90 degrees of freedom (137), which a model with its noise right exceeds once in 1000."""
    path, _, _, _ = synthetic(tmp_path, 6, stated_noise=NOISE / 2.5)
    result = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet"])
    document = json.loads(result.stdout)
    assert 1.5 < document["residuals"]["rms_whitened_after"] < 3.0
    assert result.exit_code == 3 and [w["code"] for w in document["warnings"]] == ["misfit"]
    assert "chi-square" in document["warnings"][0]["message"] and "on 90 values" in document["warnings"][0]["message"]


def test_the_misfit_bound_is_the_chi_square_quantile_and_rarely_fires_on_a_right_noise(tmp_path):
    """Wilson and Hilferty's bound against scipy's chi-square quantile, and ten cells whose noise is
    stated right: none is a misfit (each would be with probability below 1e-3)."""
    from scipy.stats import chi2

    from bcad.calibration.report import MISFIT_PROBABILITY, chi_square_bound

    for k in (1, 2, 3, 10, 90, 1000, 100000):
        exact = chi2.isf(MISFIT_PROBABILITY, k)
        assert exact <= chi_square_bound(k) <= exact * (1.031 if k < 10 else 1.01)
    for seed in range(10, 20):
        path, _, _, _ = synthetic(tmp_path, seed, count=12)
        result = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet", "--check-samples", "0"])
        assert result.exit_code == 0 and json.loads(result.stdout)["warnings"] == [], result.output
    # 3000 values: a noise stated 4 % too small (stds 4 % too small) passes the test's RMS floor of
    # 1.1, though its chi-square is beyond the bound; stated 30 % too small, it is a misfit
    for understated, code in ((1.04, 0), (1.3, 3)):
        path, _, _, _ = synthetic(tmp_path, 21, count=1000, stated_noise=NOISE / understated)
        result = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet", "--check-samples", "0"])
        document = json.loads(result.stdout)
        rms = document["residuals"]["rms_whitened_after"]
        assert result.exit_code == code, (understated, rms, document["warnings"])
        if code == 0:
            assert rms**2 * 3000 > chi_square_bound(3000)  # the chi-square alone would have fired


def test_the_robust_answer_is_the_fit_of_the_inliers_alone(tmp_path):
    """Huber's linear tail pulled on the answer from every outlier (a force c each, however far)
    and counted them as data in the covariance: with 3 of 30 rows moved by 80-120 noise stds, the
    answer and its stds were not those of the clean rows. Now both equal the plain least-squares
    fit of the file with the outliers deleted."""
    path, _, _, _ = synthetic(tmp_path, 8)
    document = yaml.safe_load(path.read_text())
    rows = document["measurements"][0]["rows"]
    rng = np.random.default_rng(3)
    moved = [4, 11, 23]
    for r in moved:
        rows[r]["values"] = [v + float(rng.choice([-1, 1]) * rng.uniform(80, 120) * NOISE) for v in rows[r]["values"]]
    path.write_text(yaml.safe_dump(document))
    robust = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet", "--robust", "--check-samples", "0"])
    assert robust.exit_code == 0, robust.output
    robust = json.loads(robust.stdout)
    assert sorted(outlier["row"] for outlier in robust["robust"]["outliers"]) == [r + 1 for r in moved]
    document["measurements"][0]["rows"] = [row for r, row in enumerate(rows) if r not in moved]
    path.write_text(yaml.safe_dump(document))
    clean = json.loads(runner.invoke(app, ["calibrate", str(path), "--json", "--quiet", "--check-samples", "0"]).stdout)
    for name, parameter in clean["parameters"].items():
        other = robust["parameters"][name]
        assert other["estimate"] == pytest.approx(parameter["estimate"], rel=1e-6, abs=1e-6 * parameter["std"])
        assert other["std"] == pytest.approx(parameter["std"], rel=1e-6)


def test_the_robust_outliers_are_the_rows_beyond_the_threshold_at_the_answer(tmp_path):
    """Rows moved by 2.5-4 times a normal noise draw sit near the threshold: flagged once at the Huber answer, a row
    kept as an inlier ended beyond it at the inliers' fit (seed 0's row 24: d 4.11 > c 4.03). The
    outliers listed are now exactly the rows beyond c at the answer."""
    from scipy.stats import chi

    threshold = chi.ppf(0.999, 3)
    for seed in range(12):
        path, _, _, _ = synthetic(tmp_path, seed)
        document = yaml.safe_load(path.read_text())
        rows = document["measurements"][0]["rows"]
        rng = np.random.default_rng(100 + seed)
        for r in rng.choice(len(rows), 4, replace=False):
            rows[r]["values"] = [v + float(rng.normal()) * rng.uniform(2.5, 4.0) * NOISE for v in rows[r]["values"]]
        path.write_text(yaml.safe_dump(document))
        compiled = compile_problem(load_problem(path))
        model = CalibrationModel(compiled)
        cal = calibrate(compiled, model, robust=True)
        distances = np.linalg.norm(model.residuals(cal.estimate).reshape(-1, 3), axis=1)
        assert {o.row for o in cal.outliers} == {r + 1 for r in np.flatnonzero(distances > threshold)}, seed
        for outlier in cal.outliers:
            assert outlier.distance == pytest.approx(distances[outlier.row - 1], rel=1e-9)


@pytest.mark.parametrize(("corrupted", "broken"), [(0.3, False), (0.6, True)])
def test_a_robust_fit_that_calls_most_rows_outliers_is_not_trusted(tmp_path, corrupted, broken):
    """With 30 % of the rows moved by tens of millimetres the robust loss flags them and the rest
    fit; with 60 % it follows the few and calls most rows outliers, which the misfit of the inliers
    alone cannot see: the warning robust_breakdown and exit 3."""
    path, _, _, _ = synthetic(tmp_path, 7, count=20)
    document = yaml.safe_load(path.read_text())
    rows = document["measurements"][0]["rows"]
    rng = np.random.default_rng(1)
    moved = rng.choice(len(rows), int(corrupted * len(rows)), replace=False)
    for r in moved:
        rows[r]["values"] = [v + float(rng.normal(0.0, 30.0)) for v in rows[r]["values"]]
    path.write_text(yaml.safe_dump(document))
    result = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet", "--robust", "--check-samples", "0"])
    found = json.loads(result.stdout)
    codes = [warning["code"] for warning in found["warnings"]]
    flagged = {outlier["row"] for outlier in found["robust"]["outliers"]}
    if broken:
        assert result.exit_code == 3 and "robust_breakdown" in codes and len(flagged) > 10
    else:
        assert result.exit_code == 0, codes
        assert {int(r) + 1 for r in moved} <= flagged and len(flagged) <= len(moved) + 1


@pytest.mark.parametrize("angle", ["deg", "rad"])
def test_an_angle_measured_in_degrees_has_its_noise_in_degrees(tmp_path, angle):
    """A gyro reading a one-joint arm's rz twice (noise 0.01, prior of the zero 1, in the
    problem's angle unit): the conjugate Gaussian update gives the zero's posterior exactly. In
    degrees the noise was read as radians, 57 times too loose (0.43 +- 0.375 deg)."""
    path = _one_link_cell(
        tmp_path,
        f"{{length: m, angle: {angle}}}",
        "{a: 1.0, alpha: 0, d: 0, theta: 0, limits: [-1.5, 1.5]}",
        "{zero: 'normal(0, 1)'}",
        "rz",
        "normal(0, 0.01)",
        "      - {joints: {arm/joint_1: 0}, values: [0.5]}\n      - {joints: {arm/joint_1: 1}, values: [1.5]}",
    )
    result = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet"])
    assert result.exit_code == 0, result.output
    found = json.loads(result.stdout)["parameters"]["arm/joint_1/zero.rz"]
    precision = 1 / 1.0**2 + 2 / 0.01**2  # the prior's and the two readings' (each 0.5 off)
    assert found["estimate"] == pytest.approx((2 * 0.5 / 0.01**2) / precision, rel=1e-6)
    assert found["std"] == pytest.approx(precision**-0.5, rel=1e-4)


def _one_link_cell(tmp_path, units: str, row: str, errors: str, parameters: str, noise: str, rows: str):
    """A one-joint DH arm (``row``, its joint's ``errors``) whose tool is read by one sensor."""
    path = tmp_path / "one_link.yaml"
    path.write_text(
        f"""name: one-link
units: {units}
frames: [base, tool]
robots:
  - name: arm
    parent: base
    dh:
      - {row}
    joints:
      default: {{status: X}}
      joint_1: {errors}
links:
  - {{name: flange, parent: arm/link_1, child: tool, pose: [0, 0, 0, 0, 0, 0]}}
measurements:
  - name: sensor
    frame: tool
    reference: base
    parameters: {parameters}
    noise: {noise}
    rows:
{rows}
"""
    )
    return path


def _one_link_tracker(tmp_path, noise: str, readings: list[tuple[float, float, float]]):
    rows = "\n".join(f"      - {{joints: {{arm/joint_1: {q}}}, values: [{tx!r}, {ty!r}]}}" for q, tx, ty in readings)
    return _one_link_cell(
        tmp_path,
        "{length: mm, angle: rad}",
        "{a: 1000, alpha: 0, d: 0, theta: 0, limits: [-3, 3]}",
        "{dh_error: {a: 'normal(0, 2)'}}",
        "tx,ty",
        noise,
        rows,
    )


def test_a_uniform_noise_is_weighed_by_its_own_density_in_the_check(tmp_path):
    """A tracker with uniform noise of half width 0.1 mm reads a one-link arm whose length error
    is 0.75 mm. The exact posterior is the prior N(0, 2^2) cut to the interval every reading
    allows (closed form, a truncated normal); the check, which weighs the readings by the uniform,
    finds its mean, and says the Laplace answer (the moment-matched Gaussian's) is not it. A
    reading 0.3 mm off makes the data impossible: no draw weighs anything, and the warning says so."""
    from scipy.stats import truncnorm

    rng = np.random.default_rng(0)  # an interval off the least-squares answer: 0.707-0.779 about 0.753
    angles = np.array([0.0, 0.4, 0.9, 1.3, -0.6])
    errors = rng.uniform(-0.08, 0.08, (len(angles), 2))
    readings = [
        (float(q), float(1000.75 * np.cos(q) + e[0]), float(1000.75 * np.sin(q) + e[1])) for q, e in zip(angles, errors)
    ]
    path = _one_link_tracker(tmp_path, "uniform(-0.1, 0.1)", readings)
    result = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet", "--check-samples", "4000"])
    document = json.loads(result.stdout)
    # each reading m of a coordinate c (cos q or sin q) of 1000 + a: a within (m -+ 0.1) / c - 1000
    low, high = -np.inf, np.inf
    for q, tx, ty in readings:
        for measured, factor in ((tx, np.cos(q)), (ty, np.sin(q))):
            if abs(factor) > 1e-9:
                ends = sorted(((measured - 0.1) / factor - 1000.0, (measured + 0.1) / factor - 1000.0))
                low, high = max(low, ends[0]), min(high, ends[1])
    exact = truncnorm(low / 2.0, high / 2.0, loc=0.0, scale=2.0)
    check = document["check"]["parameters"]["arm/joint_1/dh.tx"]
    assert abs(check["mean"] - exact.mean()) < 4 * check["mean_se"], (check, exact.mean(), low, high)
    assert check["std"] == pytest.approx(exact.std(), rel=0.1)
    assert "not_gaussian" in [w["code"] for w in document["warnings"]]  # the Laplace mean is 0.753
    impossible = [(q, tx + (0.3 if k == 2 else 0.0), ty) for k, (q, tx, ty) in enumerate(readings)]
    path = _one_link_tracker(tmp_path, "uniform(-0.1, 0.1)", impossible)
    result = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet"])
    assert result.exit_code == 3
    (warning,) = [w for w in json.loads(result.stdout)["warnings"] if w["code"] == "laplace_unchecked"]
    assert "impossible under the noise the problem gives" in warning["message"]


def test_a_csv_of_a_header_alone_is_refused_at_its_second_line(tmp_path):
    """It was refused at the measurement with "give rows: or data:", though data: was given."""
    path, _, _, _ = synthetic(tmp_path, 4, count=3)
    (tmp_path / "empty.csv").write_text(",".join(JOINTS + ["tx", "ty", "tz"]) + "\n")
    document = yaml.safe_load(path.read_text())
    del document["measurements"][0]["rows"]
    document["measurements"][0]["data"] = "empty.csv"
    path.write_text(yaml.safe_dump(document))
    result = runner.invoke(app, ["calibrate", str(path)])
    assert result.exit_code == 2
    assert f"{tmp_path / 'empty.csv'}:2:1: a header and no rows; expected a row per reading" in result.stderr


def test_csv_errors_are_located(tmp_path):
    path, _, q, measured = synthetic(tmp_path, 4, count=3)
    (tmp_path / "bad.csv").write_text(
        ",".join(JOINTS + ["tx", "ty", "tz"]) + "\n" + "0,0,0,0,0,0,1,2,3\n" + "0,0,0,0,abc,0,1,2,3\n"
    )
    document = yaml.safe_load(path.read_text())
    del document["measurements"][0]["rows"]
    document["measurements"][0]["data"] = "bad.csv"
    path.write_text(yaml.safe_dump(document))
    result = runner.invoke(app, ["calibrate", str(path)])
    assert (
        result.exit_code == 2
        and f"{tmp_path / 'bad.csv'}:3:9: 'abc' in column 'arm/joint_5' is not a number" in result.stderr
    )


def test_an_unknown_joint_column_is_placed_at_its_name_in_the_header(tmp_path):
    """The fault is the column's name, not a row's value: the error is at the header's cell."""
    path, _, _, _ = synthetic(tmp_path, 4, count=3)
    columns = JOINTS[:2] + ["arm/joint3"] + JOINTS[3:] + ["tx", "ty", "tz"]
    (tmp_path / "bad.csv").write_text(",".join(columns) + "\n" + "0,0,0,0,0,0,1,2,3\n")
    document = yaml.safe_load(path.read_text())
    del document["measurements"][0]["rows"]
    document["measurements"][0]["data"] = "bad.csv"
    path.write_text(yaml.safe_dump(document))
    result = runner.invoke(app, ["calibrate", str(path)])
    column = len(",".join(JOINTS[:2])) + 2
    assert result.exit_code == 2
    assert f"{tmp_path / 'bad.csv'}:1:{column}: unknown joint(s) 'arm/joint3'" in result.stderr
    # the same in a candidates file of --propose
    (tmp_path / "c.csv").write_text(",".join(columns[:6]) + "\n" + "0,0,0,0,0,0\n")
    document["measurements"][0]["data"] = "good.csv"
    (tmp_path / "good.csv").write_text(",".join(JOINTS + ["tx", "ty", "tz"]) + "\n" + "0,0,0,0,0,0,1,2,3\n" * 3)
    path.write_text(yaml.safe_dump(document))
    result = runner.invoke(app, ["calibrate", str(path), "--propose", "1", "--candidates", str(tmp_path / "c.csv")])
    assert result.exit_code == 2
    assert f"{tmp_path / 'c.csv'}:1:{column}: unknown joint(s) 'arm/joint3'" in result.stderr
    # a configurations file with a header and no rows, for --propose and for --predict: at its second line
    (tmp_path / "empty.csv").write_text(",".join(JOINTS) + "\n")
    for option in (["--propose", "1", "--candidates"], ["--predict"]):
        result = runner.invoke(
            app, ["calibrate", str(path), "--check-samples", "0", *option, str(tmp_path / "empty.csv")]
        )
        assert result.exit_code == 2
        assert (
            f"{tmp_path / 'empty.csv'}:2:1: a header and no rows; expected one configuration per row" in result.stderr
        )


@pytest.mark.parametrize(
    ("text", "place", "fragment"),
    [
        ("a,b,c\n1,2,x\n", "2:5", "'x' in column 'c' is not a number"),
        ("a,b,c\n1,  nan,3\n", "2:3", "'  nan' in column 'b' is not a finite number"),
        ("a,b,c\n1,2,3,4\n", "2:7", "4 cells, the header has 3"),
        ("a,b,c\n1,2\n", "2:4", "2 cells, the header has 3"),
        ("a,b,a\n", "1:5", "the header names the column 'a' twice"),
        ("", "1:1", "empty CSV file"),
        ("x,y\n", "1:1", "names none of the columns expected"),
        ("a,b,c\r\n\r\n1,2,inf\r\n", "3:5", "'inf' in column 'c' is not a finite number"),
        ("a,b,c\r1,2,3\r4,5,z\r", "3:5", "'z' in column 'c'"),
        ('a,b,c\n1,"2\n",3\n4,"5""",6\n', "4:3", "'5\"' in column 'b' is not a number"),
        ("\ufeffa,b,c\n1,b,3\n", "2:3", "'b' in column 'b'"),
        ("a,b,c\n1,2,3\n4," + "9" * 200_000 + ",6\n", "3:3", "field larger than field limit"),
    ],
)
def test_a_csv_error_names_the_line_and_column_of_its_cell(tmp_path, text, place, fragment):
    """CSV errors named a line only: each now names the 1-based column where the cell at fault
    starts (the end of a short row; a quoted cell's line ends count as lines)."""
    from bcad.calibration.model import read_csv_table
    from bcad.errors import InputError

    path = tmp_path / "data.csv"
    path.write_bytes(text.encode("utf-8"))
    with pytest.raises(InputError) as caught:
        read_csv_table(path, "a CSV file of measurements", ["a", "b", "c"])
    assert str(caught.value).startswith(f"{path}:{place}: ") and fragment in str(caught.value), caught.value


def test_cli_json_and_misfit(tmp_path):
    path, _, _, _ = synthetic(tmp_path, 5)
    result = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet"])
    assert result.exit_code == 0, result.output
    document = json.loads(result.stdout)
    assert document["warnings"] == [] and document["measurements"] == {"tracker": 30}
    after = document["residuals"]["after"]["tracker"]
    assert all(after[p]["rms"] < 2 * NOISE for p in ("tx", "ty", "tz"))
    # The noise understated a hundred times: the residuals cannot be explained, exit 3.
    path, _, _, _ = synthetic(tmp_path, 6, stated_noise=NOISE / 100)
    result = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet"])
    assert result.exit_code == 3 and json.loads(result.stdout)["warnings"][0]["code"] == "misfit"


def test_a_problem_without_measurements_is_refused(write_problem):
    from conftest import ONE_LINK_GRAPH

    result = runner.invoke(app, ["calibrate", str(write_problem(ONE_LINK_GRAPH))])
    assert result.exit_code == 2 and "measurements" in result.stderr


def test_solve_and_posterior_refuse_a_problem_with_measurements_rather_than_ignore_them(tmp_path):
    """A file with measurements and a relation was solved with its measurements
    silently ignored. solve, posterior (command and API) and batch now refuse it, exit 2, naming
    the measurements and bcad calibrate."""
    import bcad

    path = EXAMPLE / "rx90_sphere_touches.yaml"
    for command in (["solve", str(path)], ["posterior", str(path)]):
        result = runner.invoke(app, command)
        assert result.exit_code == 2, result.output
        assert "measurement" in result.stderr and "bcad calibrate" in result.stderr and "Traceback" not in result.stderr
    with pytest.raises(bcad.InputError, match="bcad calibrate"):
        bcad.posterior(path, values={})


def test_measurement_rows_beyond_the_joint_limits_are_refused(tmp_path):
    """Joint values the robot cannot reach were accepted silently. A row with joint 2
    at 3 rad (the RX90's limit: 2.4 rad) is refused, exit 2, with its line and the limits."""
    path, _, q, measured = synthetic(tmp_path, 4, count=3)
    lines = [",".join(JOINTS + ["tx", "ty", "tz"])] + [
        ",".join(repr(float(v)) for v in [*q[r], *measured[r]]) for r in range(3)
    ]
    cells = lines[2].split(",")
    cells[1] = "3.0"
    lines[2] = ",".join(cells)
    (tmp_path / "beyond.csv").write_text("\n".join(lines) + "\n")
    document = yaml.safe_load(path.read_text())
    del document["measurements"][0]["rows"]
    document["measurements"][0]["data"] = "beyond.csv"
    path.write_text(yaml.safe_dump(document))
    result = runner.invoke(app, ["calibrate", str(path)])
    assert result.exit_code == 2, result.output
    assert (
        f"{tmp_path / 'beyond.csv'}:3:{len(cells[0]) + 2}: joint arm/joint_2 = 3 is beyond its limits "
        "[-2.39983, 2.39983]" in result.stderr
    )
    # ... unless the measurement says so explicitly: then the row is used as given
    document["measurements"][0]["allow_outside_limits"] = True
    path.write_text(yaml.safe_dump(document))
    accepted = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet"])
    assert accepted.exit_code in (0, 3), accepted.output
    name = document["measurements"][0]["name"]
    assert json.loads(accepted.stdout)["measurements"] == {name: 3}
    # a candidate beyond the limits is a configuration the robot cannot go to: no setting accepts it
    (tmp_path / "candidates.csv").write_text(lines[0].rsplit(",", 3)[0] + "\n" + ",".join(cells[:6]) + "\n")
    result = runner.invoke(
        app,
        [
            "calibrate",
            str(path),
            "--check-samples",
            "0",
            "--propose",
            "1",
            "--candidates",
            str(tmp_path / "candidates.csv"),
        ],
    )
    assert result.exit_code == 2, result.output
    assert "joint arm/joint_2 = 3 is beyond its limits [-2.39983, 2.39983]" in result.stderr
    assert "the robot cannot go there" in result.stderr and "allow_outside_limits" not in result.stderr


# --- the UR5 given by DH rows (problems/calibration) -----------------------------------------

EXAMPLE = REPO / "problems" / "calibration"
sys.path.insert(0, str(EXAMPLE))
import ur5_truth  # noqa: E402

DH_KEYS = {"zero.rz": "theta", "dh.tx": "a", "dh.tz": "d", "dh.rx": "alpha", "dh.ry": "beta"}


def _ur5_truth_of(names: list[str], theta: np.ndarray) -> tuple[dict, np.ndarray, np.ndarray]:
    """The DH table, base pose and reflector offset that the parameter vector ``theta`` says."""
    dh = {key: np.array(ur5_truth.NOMINAL[key], dtype=float) for key in ur5_truth.NOMINAL}
    dh["beta"] = np.zeros(6)
    base, smr = ur5_truth.BASE_NOMINAL.copy(), ur5_truth.SMR_NOMINAL.copy()
    for name, value in zip(names, theta):
        if name.startswith("ur5/base."):
            base[PARAMETERS.index(name.rsplit(".", 1)[1])] = value
        elif name.startswith("smr_mount."):
            smr[PARAMETERS.index(name.rsplit(".", 1)[1])] += value
        else:
            joint, key = name.split("/")[1], name.split("/", 2)[2]
            dh[DH_KEYS[key]][int(joint.rsplit("_", 1)[1]) - 1] += value
    return dh, base, smr


def ur5_synthetic(tmp_path, seed: int, count: int = 30):
    """The example's model; a truth drawn from its priors (the base near its nominal pose),
    measured at ``count`` configurations through the plain DH product of ur5_truth.py."""
    rng = np.random.default_rng(seed)
    document = yaml.safe_load((EXAMPLE / "ur5_tracker.yaml").read_text())
    q = ur5_truth.configurations(rng, count)
    document["measurements"][0].pop("data")
    document["measurements"][0]["rows"] = [{"joints": dict.fromkeys(ur5_truth.JOINTS, 0.0), "values": [0.0, 0.0, 0.0]}]
    path = tmp_path / f"ur5_{seed}.yaml"
    path.write_text(yaml.safe_dump(document))
    model = CalibrationModel(compile_problem(load_problem(path)))
    priors = parameter_priors(model)
    truth = priors.mean + priors.std * rng.standard_normal(len(priors.mean))
    flat = ~priors.gaussian  # the base: near its nominal pose, well inside its bounds
    truth[flat] = priors.mean[flat] + np.where(np.arange(len(truth))[flat] % 6 < 3, 1.0, 0.002) * rng.standard_normal(
        flat.sum()
    )
    dh, base, smr = _ur5_truth_of(model.names, truth)
    measured = np.array([ur5_truth.reflector_in_tracker(row, dh, base, smr) for row in q]) + rng.normal(
        0, ur5_truth.NOISE, (count, 3)
    )
    document["measurements"][0]["rows"] = [
        {"joints": dict(zip(ur5_truth.JOINTS, map(float, q[r]))), "values": list(map(float, measured[r]))}
        for r in range(count)
    ]
    path.write_text(yaml.safe_dump(document))
    return path, truth


def test_ur5_full_dh_estimates_are_honest_over_50_seeds(tmp_path):
    z = []
    for seed in range(50):
        path, truth = ur5_synthetic(tmp_path, seed)
        cal = calibrate(compile_problem(load_problem(path)))
        scores = ((cal.estimate - truth) / cal.std)[cal.identified]
        assert np.all(np.abs(scores) < 4.5), (seed, scores)
        z.extend(scores)
    z = np.array(z)
    assert abs(z.mean()) < 0.1
    assert 0.8 < z.std() < 1.25


def test_the_ur5_example_flags_the_parallel_axes_and_its_urdf_reproduces_the_true_robot(tmp_path):
    result = runner.invoke(
        app, ["calibrate", str(EXAMPLE / "ur5_tracker.yaml"), "--json", "--quiet", "--urdf", str(tmp_path / "ur5.urdf")]
    )
    assert result.exit_code == 0, result.output
    document = json.loads(result.stdout)
    assert document["residuals"]["rms_whitened_after"] < 1.5
    assert document["check"]["trusted"] and document["check"]["disagree"] == []
    # The d errors of rows 2-4 slide along parallel axes: two combinations of them are unobservable.
    assert len(document["unobservable"]) == 2
    for entry in document["unobservable"]:
        assert set(entry["combination"]) <= {"ur5/joint_2/dh.tz", "ur5/joint_3/dh.tz", "ur5/joint_4/dh.tz"}
        assert 0.0 <= entry["information"] < 1e-6  # none: an information is never negative (rounding)
    parameters = document["parameters"]
    assert [parameters[f"ur5/joint_{k}/dh.tz"]["identified"] for k in (2, 3, 4)] == [False] * 3
    # X (the base in the tracker frame) read as the MAP, within 3 std of the truth.
    for k, name in enumerate(PARAMETERS):
        entry = parameters[f"ur5/base.{name}"]
        assert entry["kind"] == "X" and entry["reading"] == "MAP" and entry["prior"] == "flat"
        assert abs(entry["estimate"] - ur5_truth.BASE_TRUE[k]) < 3 * entry["std"]
    # The calibrated URDF loads in Pinocchio and yourdfpy, and with the calibrated base and
    # reflector it puts the reflector where the true robot does, at 100 new configurations.
    import pinocchio as pin
    import yourdfpy

    from bcad.kinematics.se3 import pose_to_matrix

    assert yourdfpy.URDF.load(
        str(tmp_path / "ur5.urdf"), build_scene_graph=False, load_meshes=False
    ).actuated_joint_names == [f"joint_{k}" for k in range(1, 7)]
    model = pin.buildModelFromUrdf(str(tmp_path / "ur5.urdf"))
    data = model.createData()
    base = pose_to_matrix(np.array([parameters[f"ur5/base.{p}"]["estimate"] for p in PARAMETERS]))
    smr = ur5_truth.SMR_NOMINAL + np.array([parameters[f"smr_mount.{p}"]["estimate"] for p in ("tx", "ty", "tz")])
    differences = []
    for q in ur5_truth.configurations(np.random.default_rng(2026), 100):
        pin.framesForwardKinematics(model, data, q)
        flange = data.oMf[model.getFrameId("link_6")].homogeneous.copy()
        flange[:3, 3] *= 1000.0
        differences.append((base @ flange @ np.append(smr, 1.0))[:3] - ur5_truth.reflector_in_tracker(q))
    errors = np.linalg.norm(differences, axis=1)
    # The noise is 0.05 mm per axis (0.08 mm in 3D): the calibrated robot is as good as the tracker,
    # within 0.05 mm RMS per axis (the MAP everywhere, no sampled L means mixed in).
    assert np.mean(errors) < 0.08 and np.max(errors) < 0.25
    assert np.sqrt(np.mean(np.square(differences))) < 0.05
    # Before calibration the nominal robot is millimetres off.
    nominal = [
        np.linalg.norm(
            ur5_truth.reflector_in_tracker(
                q, {k: np.array(v) for k, v in ur5_truth.NOMINAL.items()}, ur5_truth.BASE_NOMINAL, ur5_truth.SMR_NOMINAL
            )
            - ur5_truth.reflector_in_tracker(q)
        )
        for q in ur5_truth.configurations(np.random.default_rng(2026), 100)
    ]
    assert np.mean(nominal) > 1.0


def _same_table(a, b) -> None:
    first, second = a.read_text().splitlines(), b.read_text().splitlines()
    assert first[0] == second[0] and len(first) == len(second)
    np.testing.assert_allclose(
        np.loadtxt(a, delimiter=",", skiprows=1), np.loadtxt(b, delimiter=",", skiprows=1), rtol=0, atol=1e-8
    )


def test_the_example_data_are_what_its_script_writes(tmp_path):
    ur5_truth.write_csv(tmp_path / "data.csv")
    _same_table(tmp_path / "data.csv", EXAMPLE / "ur5_tracker.csv")


def test_touches_of_a_sphere_calibrate_the_probe_and_the_sphere(tmp_path):
    """problems/calibration/rx90_sphere_touches.yaml: a measurement in a sphere entity's frame reads
    spherical coordinates, a touch is tz = 0; every estimate within 3 std of the generator's truth."""
    import rx90_sphere_truth as truth

    rx90_sphere = EXAMPLE / "rx90_sphere_touches.yaml"
    truth.write_csv(tmp_path / "touches.csv", count=40, seed=11)
    _same_table(tmp_path / "touches.csv", EXAMPLE / "rx90_sphere_touches.csv")
    result = runner.invoke(app, ["calibrate", str(rx90_sphere), "--json", "--quiet"])
    assert result.exit_code == 0, result.output
    document = json.loads(result.stdout)
    expected = {
        "arm/joint_2/zero.rz": truth.ZEROS[1],
        "arm/joint_3/zero.rz": truth.ZEROS[2],
        "probe_mount.tx": truth.PROBE[0],
        "probe_mount.ty": truth.PROBE[1],
        "probe_mount.tz": truth.PROBE[2] - 120.0,
        "sphere_post.tx": truth.CENTRE[0] - 600.0,
        "sphere_post.ty": truth.CENTRE[1] - 100.0,
        "sphere_post.tz": truth.CENTRE[2] - 300.0,
    }
    assert set(document["parameters"]) == set(expected)
    for name, value in expected.items():
        entry = document["parameters"][name]
        assert entry["identified"] and abs(entry["estimate"] - value) < 3 * entry["std"], (name, entry, value)
    assert document["check"]["trusted"] and document["residuals"]["rms_whitened_after"] < 1.5


def test_the_robust_loss_finds_the_outliers(tmp_path):
    path, truth, q, measured = synthetic(tmp_path, 7)
    document = yaml.safe_load(path.read_text())
    rows = document["measurements"][0]["rows"]
    for r in (4, 17):
        rows[r]["values"][0] += 3.0  # 60 noise std: a bumped reflector
    path.write_text(yaml.safe_dump(document))
    result = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet"])
    assert result.exit_code == 3 and json.loads(result.stdout)["warnings"][0]["code"] == "misfit"
    result = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet", "--robust"])
    assert result.exit_code == 0, result.output
    document = json.loads(result.stdout)
    assert [(o["measurement"], o["row"]) for o in document["robust"]["outliers"]] == [("tracker", 5), ("tracker", 18)]
    cal = calibrate(compile_problem(load_problem(path)), robust=True)
    assert np.all(np.abs(((cal.estimate - truth) / cal.std)[cal.identified]) < 3.0)


def test_the_importance_check_finds_the_posterior_of_a_uniform_prior(tmp_path):
    """One angle, prior uniform(-0.01, 0.01), measured once at 0.02 with noise 0.005: the posterior
    is a normal truncated to the prior's support (closed form), which Laplace's Gaussian is not
    (its mean, 0.0114, is even outside the support)."""
    from scipy.stats import truncnorm

    document = {
        "name": "one-angle",
        "frames": ["a", "b"],
        "links": [
            {
                "name": "l",
                "parent": "a",
                "child": "b",
                "status": "FFFFFL",
                "distributions": {"rz": "uniform(-0.01, 0.01)"},
            }
        ],
        "measurements": [
            {
                "name": "m",
                "frame": "b",
                "reference": "a",
                "parameters": "rz",
                "noise": "normal(0, 0.005)",
                "rows": [{"joints": {}, "values": [0.02]}],
            }
        ],
    }
    path = tmp_path / "one.yaml"
    path.write_text(yaml.safe_dump(document))
    cal = calibrate(compile_problem(load_problem(path)), check_samples=20000, seed=1)
    exact = truncnorm((-0.01 - 0.02) / 0.005, (0.01 - 0.02) / 0.005, loc=0.02, scale=0.005)
    check = cal.check
    assert check.trusted
    assert abs(check.mean[0] - exact.mean()) < 3 * check.mean_se[0]
    assert abs(check.std[0] / exact.std() - 1) < 0.03
    # Laplace (the uniform's Gaussian surrogate) is off: the calibrated model stays the one Gaussian
    # (MAP and Laplace std), the sampled moments are reported beside it, and the
    # disagreement is a warning.
    assert check.disagreement(cal.estimate, cal.std) == [0]
    estimate, std = cal.answer()
    assert estimate[0] == cal.estimate[0] and std[0] == cal.std[0]
    result = runner.invoke(
        app, ["calibrate", str(path), "--json", "--quiet", "--check-samples", "20000", "--seed", "1"]
    )
    assert result.exit_code == 3
    document = json.loads(result.stdout)
    assert [w["code"] for w in document["warnings"]] == ["not_gaussian"] and "l.rz" in document["warnings"][0][
        "message"
    ]
    assert document["check"]["parameters"]["l.rz"]["mean"] == pytest.approx(check.mean[0])
    assert document["parameters"]["l.rz"]["estimate"] == pytest.approx(cal.estimate[0])


def test_proposed_configurations_are_the_most_informative(tmp_path):
    """The first proposal's entropy reduction is what adding that measurement and calibrating again gives."""
    path, _, _, _ = synthetic(tmp_path, 8, count=12)
    candidates = np.random.default_rng(80).uniform(-1.5, 1.5, size=(15, 6))
    lines = [",".join(JOINTS)] + [",".join(repr(float(v)) for v in row) for row in candidates]
    (tmp_path / "candidates.csv").write_text("\n".join(lines) + "\n")
    result = runner.invoke(
        app,
        [
            "calibrate",
            str(path),
            "--json",
            "--quiet",
            "--check-samples",
            "0",
            "--propose",
            "3",
            "--candidates",
            str(tmp_path / "candidates.csv"),
        ],
    )
    assert result.exit_code == 0, result.output
    ranked = json.loads(result.stdout)["proposal"]["ranked"]
    assert len({entry["row"] for entry in ranked}) == 3
    gains = [entry["entropy_reduction"] for entry in ranked]
    assert gains[0] >= gains[1] >= gains[2] > 0  # log det is submodular: greedy gains fall

    compiled = compile_problem(load_problem(path))
    before = calibrate(compiled)
    document = yaml.safe_load(path.read_text())
    model = CalibrationModel(compiled)
    reductions = []
    for row in candidates:
        predicted = model.with_measurements(
            [replace(model.measurements[0], x_rows=row[None], measured=np.zeros((1, 3)))]
        ).predictions(before.estimate[None])[0][0, 0]
        added = dict(document)
        added["measurements"] = [dict(document["measurements"][0])]
        added["measurements"][0]["rows"] = document["measurements"][0]["rows"] + [
            {"joints": dict(zip(JOINTS, map(float, row))), "values": list(map(float, predicted))}
        ]
        (tmp_path / "added.yaml").write_text(yaml.safe_dump(added))
        after = calibrate(compile_problem(load_problem(tmp_path / "added.yaml")))
        reductions.append(0.5 * (np.linalg.slogdet(before.covariance)[1] - np.linalg.slogdet(after.covariance)[1]))
    assert ranked[0]["row"] == int(np.argmax(reductions)) + 1
    assert abs(gains[0] - max(reductions)) < 1e-3 * max(reductions)


def test_the_proposal_and_the_predictions_are_printed_not_only_in_the_json(tmp_path):
    """Without --json, --propose prints its ranking (rank, CSV line, entropy reduction) and --predict
    its readings (value ± std), each as the JSON has them."""
    path, _, _, _ = synthetic(tmp_path, 8, count=12)
    candidates = np.random.default_rng(81).uniform(-1.5, 1.5, size=(6, 6))
    lines = [",".join(JOINTS)] + [",".join(repr(float(v)) for v in row) for row in candidates]
    (tmp_path / "c.csv").write_text("\n".join(lines) + "\n")
    common = ["calibrate", str(path), "--check-samples", "0", "--propose", "2", "--candidates", str(tmp_path / "c.csv")]
    printed = runner.invoke(app, [*common, "--predict", str(tmp_path / "c.csv")])
    assert printed.exit_code == 0, printed.output
    document = json.loads(runner.invoke(app, [*common, "--predict", str(tmp_path / "c.csv"), "--json"]).stdout)
    assert "the next configurations to measure" in printed.stdout and "predicted readings at" in printed.stdout
    for rank, entry in enumerate(document["proposal"]["ranked"], start=1):
        assert f"│ {rank} │ {entry['line']} │ {entry['entropy_reduction']:.4g} │".replace(
            " ", ""
        ) in printed.stdout.replace(" ", "")
    row = document["prediction"]["rows"][0]
    name, readings = next(iter(row["measurements"].items()))
    parameter, found = next(iter(readings.items()))
    assert f"{found['value']:.6g} ± {found['std']:.3g}" in printed.stdout


def test_proposing_more_than_the_candidates_ranks_them_all_and_says_so(tmp_path):
    path, _, _, _ = synthetic(tmp_path, 8, count=12)
    candidates = np.random.default_rng(82).uniform(-1.5, 1.5, size=(4, 6))
    lines = [",".join(JOINTS)] + [",".join(repr(float(v)) for v in row) for row in candidates]
    (tmp_path / "c.csv").write_text("\n".join(lines) + "\n")
    common = ["calibrate", str(path), "--check-samples", "0", "--candidates", str(tmp_path / "c.csv")]
    asked = runner.invoke(app, [*common, "--propose", "10", "--json"])
    assert asked.exit_code == 0, asked.output
    proposal = json.loads(asked.stdout)["proposal"]
    assert sorted(entry["row"] for entry in proposal["ranked"]) == [1, 2, 3, 4]
    assert proposal["note"] == "every candidate ranked: the file has 4, fewer than the 10 asked"
    assert "fewer than the 10 asked" in asked.stderr.replace("\n", " ")
    exact = json.loads(runner.invoke(app, [*common, "--propose", "4", "--json"]).stdout)["proposal"]
    assert "note" not in exact and exact["ranked"] == proposal["ranked"]


def test_calibrate_refuses_to_overwrite_its_inputs_and_needs_candidates_with_propose(tmp_path):
    path, _, _, _ = synthetic(tmp_path, 9, count=5)
    result = runner.invoke(app, ["calibrate", str(path), "--urdf", str(RX90_URDF)])
    assert result.exit_code == 2 and "refusing to overwrite the input file" in result.stderr
    result = runner.invoke(app, ["calibrate", str(path), "--propose", "2"])
    assert result.exit_code == 2 and "--candidates" in result.stderr


def test_the_readme_calibration_command_runs(tmp_path):
    """The worked example's command, with its two outputs in a temporary folder."""
    import re

    from conftest import documentation, run_bcad

    readme = documentation()
    line = next(
        line for line in readme.splitlines() if line.startswith("bcad calibrate problems/") and "--urdf" in line
    )
    assert (
        line == "bcad calibrate problems/calibration/ur5_tracker.yaml --urdf ur5_calibrated.urdf "
        "-o problems/calibration/ur5_calibration.json"
    )
    # (the result where the plans read it: in a temporary folder here, the committed one untouched)
    args = re.sub(
        r"(?:problems/calibration/)?(ur5_calibrated\.urdf|ur5_calibration\.json)",
        lambda m: str(tmp_path / m.group(1)),
        line,
    ).split()[1:]
    run = run_bcad(*args, cwd=REPO)
    assert run.returncode == 0, run.stderr
    document = json.loads((tmp_path / "ur5_calibration.json").read_text())
    assert document["urdf"] == {"ur5": str(tmp_path / "ur5_calibrated.urdf")}
    assert "<robot" in (tmp_path / "ur5_calibrated.urdf").read_text()
    # the table: DH errors by the names a plan matches (the JSON's), with the DH parameter they perturb
    assert "ur5/joint_2/dh.tz (d)" in run.stdout and "ur5/joint_2 d " not in run.stdout


def test_probe_touches_on_a_face_calibrate_the_face_and_the_probe(tmp_path):
    """A point entity (a probe's tip) measured in a face entity's frame: tz = 0 at each touch. The
    touches are found on the true cell with Pinocchio (joint 2 solved so that the tip is on the face)."""
    import pinocchio as pin
    from scipy.optimize import brentq

    rng = np.random.default_rng(12)
    true = {"table/zero": 0.8, "mount.tz": -0.4, "arm/joint_2/zero.rz": 0.0015, "arm/joint_3/zero.rz": -0.001}
    model = pin.buildModelFromUrdf(str(RX90_URDF))
    data = model.createData()
    flange = model.getFrameId("link_6")

    def tip_height(q):
        q = q.copy()
        q[1] += true["arm/joint_2/zero.rz"]
        q[2] += true["arm/joint_3/zero.rz"]
        pin.framesForwardKinematics(model, data, q)
        M = data.oMf[flange].homogeneous
        return (M[:3, :3] @ np.array([0.0, 0.0, 0.1 + true["mount.tz"] / 1000]) + M[:3, 3])[2] * 1000

    face_height = 300.0 + true["table/zero"]
    rows = []
    while len(rows) < 40:
        q = rng.uniform(-1.2, 1.2, 6)
        f = lambda angle: tip_height(np.array([q[0], angle, *q[2:]])) - face_height  # noqa: E731
        grid = np.linspace(-2.0, 2.0, 41)
        values = [f(a) for a in grid]
        crossing = next((k for k in range(40) if values[k] * values[k + 1] < 0), None)
        if crossing is None:
            continue
        q[1] = brentq(f, grid[crossing], grid[crossing + 1], xtol=1e-14)
        rows.append({"joints": dict(zip(JOINTS, map(float, q))), "values": [float(rng.normal(0, 0.02))]})
    document = {
        "name": "touch",
        "units": {"length": "mm"},
        "frames": ["world", "flange_tool", "table"],
        "robots": [
            {
                "name": "arm",
                "urdf": str(RX90_URDF),
                "parent": "world",
                "joints": {
                    "default": {"status": "X"},
                    "joint_2": {"zero": "normal(0, 0.003)"},
                    "joint_3": {"zero": "normal(0, 0.003)"},
                },
            }
        ],
        "links": [
            {
                "name": "mount",
                "parent": "arm/link_6",
                "child": "flange_tool",
                "pose": [0, 0, 100, 0, 0, 0],
                "status": "FFLFFF",
                "distributions": {"tz": "normal(0, 1)"},
            },
            {
                "name": "table",
                "parent": "world",
                "child": "table",
                "pose": [0, 0, 300, 0, 0, 0],
                "status": "FFLFFF",
                "distributions": {"tz": "normal(0, 2)"},
            },
        ],
        "entities": [
            {"name": "tip", "type": "point", "frame": "flange_tool", "at": [0, 0, 0]},
            {"name": "top", "type": "face", "frame": "table", "size": [2000, 2000]},
        ],
        "measurements": [
            {
                "name": "touches",
                "frame": "tip",
                "reference": "top",
                "parameters": "tz",
                "noise": "normal(0, 0.02)",
                "rows": rows,
            }
        ],
    }
    path = tmp_path / "touch.yaml"
    path.write_text(yaml.safe_dump(document))
    cal = calibrate(compile_problem(load_problem(path)))
    names = {
        "table.tz": true["table/zero"],
        "mount.tz": true["mount.tz"],
        "arm/joint_2/zero.rz": true["arm/joint_2/zero.rz"],
        "arm/joint_3/zero.rz": true["arm/joint_3/zero.rz"],
    }
    for name, value in names.items():
        k = cal.names.index(name)
        assert cal.identified[k], name
        assert abs(cal.estimate[k] - value) < 3 * cal.std[k], (name, cal.estimate[k], value, cal.std[k])
    assert np.sqrt(np.mean(cal.residuals_after**2)) < 1.5


def test_an_x_is_read_as_its_map_with_its_prior_or_flat(tmp_path):
    """One angle X measured once at 0.02 (noise 0.005): with the prior N(0, 0.01^2) the MAP and Laplace
    std are the conjugate Gaussian's (0.016, 0.00447); flat on its bounds, the measurement itself."""

    def run(link: dict):
        document = {
            "name": "one-x",
            "frames": ["a", "b"],
            "links": [{"name": "l", "parent": "a", "child": "b", "status": "FFFFFX", **link}],
            "measurements": [
                {
                    "name": "m",
                    "frame": "b",
                    "reference": "a",
                    "parameters": "rz",
                    "noise": "normal(0, 0.005)",
                    "rows": [{"joints": {}, "values": [0.02]}],
                }
            ],
        }
        path = tmp_path / "x.yaml"
        path.write_text(yaml.safe_dump(document))
        result = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet"])
        assert result.exit_code == 0, result.output
        return json.loads(result.stdout)["parameters"]["l.rz"]

    with_prior = run({"bounds": {"rz": [-1, 1]}, "distributions": {"rz": "normal(0, 0.01)"}})
    assert with_prior["kind"] == "X" and with_prior["reading"] == "MAP" and with_prior["prior"] == "gaussian"
    precision = 1 / 0.01**2 + 1 / 0.005**2
    assert abs(with_prior["estimate"] - 0.02 / 0.005**2 / precision) < 1e-9
    assert abs(with_prior["std"] - precision**-0.5) < 1e-9
    flat = run({"bounds": {"rz": [-1, 1]}})
    assert flat["prior"] == "flat" and abs(flat["estimate"] - 0.02) < 1e-9 and abs(flat["std"] - 0.005) < 1e-9


def test_predictions_at_new_configurations_have_honest_z_scores(tmp_path):
    """Calibrate --predict C.csv gives each reading's value at the calibrated model (the
    MAP) and its std (the Laplace covariance propagated). Over 10 synthetic full-DH UR5s (truths
    drawn from the priors, 30 noisy tracker readings each), fresh readings at 30 new
    configurations: z = (reading - predicted) / sqrt(std^2 + noise^2) has spread 0.9-1.1 and mean
    within 0.15 of 0; the calibrated model is within 0.05 mm RMS per axis of the true robot."""
    from bcad.api import calibrate as calibrate_api

    z, errors = [], []
    for seed in range(10):
        path, truth = ur5_synthetic(tmp_path, 100 + seed)
        model = CalibrationModel(compile_problem(load_problem(path)))
        dh, base, smr = _ur5_truth_of(model.names, truth)
        rng = np.random.default_rng(500 + seed)
        q = ur5_truth.configurations(rng, 30)
        csv = tmp_path / f"new_{seed}.csv"
        csv.write_text(
            "\n".join([",".join(ur5_truth.JOINTS)] + [",".join(repr(float(v)) for v in row) for row in q]) + "\n"
        )
        rows = calibrate_api(path, check_samples=0, predict=csv).document["prediction"]["rows"]
        for row, configuration in zip(rows, q):
            true = ur5_truth.reflector_in_tracker(configuration, dh, base, smr)
            reading = true + rng.normal(0.0, ur5_truth.NOISE, 3)
            found = row["measurements"]["tracker"]
            for k, name in enumerate(("tx", "ty", "tz")):
                z.append((reading[k] - found[name]["value"]) / np.hypot(found[name]["std"], found[name]["noise_std"]))
                errors.append(true[k] - found[name]["value"])
    z = np.array(z)
    assert 0.9 < z.std() < 1.1 and abs(z.mean()) < 0.15, (z.mean(), z.std())
    assert np.sqrt(np.mean(np.square(errors))) < 0.05


def test_task_directed_proposals_beat_d_optimal_on_the_task(tmp_path):
    """--propose K --candidates C.csv --for TASK.csv. A synthetic full-DH UR5 calibrated
    from 12 readings; the task is the reflector at 5 configurations in one corner of the workspace;
    60 random candidates. Each criterion's K = 3 picks are measured on the true robot (with the
    tracker's noise) and the robot calibrated again: the task's predicted std (RMS over its
    readings) after the task-directed picks is below that after the D-optimal ones, on each of 3
    cells; and the std the proposal predicted matches what the new calibration reports within 25 %."""
    from bcad.api import calibrate as calibrate_api

    def write_csv(path, rows):
        path.write_text(
            "\n".join([",".join(ur5_truth.JOINTS)] + [",".join(repr(float(v)) for v in row) for row in rows]) + "\n"
        )

    ratios = []
    for seed in range(3):
        path, truth = ur5_synthetic(tmp_path, 300 + seed, count=12)
        model = CalibrationModel(compile_problem(load_problem(path)))
        dh, base, smr = _ur5_truth_of(model.names, truth)
        rng = np.random.default_rng(700 + seed)
        corner = ur5_truth.configurations(rng, 1)[0]
        task = corner + rng.normal(0.0, 0.05, (5, 6))
        candidates = ur5_truth.configurations(rng, 60)
        write_csv(tmp_path / "task.csv", task)
        write_csv(tmp_path / "candidates.csv", candidates)
        after = {}
        for label, extra in (("task", {"task": tmp_path / "task.csv"}), ("d-optimal", {})):
            proposal = calibrate_api(
                path, check_samples=0, propose=3, candidates=tmp_path / "candidates.csv", **extra
            ).document["proposal"]
            picks = [candidates[p["row"] - 1] for p in proposal["ranked"]]
            document = yaml.safe_load(path.read_text())
            for q in picks:
                reading = ur5_truth.reflector_in_tracker(q, dh, base, smr) + rng.normal(0.0, ur5_truth.NOISE, 3)
                document["measurements"][0]["rows"].append(
                    {"joints": dict(zip(ur5_truth.JOINTS, map(float, q))), "values": list(map(float, reading))}
                )
            grown = tmp_path / f"grown_{label}_{seed}.yaml"
            grown.write_text(yaml.safe_dump(document))
            rows = calibrate_api(grown, check_samples=0, predict=tmp_path / "task.csv").document["prediction"]["rows"]
            stds = [row["measurements"]["tracker"][p]["std"] for row in rows for p in ("tx", "ty", "tz")]
            after[label] = float(np.sqrt(np.mean(np.square(stds))))
            if label == "task":
                assert proposal["ranked"][-1]["task_std"] == pytest.approx(after[label], rel=0.25)
        ratios.append(after["task"] / after["d-optimal"])
    assert all(r < 1.0 for r in ratios), ratios


def test_a_csv_with_a_bom_or_cr_line_ends_reads_as_meant_and_a_huge_cell_is_an_input_error(tmp_path):
    """A UTF-8 BOM before the header and CR-only line ends are valid files (the same
    calibration as the original); a cell over the csv module's limit is exit 2 with its line."""
    import shutil

    source = (EXAMPLE / "ur5_tracker.csv").read_bytes()
    shutil.copy(EXAMPLE / "ur5_tracker.yaml", tmp_path / "base.yaml")
    problem = (tmp_path / "base.yaml").read_text()
    variants = {
        "plain": source,
        "bom": b"\xef\xbb\xbf" + source,
        "cr": source.replace(b"\r\n", b"\n").replace(b"\n", b"\r"),
    }
    lines = source.split(b"\n")
    lines[3] = lines[3] + b"," + b"9" * 200_000
    variants["huge"] = b"\n".join(lines)
    estimates = {}
    for name, data in variants.items():
        (tmp_path / f"{name}.csv").write_bytes(data)
        (tmp_path / f"{name}.yaml").write_text(problem.replace("data: ur5_tracker.csv", f"data: {name}.csv"))
        result = runner.invoke(
            app, ["calibrate", str(tmp_path / f"{name}.yaml"), "--json", "--quiet", "--check-samples", "0"]
        )
        if name == "huge":
            assert result.exit_code == 2 and "huge.csv:4:" in result.stderr and "field limit" in result.stderr
        else:
            assert result.exit_code == 0, result.stderr
            estimates[name] = json.loads(result.stdout)["parameters"]["smr_mount.tx"]["estimate"]
    assert estimates["bom"] == estimates["plain"] == estimates["cr"]


def test_propose_for_a_planning_problem_is_its_closing_link_as_a_task(tmp_path):
    """--for PLAN.yaml directs the choice at what the plan's closing link scores (the drill tip at
    the hole). Two paths that share no code: the plan's compiled chain with the calibrated
    parameters matched by name, at the plan's configuration (its cycles closed at nominal), and
    --for TASK.csv at those joint values, where the calibration model predicts the reflector
    (the drill tip is where the reflector was). Same picks, same predicted task std."""
    import shutil

    from bcad.bayes.model import BayesModel
    from bcad.bayes.nominal import solve_nominal
    from bcad.compiler import compile_problem
    from bcad.model import load_problem

    for name in ("ur5_tracker.yaml", "ur5_tracker.csv", "ur5_drill_plan.yaml", "ur5_calibration.json"):
        shutil.copy(REPO / "problems" / "calibration" / name, tmp_path)
    rng = np.random.default_rng(4)
    header = ",".join(f"ur5/joint_{k}" for k in range(1, 7))
    (tmp_path / "candidates.csv").write_text(
        header + "\n" + "\n".join(",".join(f"{v:.4f}" for v in row) for row in rng.uniform(-3, 3, size=(40, 6))) + "\n"
    )
    plan = compile_problem(load_problem(tmp_path / "ur5_drill_plan.yaml"))
    x = solve_nominal(BayesModel(plan), np.random.default_rng(0)).x
    names = [p.name for p in plan.parameters.x]
    joints = [x[names.index(f"ur5/joint_{k}.rz")] for k in range(1, 7)]
    (tmp_path / "task.csv").write_text(header + "\n" + ",".join(repr(float(v)) for v in joints) + "\n")
    ranked = {}
    for task in ("ur5_drill_plan.yaml", "task.csv"):
        out = tmp_path / f"{task}.json"
        result = CliRunner().invoke(
            app,
            [
                "calibrate",
                str(tmp_path / "ur5_tracker.yaml"),
                "--quiet",
                "--check-samples",
                "0",
                "--propose",
                "4",
                "--candidates",
                str(tmp_path / "candidates.csv"),
                "--for",
                str(tmp_path / task),
                "-o",
                str(out),
            ],
        )
        assert result.exit_code == 0, result.output
        proposal = json.loads(out.read_text())["proposal"]
        ranked[task] = proposal["ranked"]
        # the task std's unit, in the JSON and the table's heading (both millimetres here)
        assert proposal["task_unit"] == "mm"
        from rich.console import Console

        from bcad.calibration.report import proposal_table

        console = Console(width=120, color_system=None)
        with console.capture() as captured:
            console.print(proposal_table(proposal))
        assert "task std (mm)" in captured.get(), captured.get()
    plan_picks, csv_picks = ranked["ur5_drill_plan.yaml"], ranked["task.csv"]
    assert [p["row"] for p in plan_picks] == [p["row"] for p in csv_picks]
    for a, b in zip(plan_picks, csv_picks):
        assert a["task_std"] == pytest.approx(b["task_std"], rel=1e-4)
    assert plan_picks[-1]["task_std"] < plan_picks[0]["task_std"]  # each pick lowers it


def test_propose_for_a_plan_without_calibrated_parameters_is_exit_2(tmp_path, write_problem):
    import shutil

    for name in ("ur5_tracker.yaml", "ur5_tracker.csv"):
        shutil.copy(REPO / "problems" / "calibration" / name, tmp_path)
    (tmp_path / "candidates.csv").write_text(
        "ur5/joint_1,ur5/joint_2,ur5/joint_3,ur5/joint_4,ur5/joint_5,ur5/joint_6\n"
        "0.1,0.2,0.3,0.4,0.5,0.6\n0.6,0.5,0.4,0.3,0.2,0.1\n"
    )
    from conftest import ONE_LINK_GRAPH

    plan = write_problem(ONE_LINK_GRAPH, "unrelated.yaml")
    result = CliRunner().invoke(
        app,
        [
            "calibrate",
            str(tmp_path / "ur5_tracker.yaml"),
            "--quiet",
            "--check-samples",
            "0",
            "--propose",
            "1",
            "--candidates",
            str(tmp_path / "candidates.csv"),
            "--for",
            str(plan),
        ],
    )
    assert result.exit_code == 2, result.output
    assert "names none of the calibrated parameters" in result.output


def test_the_rows_of_all_measurements_are_bounded_together(tmp_path, monkeypatch):
    """100 measurements of 100,000 rows each are 1e7 rows: refused once the running total passes
    the bound (here lowered to 50), naming the measurement where it did, before any solve."""
    import bcad.calibration.model as model

    monkeypatch.setattr(model, "MAX_ROWS", 50)
    path, _, _, _ = synthetic(tmp_path, 1, count=30)
    document = yaml.safe_load(path.read_text())
    twin = {**document["measurements"][0], "name": "twin"}
    document["measurements"].append(twin)
    path.write_text(yaml.safe_dump(document))
    result = runner.invoke(app, ["calibrate", str(path)])
    assert result.exit_code == 2 and "the measurements hold more than 50 rows together" in result.stderr, result.output


def test_the_table_gives_each_std_its_unit():
    from bcad.calibration.report import calibration_table

    document = {
        "problem": "p",
        "units": {"length": "mm", "angle": "rad"},
        "parameters": {
            "base.tx": {"kind": "X", "estimate": 2001.2, "std": 0.0156, "prior": "flat", "identified": True},
            "joint.rz": {"kind": "L", "estimate": 0.001, "std": 0.0002, "prior": "flat", "identified": True},
        },
    }
    from rich.console import Console

    console = Console(width=200, record=True)
    console.print(calibration_table(document))
    text = console.export_text()
    assert "0.0156 mm" in text and "0.0002 rad" in text


def _broken_tracker(folder, case: str):
    """The UR5 examples copied into ``folder``, broken as ``case`` says; the problem's path."""
    import shutil

    example = "ur5_eye_in_hand" if case == "camera_info" else "ur5_tracker"
    data = "ur5_camera_views.csv" if case == "camera_info" else "ur5_tracker.csv"
    shutil.copy(EXAMPLE / data, folder / data)
    text = (EXAMPLE / f"{example}.yaml").read_text()
    if case == "frame":
        text = text.replace("    reference: tracker\n", "    reference: nowhere\n")
    elif case == "missing":
        text = text.replace(f"data: {data}", "data: gone.csv")
    elif case == "cell":
        lines = (folder / data).read_text().splitlines()
        lines[2] = "nan" + lines[2][lines[2].index(",") :]
        (folder / data).write_text("\n".join(lines) + "\n")
    elif case == "camera_info":
        (folder / "info.yaml").write_text(
            "image_width: 1280\nimage_height: 1024\ncamera_matrix: {data: [0, 0, 640, 0, 0, 512, 0, 0, 1]}\n"
            "distortion_coefficients: {data: [0, 0, 0, 0, 0]}\n"
        )
        start, end = text.index("    image_size:"), text.index("measurements:")
        text = text[:start] + "    camera_info: info.yaml\n\n" + text[end:]
    path = folder / "cell.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("case", "fragment"),
    [
        ("frame", "cell.yaml:86:16: unknown frame or entity 'nowhere'"),
        ("missing", ": 'gone.csv' not found"),
        ("cell", "ur5_tracker.csv:3:1: 'nan' in column 'ur5/joint_1' is not a finite number"),
        ("camera_info", "info.yaml:3:24: camera_matrix: expected positive focal lengths"),
    ],
)
def test_validate_refuses_what_calibrate_refuses_at_the_same_place(tmp_path, case, fragment):
    """validate accepted a problem whose measurements calibrate then refused (an unknown frame, a
    missing or bad CSV, a bad camera_info): it reads them with calibrate's own code, exit 2, the
    same message at the same place."""
    path = _broken_tracker(tmp_path, case)
    validated = runner.invoke(app, ["validate", str(path)])
    calibrated = runner.invoke(app, ["calibrate", str(path), "--quiet", "--check-samples", "0"])
    assert validated.exit_code == calibrated.exit_code == 2, validated.output
    assert fragment in validated.stderr and validated.stderr == calibrated.stderr, (validated.stderr, calibrated.stderr)
