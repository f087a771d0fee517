"""Tables never cut a number: at any width, in a terminal or piped, every estimate of
the solve/posterior (Table 2) and calibrate tables is printed whole."""

from __future__ import annotations

import io
import json
import re

import pytest
from rich.console import Console

from bcad.bayes.result import DesignResult
from bcad.calibration.report import calibration_table
from bcad.report import contributors_table, posterior_table
from bcad.tables import WholeTable

from conftest import REPO, run_bcad, rx90_solved

WIDTHS = (40, 52, 60, 68, 80, 100, 160)


def _render(renderable, width: int) -> str:
    buffer = io.StringIO()
    Console(file=buffer, width=width, force_terminal=False, color_system=None).print(renderable)
    return buffer.getvalue()


def _tokens(text: str) -> set[str]:
    return set(re.findall(r"[-+]?\d[\d.e+-]*", text))


@pytest.fixture(scope="module")
def posterior_result(tmp_path_factory):
    return json.loads(rx90_solved(tmp_path_factory).read_text())


@pytest.fixture(scope="module")
def calibration_result():
    run = run_bcad("calibrate", "problems/calibration/rx90_sphere_touches.yaml", "--json", "--quiet", cwd=REPO)
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout)


@pytest.mark.parametrize("width", WIDTHS)
def test_table_2_shows_every_figure_whole(posterior_result, width):
    text = _render(posterior_table(DesignResult.model_validate(posterior_result)), width)
    assert "…" not in text
    assert max(len(line) for line in text.splitlines()) <= width
    tokens = _tokens(text)
    for link in posterior_result["posterior"]["links"].values():
        for key in ("mean", "std", "mean_se", "std_se"):  # each figure and its standard error
            for value in link[key] + link["weighted"][key]:
                # four decimals, or two significant digits where those would keep fewer
                assert f"{value:.4f}" in tokens or any(_two_digits(token, value) for token in tokens), (
                    width,
                    key,
                    value,
                )


def _two_digits(token: str, value: float) -> bool:
    """Whether ``token`` is ``value`` to two significant digits."""
    try:
        shown = float(token)
    except ValueError:
        return False
    return abs(value) < 0.00095 and abs(shown - value) <= 0.051 * abs(value)


def test_a_figure_too_small_for_four_decimals_keeps_two_digits_unless_it_is_round_off():
    from bcad.report import _figure

    values = (1.0e-5, -4.86e-5, 0.000485, 0.00012, -0.00096, 0.0011, 0.0, 20.42719, None)
    assert [_figure(v) for v in values] == [
        "1.0e-5",
        "-4.9e-5",
        "0.00049",
        "0.00012",
        "-0.0010",  # two digits at four decimals already
        "0.0011",
        "0.0000",
        "20.4272",
        "-",
    ]
    assert _figure(3.1e-17, round_off=1e-9) == "0.0000" and _figure(1e-5, round_off=1e-9) == "1.0e-5"


def test_round_off_beside_a_turned_frame_reads_as_zero(write_problem):
    """A frame turned by pi/2 leaves 1e-17 in the closing link's ty: noise, shown as 0.0000; a
    std of 10 um in metres beside it keeps its digits."""
    path = write_problem(
        """
        name: rot
        frames: [a, m, n, b]
        links:
          - {name: unknown, parent: a, child: m, status: XFFFFF, bounds: {tx: [-10, 10]}}
          - {name: turn, parent: m, child: n, pose: [0, 0, 0, 1.5707963267948966, 0, 0]}
          - {name: free, parent: n, child: b, status: FLFFFF, distributions: {ty: 'normal(0.5, 1e-5)'}}
          - {name: measured, parent: a, child: b, pose: [3, 0, 0.5, 0, 0, 0], status: LFFFFF, close: true,
             distributions: {tx: 'normal(0, 0.4)'}}
        """
    )
    run = run_bcad("posterior", path, "--value", "unknown.tx=3", "--samples", "2000", "--json")
    link = json.loads(run.stdout)["posterior"]["links"]["measured"]
    assert 0 < abs(link["mean"][1]) < 1e-15  # the round-off the table hides
    assert 5e-6 < link["std"][2] < 2e-5  # tz: the free link's 1e-5 turned into z
    text = _render(posterior_table(DesignResult.model_validate(json.loads(run.stdout))), 120)
    mantissa, exponent = f"{link['std'][2]:.1e}".split("e")
    assert "e-1" not in text and f"{mantissa}e{int(exponent)}" in text, text  # 1.0e-5: two digits kept
    # the legend names the constrained parameters (a redirected table has no bold to show them)
    assert "bold: constrained parameters (tx)" in " ".join(text.split()), text


