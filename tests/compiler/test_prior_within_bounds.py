"""A prior on an X that puts no probability within its bounds is refused at the prior (exit 2):
p(X) would be 0 wherever the search may go, and the run would end at log p(X) I(X) = -inf."""

from __future__ import annotations

import pytest

from bcad.compiler import compile_problem
from bcad.errors import InputError
from bcad.model import load_problem

from conftest import ONE_LINK_GRAPH, run_bcad


@pytest.mark.parametrize(
    "prior, refused",
    [
        ("uniform(15, 16)", True),
        ("truncnormal(20, 1, 19, 21)", True),
        ("uniform(9, 12)", False),
        ("normal(50, 1)", False),
    ],
)
def test_a_link_prior_outside_its_bounds_is_refused(write_problem, prior, refused):
    text = ONE_LINK_GRAPH.replace("'normal(1, 2)'", f"'{prior}'")
    assert text != ONE_LINK_GRAPH
    path = write_problem(text)
    if not refused:
        compile_problem(load_problem(path))
        return
    run = run_bcad("validate", path)
    assert run.returncode == 2 and "Traceback" not in run.stderr
    assert "the prior on tx (its support [" in run.stderr and "within its bounds [-10, 10]" in run.stderr


def test_a_joint_prior_outside_its_bounds_is_refused(write_problem):
    text = """
name: slider
frames: [w, tip, target]
robots:
  - name: arm
    parent: w
    dh:
      - {a: 0.3, alpha: 0, d: 0, theta: 0, limits: [-3, 3]}
    joints:
      joint_1: {status: X, bounds: [-1, 1], prior: 'uniform(2, 3)', zero: 'normal(0, 0.001)'}
links:
  - {name: t, parent: arm/link_1, child: tip}
  - {name: g, parent: w, child: target, pose: [0.3, 0, 0, 0, 0, 0]}
  - {name: c, parent: target, child: tip, close: true, status: LLFFFF,
     distributions: {tx: 'normal(0, 0.01)', ty: 'normal(0, 0.01)'}}
"""
    with pytest.raises(InputError, match=r"the prior on joint 'joint_1' \(its support \[2, 3\]\) puts no probability"):
        compile_problem(load_problem(write_problem(text)))
