"""Closing links whose ry is near +-90 degrees: the rpy angles' gimbal lock, said as a finding."""

from __future__ import annotations

import json

import numpy as np
from scipy.spatial.transform import Rotation

from bcad import api

from conftest import REPO

WALL_TOUCH = """\
name: arm3-wall
frames: [base, j1, z1, e1, j2, z2, e2, j3, z3, tool, wall]
links:
  - {name: q1, parent: base, child: j1, status: FFFFFX, bounds: {rz: [-3.1, 3.1]}}
  - {name: zero1, parent: j1, child: z1, status: FFFFFL, distributions: {rz: 'normal(0, 0.01)'}}
  - {name: l1, parent: z1, child: e1, pose: [0.5, 0, 0, 0, 0, 0]}
  - {name: q2, parent: e1, child: j2, status: FFFFFX, bounds: {rz: [-3.1, 3.1]}}
  - {name: zero2, parent: j2, child: z2, status: FFFFFL, distributions: {rz: 'normal(0, 0.01)'}}
  - {name: l2, parent: z2, child: e2, pose: [0.4, 0, 0, 0, 0, 0]}
  - {name: q3, parent: e2, child: j3, status: FFFFFX, bounds: {rz: [-3.1, 3.1]}}
  - {name: zero3, parent: j3, child: z3, status: FFFFFL, distributions: {rz: 'normal(0, 0.02)'}}
  - {name: l3, parent: z3, child: tool, pose: [0.2, 0, 0, 0, 0, 0]}
  - {name: fixture, parent: base, child: wall, pose: [0.8, 0.3, 0, 0, 0, 0], status: LLFFFF,
     distributions: {tx: 'normal(0, 0.002)', ty: 'uniform(-0.01, 0.01)'}}
entities:
  - {name: panel, type: face, frame: wall, pose: [0, 0, 0, 0, -1.5707963267948966, 0], size: [0.2, 0.2]}
  - {name: tip, type: point, frame: tool, at: [0, 0, 0]}
relations:
  - {name: touch, type: point_on_face, parent: panel, child: tip, status: FFLFFF,
     distributions: {tz: 'normal(0, 0.002)'}}
"""


def test_near_ninety_degrees_rx_and_rz_spread_where_their_difference_does_not():
    """The finding's claim, checked with scipy's rotations (not bcad's): small rotations about a
    pose whose ry is 3 degrees from 90 spread rx and rz over several times their width, together,
    and rz - rx within it."""
    rng = np.random.default_rng(0)
    centre = Rotation.from_euler("ZYX", [0.3, np.pi / 2 - np.radians(3.0), 0.2])
    width = 1e-3
    turned = Rotation.from_rotvec(rng.normal(0.0, width, (2000, 3))) * centre
    rz, ry, rx = turned.as_euler("ZYX").T  # R = Rz(rz) Ry(ry) Rx(rx)
    assert min(rx.std(), rz.std()) > 8 * width
    assert (rz - rx).std() < 2 * width and np.corrcoef(rx, rz)[0, 1] > 0.99


def test_a_closing_link_near_ninety_degrees_has_the_finding_and_one_near_zero_not(tmp_path):
    path = tmp_path / "wall.yaml"
    path.write_text(WALL_TOUCH)
    result = json.loads(
        api.posterior(path, values={"q1.rz": 1.0252, "q2.rz": -1.5751, "q3.rz": 0.6182}, samples=20000).to_json()
    )
    link = result["posterior"]["links"]["touch"]
    ry = link["mean"][link["params"].index("ry")]
    assert abs(np.degrees(ry) - 90.0) < 6.0  # the face turned by -90 degrees about y
    (finding,) = [f for f in result["findings"] if f["code"] == "gimbal_lock"]
    assert "closing link 'touch'" in finding["message"] and "only rz - rx is" in finding["message"]
    assert result["warnings"] == []
    planar = json.loads(
        api.posterior(
            REPO / "problems" / "studies" / "planar_2r.yaml",
            values={"joint1.rz": 0.5, "joint2.rz": -1.0},
            samples=20000,
        ).to_json()
    )
    assert not [f for f in planar["findings"] if f["code"] == "gimbal_lock"]


def test_the_finding_s_edges_its_minus_ninety_wording_and_a_rotation_without_spread():
    """Stand-in posteriors: within 6 degrees of +-90 with a spread, the finding names the
    combination that holds (the scipy check above at +90; at -90, rz + rx); not at 84 degrees,
    nor where rx and rz do not spread beyond rounding."""
    from types import SimpleNamespace

    from bcad.bayes.trust import gimbal_findings

    def posterior(ry_degrees: float, spread: float):
        mean = np.array([0.0, 0.0, 0.0, 0.1, np.radians(ry_degrees), 0.2])
        std = np.array([1.0, 1.0, 1.0, spread, 0.01, spread])
        return SimpleNamespace(links=[SimpleNamespace(name="contact", mean=mean, std=std)])

    (minus,) = gimbal_findings(posterior(-88.0, 0.05))
    assert "-88.0 degrees" in minus["message"] and "only rz + rx is" in minus["message"]
    assert len(gimbal_findings(posterior(84.1, 0.05))) == 1 and not gimbal_findings(posterior(83.9, 0.05))
    assert not gimbal_findings(posterior(90.0, 1e-17)) and not gimbal_findings(posterior(0.0, 0.05))
    # scipy at -90: rx and rz spread in opposite directions, rz + rx within the rotation's width
    centre = Rotation.from_euler("ZYX", [0.3, -np.pi / 2 + np.radians(3.0), 0.2])
    turned = Rotation.from_rotvec(np.random.default_rng(1).normal(0.0, 1e-3, (2000, 3))) * centre
    rz, _, rx = turned.as_euler("ZYX").T
    assert (rz + rx).std() < 2e-3 and np.corrcoef(rx, rz)[0, 1] < -0.99
