"""``bcad validate`` accepts a problem that describes a cell but gives solve nothing to do, and says
what solve (and posterior) would refuse in it (a note on stderr, exit 0)."""

from __future__ import annotations

import json

from conftest import RX90_EXAMPLE, run_bcad

TREE = """
name: tree
frames: [a, b]
links:
  - {name: ab, parent: a, child: b, status: LFFFFF, distributions: {tx: 'normal(0, 1)'}}
"""

NO_UNKNOWN = """
name: no-unknown
frames: [a, m]
links:
  - {name: placed, parent: a, child: m, status: LFFFFF, distributions: {tx: 'normal(1, 2)'}}
  - {name: measured, parent: a, child: m, pose: [3, 0, 0, 0, 0, 0], status: LFFFFF, close: true,
     distributions: {tx: 'normal(0, 0.4)'}}
"""


def test_a_problem_without_a_cycle_is_valid_and_named_as_one_solve_refuses(write_problem):
    run = run_bcad("validate", write_problem(TREE), "--json")
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout)["stats"]["cycles"] == 0
    assert "note: bcad solve and bcad posterior refuse this problem: the problem has no cycle" in run.stderr
    # and both do refuse it (posterior for the same reason; solve first for its lack of X)
    assert run_bcad("solve", write_problem(TREE)).returncode == 2
    sampled = run_bcad("posterior", write_problem(TREE), "--samples", "1e3")
    assert sampled.returncode == 2 and "the problem has no cycle" in sampled.stderr


def test_a_problem_without_x_is_named_as_one_only_posterior_takes(write_problem):
    run = run_bcad("validate", write_problem(NO_UNKNOWN))
    assert run.returncode == 0, run.stderr
    assert "note: bcad solve refuses this problem: the problem has no X" in run.stderr
    assert run_bcad("posterior", write_problem(NO_UNKNOWN), "--samples", "1e3", "--json").returncode == 0


def test_a_solvable_problem_gets_no_note():
    run = run_bcad("validate", RX90_EXAMPLE)
    assert run.returncode == 0 and "note:" not in run.stderr


def test_fewer_initial_draws_than_the_population_is_refused_where_written(write_problem):
    """The GA draws each individual of its first population once at least: a budget below the
    population could never initialise it (it stopped the mc solve with 'no random X gave a non-zero
    objective')."""
    text = TREE + "solver: {estimator: mc, population: 12, elite: 2, max_initial_draws: 11}\n"
    run = run_bcad("validate", write_problem(text))
    assert run.returncode == 2, run.stderr
    assert "problem.yaml:5:9: solver: max_initial_draws (11) must be at least population (12)" in run.stderr
    assert run_bcad("validate", write_problem(text.replace("draws: 11", "draws: 12"))).returncode == 0
