"""The Bayesian solver on problems whose answer is known in closed form."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from bcad.bayes.objective import Objective
from bcad.bayes.run import solve_document as solve
from bcad.bayes.sampling import FreeParameterSampler
from bcad.cli import app
from bcad.compiler import compile_problem
from bcad.kinematics import Samples
from bcad.model import load_problem

from conftest import ONE_LINK_GRAPH

runner = CliRunner()

ONE_LINK = (
    ONE_LINK_GRAPH + "solver: {population: 16, max_samples: 1024, posterior_samples: 200000, selection_samples: 4096}\n"
)
# The optimum is the precision-weighted mean of the prior's 1 (precision 1/4) and 3 (precision 4).
X_STAR = (1 / 4 * 1 + 4 * 3) / (1 / 4 + 4)


def _log_normal(x, mean, std):
    return -0.5 * ((x - mean) / std) ** 2 - math.log(std) - 0.5 * math.log(2 * math.pi)


@pytest.fixture
def one_link(write_problem):
    return compile_problem(load_problem(write_problem(ONE_LINK)))


def test_monte_carlo_estimate_matches_the_closed_form_integral(one_link):
    objective = Objective(one_link)
    samples = Samples(FreeParameterSampler(one_link).draw(np.random.default_rng(0), 200000))
    xs = np.array([[1.5], [2.5], [3.0], [3.8]])
    estimate = objective.log_value(xs, samples, 0.0)
    exact = np.array([_log_normal(x, 1, 2) + _log_normal(x, 3, 0.5) for x in xs[:, 0]])
    np.testing.assert_allclose(estimate, exact, atol=0.02)


def test_solution_and_posterior_match_the_closed_form(one_link):
    result = solve(one_link, backend="bayes", seed=3)
    x = result["solution"]["unknown.tx"]
    assert x == pytest.approx(X_STAR, abs=0.03)
    link = result["posterior"]["links"]["measured"]
    assert link["constrained"] == ["tx"]
    # The state of the cycle at X*: Q = X* + L (Table 2's mean and std) ...
    assert link["mean"][0] == pytest.approx(x, abs=0.005)
    assert link["std"][0] == pytest.approx(0.3, rel=0.01)
    # ... and the posterior weighted by the closing link's own N(3, 0.4^2).
    precision = 1 / 0.3**2 + 1 / 0.4**2
    assert link["weighted"]["std"][0] == pytest.approx(precision**-0.5, rel=0.02)
    assert link["weighted"]["mean"][0] == pytest.approx((x / 0.3**2 + 3 / 0.4**2) / precision, abs=0.005)
    exact = _log_normal(x, 1, 2) + _log_normal(x, 3, 0.5)
    assert result["objective"]["log_value"] == pytest.approx(exact, abs=0.02)


def test_nominal_backend_closes_the_cycle_exactly(one_link):
    result = solve(one_link, backend="nominal", seed=0, posterior_samples=1000)
    assert result["solution"]["unknown.tx"] == pytest.approx(3.0, abs=1e-6)
    assert result["diagnostics"]["nominal"]["closed"] is True


def test_same_seed_same_bytes_except_timings(write_problem):
    path = write_problem(ONE_LINK)
    outputs = []
    for _ in range(2):
        result = runner.invoke(app, ["solve", str(path), "--seed", "5", "--quiet", "--samples", "2e4"])
        assert result.exit_code == 0, result.stderr
        document = json.loads(result.stdout)
        document["stats"].pop("seconds")
        document["diagnostics"].pop("timings")
        outputs.append(json.dumps(document, sort_keys=True))
    assert outputs[0] == outputs[1]
    other = runner.invoke(app, ["solve", str(path), "--seed", "6", "--quiet", "--samples", "2e4"])
    # Another seed draws other samples; the default search (Newton on the linearised
    # objective, from the nominal solution) is deterministic and finds the same X.
    assert json.loads(other.stdout)["objective"]["log_value"] != json.loads(outputs[0])["objective"]["log_value"]
    assert json.loads(other.stdout)["solution"]["unknown.tx"] == pytest.approx(
        json.loads(outputs[0])["solution"]["unknown.tx"], abs=1e-6
    )


def test_posterior_command_reproduces_the_solve_posterior(write_problem, tmp_path):
    path = write_problem(ONE_LINK)
    out = tmp_path / "result.json"
    assert runner.invoke(app, ["solve", str(path), "-o", str(out), "--seed", "2", "--samples", "1e4"]).exit_code == 0
    solved = json.loads(out.read_text())
    again = runner.invoke(app, ["posterior", str(path), "--at", str(out), "--samples", "1e4", "--seed", "2", "--json"])
    assert again.exit_code == 0, again.stderr
    assert json.loads(again.stdout)["posterior"] == solved["posterior"]
    by_hand = runner.invoke(app, ["posterior", str(path), "--value", "unknown.tx=3", "--samples", "2.5e4", "--json"])
    link = json.loads(by_hand.stdout)["posterior"]["links"]["measured"]
    assert link["mean"][0] == pytest.approx(3.0, abs=0.01)
    assert json.loads(by_hand.stdout)["posterior"]["samples"] == 25000
