"""End-to-end cases beyond the paper's example: degrees, two cycles, prismatic joints, QMC."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from bcad.bayes.run import solve_document as solve
from bcad.compiler import compile_problem
from bcad.kinematics import Samples
from bcad.model import load_problem

from conftest import ONE_LINK_GRAPH


def test_results_are_reported_in_degrees_when_the_problem_is(write_problem):
    # Rotational twin of the one-link problem: Q = X + L about z, L ~ N(0, 2 deg),
    # the closing link scores Q - 30 deg ~ N(0, 3 deg); X uniform on [-90, 90] deg.
    text = """
    name: turn
    units: {angle: deg}
    frames: [a, m, b]
    links:
      - {name: unknown, parent: a, child: m, status: FFFFFX, bounds: {rz: [-90, 90]}}
      - {name: free, parent: m, child: b, status: FFFFFL, distributions: {rz: 'normal(0, 2)'}}
      - {name: measured, parent: a, child: b, pose: [0, 0, 0, 0, 0, 30], status: FFFFFL, close: true, distributions: {rz: 'normal(0, 3)'}}
    solver: {population: 16, max_samples: 1024, posterior_samples: 50000}
    """
    result = solve(compile_problem(load_problem(write_problem(text))), backend="bayes", seed=0)
    assert result["units"]["angle"] == "deg"
    assert result["solution"]["unknown.rz"] == pytest.approx(30.0, abs=0.5)
    link = result["posterior"]["links"]["measured"]
    assert link["std"][5] == pytest.approx(2.0, rel=0.02)
    assert link["mean"][5] == pytest.approx(result["solution"]["unknown.rz"], abs=0.05)


def test_two_cycles_are_closed_together(write_problem):
    # Two measurements of the same unknown through two free links: two closing links.
    text = """
    name: two-cycles
    frames: [a, m, b, c]
    links:
      - {name: unknown, parent: a, child: m, status: XFFFFF, bounds: {tx: [-10, 10]}}
      - {name: free_b, parent: m, child: b, status: LFFFFF, distributions: {tx: 'normal(0, 0.2)'}}
      - {name: free_c, parent: m, child: c, status: LFFFFF, distributions: {tx: 'normal(0, 0.2)'}}
      - {name: seen_b, parent: a, child: b, pose: [2, 0, 0, 0, 0, 0], status: LFFFFF, close: true, distributions: {tx: 'normal(0, 0.2)'}}
      - {name: seen_c, parent: a, child: c, pose: [3, 0, 0, 0, 0, 0], status: LFFFFF, close: true, distributions: {tx: 'normal(0, 0.2)'}}
    solver: {population: 16, max_samples: 1024, posterior_samples: 50000}
    """
    compiled = compile_problem(load_problem(write_problem(text)))
    assert compiled.stats.cycles == 2
    result = solve(compiled, backend="bayes", seed=0)
    # Both cycles pull X towards their own measurement with equal weight: the optimum is 2.5.
    assert result["solution"]["unknown.tx"] == pytest.approx(2.5, abs=0.05)
    assert set(result["posterior"]["links"]) == {"seen_b", "seen_c"}
    nominal = solve(compiled, backend="nominal", seed=0, posterior_samples=1000)
    assert nominal["solution"]["unknown.tx"] == pytest.approx(2.5, abs=1e-6)  # least squares agrees


def test_quasi_monte_carlo_solves_the_closed_form_problem(write_problem):
    text = ONE_LINK_GRAPH + "solver: {population: 16, max_samples: 1024, posterior_samples: 65536, qmc: true}\n"
    result = solve(compile_problem(load_problem(write_problem(text))), backend="bayes", seed=0)
    assert result["solution"]["unknown.tx"] == pytest.approx((0.25 + 12) / 4.25, abs=0.03)
    assert result["posterior"]["links"]["measured"]["std"][0] == pytest.approx(0.3, rel=0.005)


def test_prismatic_and_negative_axis_joints_match_pinocchio(write_problem, tmp_path):
    urdf = tmp_path / "slide.urdf"
    urdf.write_text(
        """<robot name="slide">
  <link name="base"/><link name="carriage"/><link name="arm"/><link name="tool"/>
  <joint name="rail" type="prismatic"><parent link="base"/><child link="carriage"/>
    <origin xyz="0.1 0 0.2" rpy="0 0.3 0"/><axis xyz="1 0 0"/><limit lower="-0.5" upper="0.5" effort="1" velocity="1"/></joint>
  <joint name="turn" type="revolute"><parent link="carriage"/><child link="arm"/>
    <origin xyz="0 0.2 0" rpy="0.4 0 0"/><axis xyz="0 0 -1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="flange" type="fixed"><parent link="arm"/><child link="tool"/><origin xyz="0.3 0 0" rpy="0 0 0.5"/></joint>
</robot>"""
    )
    text = f"""
    name: slide
    frames: [world]
    robots:
      - name: r
        urdf: {urdf}
        parent: world
        joints:
          default:
            status: X
          rail:
            zero: normal(0, 0.01)
    """
    compiled = compile_problem(load_problem(write_problem(text)))
    assert compiled.parameters.x_names == ["r/rail.tx", "r/turn.rz"]
    # The negative axis: the link parameter is -q, so its bounds are the negated limits.
    assert compiled.parameters.x_bounds[1] == (-2.0, 2.0)
    rng = np.random.default_rng(0)
    q = np.column_stack([rng.uniform(-0.5, 0.5, 20), rng.uniform(-2, 2, 20)])
    zero = rng.normal(0, 0.01, size=(20, 1))
    link_values = np.column_stack([q[:, 0], -q[:, 1]])  # X holds tx = q_rail and rz = -q_turn
    tool = (
        compile_problem(load_problem(write_problem(text)))
        .frame_transforms(link_values, Samples(zero))["r/tool"]
        .matrices()
    )
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    frame = model.getFrameId("tool")
    for n in range(20):
        pin.framesForwardKinematics(model, data, np.array([q[n, 0] + zero[n, 0], q[n, 1]]))
        np.testing.assert_allclose(tool[n], data.oMf[frame].homogeneous, atol=1e-12)
