"""Measure, then plan: the covariance a reader rebuilds from a calibration result (its
``laplace_std`` and ``correlation``) is the one bcad computed, to rounding, at any number of
readings, and a planning problem takes the result in ``calibration:``.

Full DH has correlations near -1: written to 6 decimals (an error of 5e-7), the rebuilt covariance
was not bcad's, and with correlations within 1e-4 of -1 not positive semidefinite."""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest

import bcad
from bcad.calibration.model import CalibrationModel
from bcad.calibration.report import calibration_document
from bcad.calibration.solve import calibrate
from bcad.compiler.calibration import read_posterior
from bcad.compiler.units import parameter_scales
from bcad.io import write_json_atomic

from conftest import REPO, run_bcad

CALIBRATION = REPO / "problems" / "calibration"


def _truth():
    spec = importlib.util.spec_from_file_location("ur5_truth", CALIBRATION / "ur5_truth.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("readings", [50, 500, 2000])
def test_a_calibration_result_rebuilds_to_bcads_covariance_and_plans(tmp_path, readings):
    _truth().write_csv(tmp_path / "tracker.csv", readings, seed=readings)
    text = (CALIBRATION / "ur5_tracker.yaml").read_text().replace("../../robots/", f"{REPO}/robots/")
    problem = tmp_path / "tracker.yaml"
    problem.write_text(text.replace("data: ur5_tracker.csv", "data: tracker.csv"))
    compiled = bcad.compile(problem)
    model = CalibrationModel(compiled)
    result = calibrate(compiled, model)
    written = tmp_path / "calibration.json"
    write_json_atomic(calibration_document(compiled, model, result, 0.0), written)

    names, _, covariance, _ = read_posterior(written, compiled.problem)
    assert names == result.names
    scale = parameter_scales(compiled, names)
    own = result.covariance * np.outer(scale, scale)  # the problem's units, as the file's
    std = np.sqrt(np.diag(own))
    assert np.max(np.abs(np.sqrt(np.diag(covariance)) / std - 1.0)) < 1e-6
    assert np.max(np.abs(covariance - own) / np.outer(std, std)) < 1e-9
    correlation = own / np.outer(std, std)
    assert np.max(np.abs(correlation[~np.eye(len(names), dtype=bool)])) > 0.98  # near +-1, where rounding tells
    assert np.min(np.linalg.eigvalsh(covariance / np.outer(std, std))) > -1e-8

    plan_text = (CALIBRATION / "ur5_drill_plan.yaml").read_text().replace("../../robots/", f"{REPO}/robots/")
    plan = tmp_path / "plan.yaml"
    plan.write_text(plan_text.replace("calibration: [ur5_calibration.json]", "calibration: [calibration.json]"))
    run = run_bcad("solve", plan, "--quiet", "-o", tmp_path / "plan.json")
    assert run.returncode == 0, run.stderr
    assert len(json.loads((tmp_path / "plan.json").read_text())["calibration"][0]["applied"]) == len(names)


def test_the_written_correlation_is_symmetric():
    import subprocess
    import sys
    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        out = f"{folder}/u.json"
        subprocess.run(
            [
                sys.executable,
                "-m",
                "bcad.cli",
                "calibrate",
                str(REPO / "problems/calibration/ur5_tracker.yaml"),
                "-o",
                out,
                "--quiet",
            ],
            check=True,
            capture_output=True,
        )
        matrix = np.array(json.loads(open(out).read())["correlation"]["matrix"])
    assert np.array_equal(matrix, matrix.T)