def test_an_angle_s_standard_error_beside_a_long_length_is_not_round_off():
    """The round-off was ROUND_OFF times the table's largest figure of any unit: a drill plan's
    1565 mm mean hid its rotations' 1e-6 rad standard errors as 0.0000. Lengths and angles now
    have a round-off each."""
    from types import SimpleNamespace

    from bcad.report import _figure, _round_off

    link = SimpleNamespace(
        params=["tx", "ty", "tz", "rx", "ry", "rz"],
        mean=[1565.0, -3e-13, 200.0, 0.5, 1e-17, -1.2],
        mean_se=[6e-5, 6e-5, 6e-5, 1.02e-6, 1.02e-6, 5.5e-7],
        std=[0.0258, 0.0263, 0.0238, 1e-4, 1e-4, 1e-4],
        std_se=[1e-5] * 6,
        weighted=None,
    )
    lengths, angles = _round_off([link])[True], _round_off([link])[False]
    assert [_figure(v, round_off=angles) for v in link.mean_se[3:]] == ["1.0e-6", "1.0e-6", "5.5e-7"]
    assert _figure(link.mean[1], round_off=lengths) == "0.0000"  # 3e-13 beside 1565: round-off
    assert _figure(link.mean[4], round_off=angles) == "0.0000"  # 1e-17 beside 1.2 rad
    # a rotation-only closure: every length is round-off, with nothing of its kind beside it
    turned = SimpleNamespace(**{**vars(link), "mean": [-1.1e-17, 5.4e-17, -1.4e-17, 0.5, 0.2, 0.1]})
    turned.mean_se = [1e-19] * 3 + [1e-3] * 3
    turned.std = turned.std_se = [2e-18] * 3 + [1e-3] * 3
    lengths = _round_off([turned])[True]
    assert [_figure(v, round_off=lengths) for v in turned.mean[:3]] == ["0.0000"] * 3


def test_a_camera_s_prior_reads_as_written():
    """A focal length's prior normal(1100, 50) read [1.1e+03 ± 50]: its mean keeps five digits."""
    document = {
        "problem": "eye",
        "units": {"length": "mm", "angle": "rad"},
        "parameters": {
            "camera.fx": {
                "kind": "L",
                "estimate": 1103.2,
                "std": 2.1,
                "prior": "gaussian",
                "prior_mean": 1100.0,
                "prior_std": 50.0,
                "identified": True,
                "unit": "px",
            }
        },
    }
    text = _render(calibration_table(document), 120)
    assert "[1100 ± 50]" in text and "e+03" not in text, text


@pytest.mark.parametrize("width", WIDTHS)
def test_calibration_table_shows_every_estimate_whole(calibration_result, width):
    text = _render(calibration_table(calibration_result), width)
    assert "…" not in text
    tokens = _tokens(text)
    for name, entry in calibration_result["parameters"].items():
        assert f"{entry['estimate']:.5g}" in tokens, (width, name)
        assert f"{entry['std']:.3g}" in tokens, (width, name)


@pytest.mark.parametrize("width", (40, 60, 80))
def test_contributors_table_keeps_its_stds(posterior_result, width):
    text = _render(contributors_table(DesignResult.model_validate(posterior_result)), width)
    assert "…" not in text
    units = posterior_result["units"]
    for parameters in posterior_result["contributors"].values():
        for parameter, entry in parameters.items():
            assert f"{entry['std']:.4g}" in _tokens(text)
            # with its unit beside it, the problem's (the RX90 example: mm and rad)
            unit = units["length"] if parameter.startswith("t") else units["angle"]
            std = re.escape(f"{entry['std']:.4g}")
            assert re.search(rf"{std}\s+{unit}\b", text), (parameter, unit)


def test_the_wide_layout_is_kept_where_it_fits(posterior_result):
    """At 160 columns Table 2 is the paper's layout (parameters as columns); at 40 it is records."""
    table = posterior_table(DesignResult.model_validate(posterior_result))
    assert isinstance(table, WholeTable)
    wide = _render(table, 160)
    assert re.search(r"tx \(mm\).*ty \(mm\).*rz \(rad\)", wide)
    narrow = _render(table, 40)
    assert "contact tx (mm)" in narrow and "w std" in narrow


def test_piped_commands_print_whole_numbers(tmp_path):
    """`bcad calibrate` piped (rich's 80 columns) and at a 60-column terminal."""
    for columns in ("80", "60"):
        run = run_bcad("calibrate", "problems/calibration/ur5_tracker.yaml", cwd=REPO, env_extra={"COLUMNS": columns})
        assert run.returncode in (0, 3), run.stderr
        assert "…" not in run.stdout + run.stderr


def test_the_statistics_title_is_one_line_in_80_columns():
    """validate's title wrapped as '... (Table' / '1)': the table is as wide as its title."""
    from bcad.compiler import compile_problem
    from bcad.model import load_problem
    from bcad.report import stats_table

    compiled = compile_problem(load_problem(REPO / "problems" / "rx90_face_on_face.yaml"))
    out = io.StringIO()
    Console(file=out, width=80, color_system=None).print(stats_table(compiled))
    assert out.getvalue().splitlines()[0].strip() == "rx90-face-on-face: problem statistics (Table 1)"
