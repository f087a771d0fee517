"""The README's annotated example is a valid problem, and its quick start is two commands."""

from __future__ import annotations

import re

from bcad.compile import compile_problem
from bcad.model import load_problem

from conftest import REPO, RX90_URDF

README = (REPO / "README.md").read_text(encoding="utf-8")


def test_annotated_example_is_valid(write_problem):
    example = re.search(r"```yaml\n(.*?)```", README, re.S).group(1)
    example = example.replace("../robots/rx90.urdf", str(RX90_URDF))
    compiled = compile_problem(load_problem(write_problem(example)))
    stats = compiled.stats
    # X: fixture.rz and joints 1-5 (joint 6 is F); L: base (3), zeros (6),
    # fixture tx,ty (2), tool tz (1), and the relation's tz is scored, not integrated.
    assert stats.optimization_dim == 6
    assert stats.integration_dim == 12
    assert stats.cycles == 1
    assert stats.inequality_constraints == 4
    assert compiled.parameters.x_bounds[compiled.parameters.x_names.index("arm/joint_1.rz")] == (-1.0, 1.0)


def test_quick_start_is_two_commands():
    block = re.search(r"## Quick start\n\n```bash\n(.*?)```", README, re.S).group(1)
    commands = [line for line in block.splitlines() if line.strip()]
    assert commands == [
        "python -m pip install -e . && bcad solve problems/rx90_face_on_face.yaml",
        "python -m pip install -e '.[test]' && python -m pytest",
    ]
