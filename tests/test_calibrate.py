"""Calibration (issue 10): synthetic measurements of a known RX90 cell, against the truth."""

from __future__ import annotations

import json

import numpy as np
import yaml
from typer.testing import CliRunner

from bcad.bayes.linear import free_parameter_moments
from bcad.calibrate.model import CalibrationModel
from bcad.calibrate.solve import calibrate
from bcad.cli import app
from bcad.compile import compile_problem
from bcad.kinematics import Samples
from bcad.model import load_problem

from conftest import RX90_URDF

runner = CliRunner()
NOISE = 0.05  # mm, a laser tracker's
CELL = {
    "name": "rx90-calibration",
    "units": {"length": "mm"},
    "frames": ["world", "tool"],
    "robots": [{
        "name": "arm", "urdf": str(RX90_URDF), "parent": "world", "status": "LLLLLL",
        "distributions": {"tx": "normal(0, 0.5)", "ty": "normal(0, 0.5)", "tz": "normal(0, 0.5)",
                          "rx": "normal(0, 0.001)", "ry": "normal(0, 0.001)", "rz": "normal(0, 0.001)"},
        "joints": {"default": {"status": "X", "zero": "normal(0, 0.002)"}},
    }],
    "links": [{"name": "mount", "parent": "arm/link_6", "child": "tool", "pose": [0, 0, 100, 0, 0, 0], "status": "LLLFFF",
               "distributions": {"tx": "normal(0, 0.2)", "ty": "normal(0, 0.2)", "tz": "normal(0, 0.2)"}}],
}
JOINTS = [f"arm/joint_{k}" for k in range(1, 7)]


def _measurement(rows, noise=NOISE):
    return {"name": "tracker", "frame": "tool", "reference": "world", "parameters": "tx,ty,tz",
            "noise": f"normal(0, {noise})", "rows": rows}


def synthetic(tmp_path, seed: int, count: int = 30, noise: float = NOISE, stated_noise: float = NOISE):
    """A cell whose true L is drawn from the prior, measured at ``count`` random configurations."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(-1.5, 1.5, size=(count, 6))
    placeholder = [{"joints": dict.fromkeys(JOINTS, 0.0), "values": [0.0, 0.0, 0.0]}]
    path = tmp_path / f"cell{seed}.yaml"
    path.write_text(yaml.safe_dump({**CELL, "measurements": [_measurement(placeholder)]}))
    compiled = compile_problem(load_problem(path))
    mean, variance = free_parameter_moments(compiled)
    truth = mean + np.sqrt(variance) * rng.standard_normal(len(mean))
    chain = CalibrationModel(compiled).measurements[0].chain
    true_positions = chain.evaluate(q, Samples(np.repeat(truth[None], count, axis=0))).poses()[:, :3]
    measured = true_positions + rng.normal(0.0, noise, true_positions.shape)
    rows = [{"joints": dict(zip(JOINTS, map(float, q[r]))), "values": list(map(float, measured[r]))} for r in range(count)]
    path.write_text(yaml.safe_dump({**CELL, "measurements": [_measurement(rows, stated_noise)]}))
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


def test_reported_standard_deviations_are_honest(tmp_path):
    z = []
    for seed in range(30):
        path, truth, _, _ = synthetic(tmp_path, seed)
        cal = calibrate(compile_problem(load_problem(path)))
        z.extend(((cal.estimate - truth) / cal.std)[cal.identified])
    z = np.array(z)
    assert abs(z.mean()) < 0.15
    assert 0.8 < z.std() < 1.25


def test_csv_data_give_the_same_calibration(tmp_path):
    path, _, q, measured = synthetic(tmp_path, 3)
    inline = calibrate(compile_problem(load_problem(path)))
    lines = [",".join(JOINTS + ["tx", "ty", "tz"])] + [",".join(repr(float(v)) for v in [*q[r], *measured[r]]) for r in range(len(q))]
    (tmp_path / "tracker.csv").write_text("\n".join(lines) + "\n")
    document = yaml.safe_load(path.read_text())
    measurement = document["measurements"][0]
    del measurement["rows"]
    measurement["data"] = "tracker.csv"
    path.write_text(yaml.safe_dump(document))
    from_csv = calibrate(compile_problem(load_problem(path)))
    np.testing.assert_allclose(from_csv.estimate, inline.estimate, rtol=0, atol=1e-12)


def test_csv_errors_are_located(tmp_path):
    path, _, q, measured = synthetic(tmp_path, 4, count=3)
    (tmp_path / "bad.csv").write_text(",".join(JOINTS + ["tx", "ty", "tz"]) + "\n" + "0,0,0,0,0,0,1,2,3\n" + "0,0,0,0,abc,0,1,2,3\n")
    document = yaml.safe_load(path.read_text())
    del document["measurements"][0]["rows"]
    document["measurements"][0]["data"] = "bad.csv"
    path.write_text(yaml.safe_dump(document))
    result = runner.invoke(app, ["calibrate", str(path)])
    assert result.exit_code == 2 and f"{tmp_path / 'bad.csv'}:3: 'abc' in column arm/joint_5 is not a number" in result.stderr


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
