"""Cases that once ended in exit 1 end in exit 0, 2 or 3, never a traceback: a full device, an
ASCII-only stdout, mathtext in names, a 400-digit number in a result, every row an outlier,
long or slashed robot names in file names, odd --sweep keys and values."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from typer.testing import CliRunner

from bcad.cli import app

from conftest import ONE_LINK_GRAPH, REPO

runner = CliRunner()


def _problem(folder: Path, name: str = "one-link") -> Path:
    path = folder / "one.yaml"
    path.write_text(
        textwrap.dedent(ONE_LINK_GRAPH).lstrip("\n").replace("name: one-link", f"name: {json.dumps(name)}")
        + "solver: {search_starts: 2, posterior_samples: 2000}\n",
        encoding="utf-8",
    )
    return path


def _bcad(*args, stdout=subprocess.PIPE, env=None):
    return subprocess.run(
        [sys.executable, "-m", "bcad.cli", *map(str, args)],
        stdout=stdout,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, **(env or {})},
        timeout=120,
    )


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
@pytest.mark.parametrize(
    "args",
    [
        ["validate", "{p}"],
        ["schema"],
        ["graph", "{p}", "--dot"],
        ["--help"],
        ["--version"],
        ["solve", "{p}", "--quiet"],
    ],
)
def test_a_full_device_on_stdout_is_exit_2_in_one_line(tmp_path, args):
    problem = _problem(tmp_path)
    with open("/dev/full", "w") as full:
        result = _bcad(*[a.format(p=problem) for a in args], stdout=full)
    assert result.returncode == 2, result.stderr
    assert "cannot write the output: No space left on device" in result.stderr
    assert "Traceback" not in result.stderr


def test_an_ascii_only_stdout_shows_escapes_not_an_error(tmp_path):
    problem = _problem(tmp_path, "Düsseldorf ✓ 机器人")
    result = _bcad("validate", problem, env={"PYTHONIOENCODING": "ascii", "LC_ALL": "C"})
    assert result.returncode == 0, result.stderr
    assert "D\\xfcsseldorf" in result.stdout and "\\u2713" in result.stdout


def test_mathtext_in_names_is_drawn_literally(tmp_path):
    pytest.importorskip("matplotlib")
    problem = tmp_path / "m.yaml"
    problem.write_text(
        textwrap.dedent(r"""
        name: '$\foo$ bad'
        frames: ['$a\foo', 'm$', 'b\sqrt{']
        links:
          - {name: '$\frac{1}', parent: '$a\foo', child: 'm$', status: XFFFFF, bounds: {tx: [-10, 10]}, distributions: {tx: 'normal(1, 2)'}}
          - {name: '\bar$x', parent: 'm$', child: 'b\sqrt{', status: LFFFFF, distributions: {tx: 'normal(0, 0.3)'}}
          - {name: '$x^{$', parent: '$a\foo', child: 'b\sqrt{', pose: [3, 0, 0, 0, 0, 0], status: LFFFFF, close: true, distributions: {tx: 'normal(0, 0.4)'}}
        solver: {search_starts: 2, posterior_samples: 2000}
        """).lstrip()
    )
    result = runner.invoke(app, ["solve", str(problem), "--quiet", "-o", str(tmp_path / "m.json")])
    assert result.exit_code == 0, result.output
    for what in ("arms", "posterior", "graph"):
        picture = tmp_path / f"m_{what}.svg"
        result = runner.invoke(
            app,
            [
                "plot",
                str(problem),
                "--what",
                what,
                "--at",
                str(tmp_path / "m.json"),
                "--samples",
                "2000",
                "-o",
                str(picture),
            ],
        )
        assert result.exit_code == 0, (what, result.output)
        # SVG keeps text as text: the name is there as written (XML-escaped), not typeset.
        assert "x^{" in picture.read_text(encoding="utf-8") or what == "arms"


@pytest.mark.parametrize("value", ["1" + "0" * 400, "1" + "0" * 5000])
def test_a_huge_integer_in_a_result_is_exit_2(tmp_path, value):
    problem = _problem(tmp_path)
    at = tmp_path / "at.json"
    at.write_text('{"solution": {"unknown.tx": ' + value + '}, "seed": 0}')
    result = runner.invoke(app, ["posterior", str(problem), "--at", str(at), "--samples", "1000", "--json"])
    assert result.exit_code == 2, result.output
    assert "at.json" in result.output and "Traceback" not in result.output


def test_a_huge_integer_in_a_calibration_result_is_exit_2(tmp_path):
    problem = _problem(tmp_path)
    calibration = tmp_path / "cal.json"
    calibration.write_text('{"parameters": {"free.tx": {"map": 1' + "0" * 400 + ', "laplace_std": 1}}}')
    result = runner.invoke(app, ["solve", str(problem), "--quiet", "--calibration", str(calibration)])
    assert result.exit_code == 2, result.output
    assert "cal.json" in result.output and "at most 1e12" in result.output


def test_every_row_an_outlier_is_a_warning_with_strict_json(tmp_path):
    import csv
    import random

    for name in ("rx90_sphere_touches.yaml", "rx90_sphere_touches.csv"):
        shutil.copy(REPO / "problems" / "calibration" / name, tmp_path)
    (tmp_path / "rx90_sphere_touches.yaml").write_text(
        (tmp_path / "rx90_sphere_touches.yaml")
        .read_text()
        .replace("../../robots/rx90.urdf", str(REPO / "robots" / "rx90.urdf"))
    )
    rows = list(csv.reader((tmp_path / "rx90_sphere_touches.csv").open()))
    shuffle = random.Random(1)
    rows[1:] = [
        row[:-1] + [str(float(row[-1]) + shuffle.choice([-1, 1]) * shuffle.uniform(50, 500))] for row in rows[1:]
    ]
    with (tmp_path / "rx90_sphere_touches.csv").open("w", newline="") as stream:
        csv.writer(stream).writerows(rows)
    result = runner.invoke(
        app,
        [
            "calibrate",
            str(tmp_path / "rx90_sphere_touches.yaml"),
            "--robust",
            "--quiet",
            "--check-samples",
            "0",
            "-o",
            str(tmp_path / "out.json"),
        ],
    )
    assert result.exit_code == 3, result.output
    document = json.loads((tmp_path / "out.json").read_text(), parse_constant=lambda c: pytest.fail(f"{c} in JSON"))
    assert "all_outliers" in [warning["code"] for warning in document["warnings"]]
    assert document["residuals"]["rms_whitened_after"] > 100


def test_json_text_writes_null_for_a_figure_that_is_not_finite():
    from bcad.io import json_text

    text = json_text({"a": float("nan"), "b": [1.0, float("inf")], "c": {"d": -float("inf"), "e": 2}})
    assert json.loads(text) == {"a": None, "b": [1.0, None], "c": {"d": None, "e": 2}}


@pytest.mark.parametrize("name", ["x" * 5000, "../../etc/escape", "a/b", "..", "ünï ✓"])
def test_robot_names_make_safe_distinct_file_names(tmp_path, name):
    from bcad.calibration.urdf import urdf_paths

    paths = urdf_paths(tmp_path / "cal.urdf", [name, "other"])
    written = paths[name]
    assert written.parent == tmp_path and len(written.name.encode()) <= 255 and "/" not in written.name
    assert paths["other"].name == "cal_other.urdf" and written != paths["other"]
    written.write_text("ok")  # a file name the file system takes
    assert urdf_paths(tmp_path / "cal.urdf", [name + "2", "other"])[name + "2"] != written


@pytest.mark.parametrize(
    "value, expected",
    [
        ("links.free.distributions.tx.std=2024-01-01", "date"),
        ("links.free.distributions.tx.std=!!binary aGVsbG8=", "bytes"),
        ("links.free.distributions.tx.std=&a [*a]", "contains itself"),
        ("name=!!set {a: null}", "set"),
        ("links..x=1", "empty segment"),
        ("links.nowhere.tx=1", "'nowhere' is not in links"),
    ],
)
def test_odd_set_keys_and_values_are_refused_before_running(tmp_path, value, expected):
    problem = _problem(tmp_path)
    result = runner.invoke(app, ["batch", str(problem), "--out", str(tmp_path / "out"), "--quiet", "--sweep", value])
    assert result.exit_code == 2, result.output
    assert expected in result.output
    assert not (tmp_path / "out" / "summary.jsonl").exists()


def test_a_long_set_value_gets_a_short_distinct_result_name(tmp_path):
    problem = _problem(tmp_path)
    values = ",".join(["a" * 3000, "a" * 2999 + "b"])
    result = runner.invoke(
        app,
        [
            "batch",
            str(problem),
            "--out",
            str(tmp_path / "out"),
            "--quiet",
            "--jobs",
            "1",
            "--sweep",
            f"links.free.name={values}",
        ],
    )
    assert result.exit_code == 0, result.output
    names = sorted(path.name for path in (tmp_path / "out").glob("one__*.json"))
    assert len(names) == 2 and all(len(name.encode()) <= 255 for name in names)


def test_a_solver_setting_may_be_swept_in_a_file_without_solver(tmp_path):
    problem = tmp_path / "bare.yaml"
    problem.write_text(textwrap.dedent(ONE_LINK_GRAPH).lstrip("\n"))
    result = runner.invoke(
        app,
        [
            "batch",
            str(problem),
            "--out",
            str(tmp_path / "out"),
            "--quiet",
            "--jobs",
            "1",
            "--sweep",
            "solver.posterior_samples=1000,2000",
        ],
    )
    assert result.exit_code == 0, result.output
    for count in (1000, 2000):
        document = json.loads((tmp_path / "out" / f"bare__posterior_samples={count}.json").read_text())
        assert document["posterior"]["samples"] == count


def test_a_noise_of_1e_12_is_a_warning_not_a_crash(tmp_path):
    for name in ("ur5_tracker.yaml", "ur5_tracker.csv"):
        shutil.copy(REPO / "problems" / "calibration" / name, tmp_path)
    problem = tmp_path / "ur5_tracker.yaml"
    problem.write_text(problem.read_text().replace("noise: normal(0, 0.05)", "noise: normal(0, 1e-12)"))
    result = runner.invoke(
        app, ["calibrate", str(problem), "--quiet", "--check-samples", "200", "-o", str(tmp_path / "o.json")]
    )
    assert result.exit_code == 3, result.output
    codes = [warning["code"] for warning in json.loads((tmp_path / "o.json").read_text())["warnings"]]
    assert "misfit" in codes


def test_the_check_proposal_factors_a_covariance_rounded_to_not_quite_positive_definite():
    import numpy as np

    from bcad.calibration.check import _proposal_factor

    rng = np.random.default_rng(0)
    basis = np.linalg.qr(rng.normal(size=(5, 5)))[0]
    covariance = basis @ np.diag([1.0, 1e-3, 1e-9, 0.0, -1e-17]) @ basis.T  # rounding's negative eigenvalue
    scale, log_determinant = _proposal_factor(covariance)
    product = scale @ scale.T
    np.testing.assert_allclose(product, covariance, atol=1e-13)
    assert np.linalg.eigvalsh(product).min() > 0.0  # a proper Gaussian proposal
    # log |det S| of the floored spectrum (1, 1e-3, 1e-9, 1e-14, 1e-14), written out
    assert log_determinant == pytest.approx(0.5 * np.log(1.0 * 1e-3 * 1e-9 * 1e-14 * 1e-14), rel=1e-6)


def test_a_root_of_a_covariance_rounded_below_zero():
    """The linearised integral's conditional covariance, with stds of 1e9 beside 1e-3 (a fuzzed
    RX90), lost its definiteness to rounding and Cholesky raised (exit 1): the root now falls
    back to the eigen-decomposition, R R^T equal to the matrix with its negative eigenvalue
    floored."""
    import numpy as np

    from bcad.bayes.linear import _scaled_cholesky

    rng = np.random.default_rng(2)
    basis = np.linalg.qr(rng.normal(size=(4, 4)))[0]
    bad = basis @ np.diag([2.0, 1.0, 1e-4, -1e-6]) @ basis.T  # rounding's negative eigenvalue
    good = np.diag([1e6, 1e-6, 1.0, 3.0])
    root = _scaled_cholesky(np.stack([bad, good]))
    product = root @ np.swapaxes(root, 1, 2)
    np.testing.assert_allclose(product[1], good, rtol=1e-6)
    np.testing.assert_allclose(product[0], bad, atol=1e-5)
    assert np.linalg.eigvalsh(product[0]).min() >= -1e-12


@pytest.mark.parametrize("value", [1e308, -1e308, 10**30, 10.5])
def test_a_result_whose_x_is_outside_its_bounds_is_exit_2(tmp_path, value):
    """A hand-edited or foreign result: X outside the problem's bounds (tx in [-10, 10]) is refused
    by posterior (--at and --value) and by every picture, naming the parameter and its bounds (1e308
    crashed the arms and posterior pictures with exit 1)."""
    problem = _problem(tmp_path)
    result = runner.invoke(app, ["solve", str(problem), "--quiet", "-o", str(tmp_path / "r.json")])
    assert result.exit_code == 0, result.output
    document = json.loads((tmp_path / "r.json").read_text())
    document["solution"]["unknown.tx"] = value
    at = tmp_path / "at.json"
    at.write_text(json.dumps(document))
    runs = [
        ["posterior", str(problem), "--at", str(at), "--samples", "500", "--json"],
        ["posterior", str(problem), "--value", f"unknown.tx={value}", "--samples", "500", "--json"],
    ]
    runs += [
        ["plot", str(problem), "--what", what, "--at", str(at), "--samples", "500", "-o", str(tmp_path / "p.png")]
        for what in ("arms", "posterior")
    ]
    for args in runs:
        result = runner.invoke(app, args)
        assert result.exit_code == 2, (args, result.output)
        assert "unknown.tx" in result.output and "outside its bounds [-10, 10]" in result.output


@pytest.mark.parametrize("args", [["--version"], ["schema"]])
def test_a_closed_pipe_on_stdout_is_exit_2_without_a_message(args):
    """The reader of stdout is gone before bcad writes (`bcad schema | true`): exit 2, as for a
    full device, and nothing on stderr (the reader left on purpose), never a traceback."""
    child = subprocess.Popen([sys.executable, "-m", "bcad.cli", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    child.stdout.close()  # long before the child has started, let alone written
    _, error = child.communicate(timeout=60)
    assert child.returncode == 2, error
    assert error == b""


def test_posterior_samples_past_half_a_minute_are_refused_before_any_work(tmp_path):
    """The one-link graph costs 20 links a sample (a cycle of 3 links, 1 L drawn: the closing
    link's distribution scores, it is not drawn; 16 overhead): at most 4e8 / 20 samples."""
    import time

    import bcad
    from bcad.errors import InputError

    problem = _problem(tmp_path)
    solution = tmp_path / "x.json"
    assert runner.invoke(app, ["solve", str(problem), "-o", str(solution), "--quiet"]).exit_code == 0
    started = time.perf_counter()
    result = runner.invoke(app, ["posterior", str(problem), "--at", str(solution), "--samples", "1e9"])
    assert result.exit_code == 2 and "at most 20,000,000" in result.output, result.output
    assert time.perf_counter() - started < 10
    # the same count from the problem's solver settings points at its line
    heavy = tmp_path / "heavy.yaml"
    heavy.write_text(problem.read_text().replace("posterior_samples: 2000", "posterior_samples: 100000000"))
    result = runner.invoke(app, ["solve", str(heavy)])
    line = next(i for i, text in enumerate(heavy.read_text().splitlines(), 1) if "posterior_samples" in text)
    assert result.exit_code == 2 and f"heavy.yaml:{line}:" in result.output, result.output
    # and validate, which passed it, refuses it with the same message at the same place
    checked = runner.invoke(app, ["validate", str(heavy)])
    assert checked.exit_code == 2 and checked.stderr == result.stderr, (checked.output, result.output)
    with pytest.raises(InputError, match="bcad.posterior: samples: .*at most 20,000,000"):
        bcad.posterior(problem, at=solution, samples=10**8)
    # just within the limit is accepted (checked, not run: the check is all that differs)
    from bcad.bayes.work import check_posterior_work
    from bcad.compiler import compile_problem
    from bcad.model.problem import load

    compiled = compile_problem(load(problem))
    check_posterior_work(compiled, 20_000_000, "--samples")
    with pytest.raises(InputError):
        check_posterior_work(compiled, 20_000_001, "--samples")


def test_the_posterior_reports_its_samples_as_it_draws_them(tmp_path):
    import numpy as np

    from bcad.bayes.run import posterior_document
    from bcad.compiler import compile_problem
    from bcad.model.problem import load

    compiled = compile_problem(load(_problem(tmp_path)))
    calls = []
    posterior_document(
        compiled,
        np.array([1.0]),
        samples=300_000,
        seed=0,
        estimator="linear",
        progress=lambda done, total: calls.append((done, total)),
    )
    assert len(calls) >= 2 and all(total == 300_000 for _, total in calls)
    done = [d for d, _ in calls]
    assert done == sorted(done) and done[-1] == 300_000 and done[0] < 300_000


def _touches(count: int) -> str:
    """The UR5 probe example with ``count`` copies of its touch (every one through the whole arm)."""
    import yaml

    document = yaml.safe_load((REPO / "problems" / "ur5_probe_face.yaml").read_text())
    document["robots"][0]["urdf"] = str(REPO / "robots" / "ur5.urdf")
    touch = document["relations"][0]
    document["relations"] = [{**touch, "name": f"touch{k}"} for k in range(count)]
    return yaml.safe_dump(document)


def test_a_search_through_too_many_chain_links_is_refused_at_once(tmp_path):
    """25 touches of a UR5 through its whole chain (18 links each: 450) would take about 45 s and
    over a GB; refused in seconds, naming the limit. 1000 relations pass the cycle limit first."""
    import time

    path = tmp_path / "touches.yaml"
    path.write_text(_touches(25))
    started = time.perf_counter()
    result = runner.invoke(app, ["solve", str(path), "--quiet"])
    assert result.exit_code == 2 and "hold 450 links" in result.output and "at most 400" in result.output, result.output
    assert time.perf_counter() - started < 20
    path.write_text(_touches(1000))
    result = runner.invoke(app, ["solve", str(path), "--quiet"])
    assert result.exit_code == 2 and "1000 cycles" in result.output and "at most 200" in result.output, result.output


def test_a_message_lists_a_few_names_and_counts_the_rest():
    """A measurement row naming an unknown joint listed every X joint of the problem (thousands of
    them in a generated problem): a message lists the first few and counts the others."""
    from bcad.errors import listed

    assert listed(["a", "b", "c"]) == "a, b, c"
    assert listed([f"j{k}" for k in range(5000)]) == "j0, j1, j2, j3, j4, j5, j6, j7 and 4992 more"
    assert listed(range(10), 2) == "0, 1 and 8 more"
