"""Hostile numbers and settings: every one is refused by the schema with exit 2 and
FILE:LINE:COL, before it can make a loop endless, exhaust memory or reach the solver."""

from __future__ import annotations

import re

import pytest
from typer.testing import CliRunner

from bcad.cli import app

from conftest import ONE_LINK_GRAPH

runner = CliRunner()

CASES = {
    "NaN in a pose": ("pose: [3, 0, 0, 0, 0, 0]", "pose: [.nan, 0, 0, 0, 0, 0]", "finite"),
    "1e400 in a pose": ("pose: [3, 0, 0, 0, 0, 0]", "pose: [1e400, 0, 0, 0, 0, 0]", "finite"),
    "bounds of infinity": ("bounds: {tx: [-10, 10]}", "bounds: {tx: [-.inf, .inf]}", "finite"),
    "bounds of 1.7e308": ("bounds: {tx: [-10, 10]}", "bounds: {tx: [-1.7e308, 1.7e308]}", "greater than or equal"),
    "uniform(-inf, inf)": ("'normal(0, 0.3)'", "'uniform(-inf, inf)'", "finite"),
    "a standard deviation of 1e-300": ("'normal(0, 0.4)'", "'normal(0, 1e-300)'", "greater than or equal"),
    "a truncnormal with no mass": ("'normal(0, 0.3)'", "'truncnormal(0, 0.001, 50, 60)'", "probability"),
    # YAML's true and false are no numbers (pydantic's lax mode read true as 1: a std of 1)
    "a pose of true": ("pose: [3, 0, 0, 0, 0, 0]", "pose: [true, 0, 0, 0, 0, 0]", "got true; expected a number"),
    "bounds of false": ("bounds: {tx: [-10, 10]}", "bounds: {tx: [false, 10]}", "got false; expected a number"),
    "a std of true": ("'normal(0, 0.3)'", "{type: normal, mean: 0, std: true}", "std: got true; expected a number"),
}
SETTINGS = {
    "beta: .inf": "finite",
    "beta: 1.005": "greater than or equal",
    "mutation_scale: .inf": "finite",
    "population: 100000000": "less than or equal",
    "tournament: 1000000000": "less than or equal",
    "alpha: 0.999999999": "less than or equal",
    "generations_per_temperature: 1000000000": "less than or equal",
    "posterior_samples: 10000000000": "less than or equal",
    "selection_samples: 10000000000": "less than or equal",
    "max_samples: 100000000": "less than or equal",
    "posterior_samples: true": "got true; expected a whole number",
    "qmc: 2": "valid boolean",
}


def _refused(path, fragment):
    result = runner.invoke(app, ["validate", str(path)])
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert re.match(rf"{re.escape(str(path))}:\d+:\d+: ", result.stderr), result.stderr
    assert fragment in result.stderr, result.stderr


@pytest.mark.parametrize("case", CASES)
def test_non_finite_and_absurd_numbers_are_refused(write_problem, case):
    old, new, fragment = CASES[case]
    assert old in ONE_LINK_GRAPH
    _refused(write_problem(ONE_LINK_GRAPH.replace(old, new, 1)), fragment)


@pytest.mark.parametrize("setting", SETTINGS)
def test_every_solver_setting_is_bounded(write_problem, setting):
    _refused(write_problem(ONE_LINK_GRAPH + f"solver: {{{setting}}}\n"), SETTINGS[setting])


def test_the_sample_count_always_grows(write_problem):
    # beta = 1.1 on N0 = 5 rounds 5.5 to 6, and 1.1 * 6 = 6.6 to 7: the GA's phase 3 ends.
    path = write_problem(
        ONE_LINK_GRAPH + "solver: {estimator: mc, beta: 1.1, initial_samples: 5, max_samples: 40, population: 8}\n"
    )
    result = runner.invoke(app, ["solve", str(path), "--quiet", "--samples", "2000"])
    assert result.exit_code in (0, 3), result.output
