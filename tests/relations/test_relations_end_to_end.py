"""Every relation in a problem that solves (exit 0, no warning), and the UR5 probe
touching a sphere checked with Pinocchio."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from conftest import REPO, run_bcad

# A part on a fixture: the part's placement (tx, ty, tz, rz) is X, the fixture's is L; the
# relation from the fixture's entity to the part's closes the one cycle.
ENTITIES = {
    "face": {"type": "face", "pose": [0, 0, 0, 0, 0, 0], "size": [40, 30]},
    "point": {"type": "point", "at": [0, 0, 0]},
    "edge": {"type": "edge", "start": [0, 0, 0], "end": [30, 0, 0]},
    "sphere": {"type": "sphere", "center": [0, 0, 0], "radius": 6.0},
    "cylinder": {"type": "cylinder", "pose": [0, 0, 0, 0, 0, 0], "radius": 6.0, "length": 20.0},
}
CASES = {
    # relation: (parent, child overrides, statuses and distributions of the relation)
    "point_on_edge": ("edge", "point", {}, "FLLFFF", {"ty": "normal(0, 0.05)", "tz": "normal(0, 0.05)"}),
    "edge_on_edge": (
        "edge",
        "edge",
        {"end": [10, 0, 0]},
        "FLLFLL",
        {"ty": "normal(0, 0.05)", "tz": "normal(0, 0.05)", "ry": "normal(0, 0.005)", "rz": "normal(0, 0.005)"},
    ),
    "point_on_sphere": ("sphere", "point", {}, "FFLFFF", {"tz": "normal(0, 0.05)"}),
    "sphere_on_face": ("face", "sphere", {}, "FFLFFF", {"tz": "normal(0, 0.05)"}),
    "sphere_in_sphere": ("sphere", "sphere", {"radius": 5.9}, "FFFFFF", {}),
    "point_in_cylinder": ("cylinder", "point", {}, "FFFFFF", {}),
    "sphere_in_cylinder": ("cylinder", "sphere", {"radius": 5.9}, "FFFFFF", {}),
    "cylinder_in_cylinder": ("cylinder", "cylinder", {"radius": 5.9}, "FFFFFF", {}),
    "cylinder_on_face": (
        "face",
        "cylinder",
        {},
        "FFLLLF",
        {"tz": "normal(0, 0.05)", "rx": "normal(0, 0.002)", "ry": "normal(0, 0.002)"},
    ),
}


def _problem(kind: str) -> dict:
    parent_type, child_type, child_override, status, distributions = CASES[kind]
    start = {
        "point_on_sphere": [6.0, 0, 0],
        "sphere_on_face": [0, 0, 6.0],
        "cylinder_in_cylinder": [0, 0, 5.0],
        "point_in_cylinder": [0, 0, 10.0],
        "sphere_in_cylinder": [0, 0, 10.0],
    }.get(kind, [0.0, 0.0, 0.0])
    return {
        "name": kind,
        "units": {"length": "mm"},
        "frames": ["world", "fixture", "part"],
        "links": [
            {
                "name": "fixture_placement",
                "parent": "world",
                "child": "fixture",
                "status": "LLLFFF",
                "distributions": {"tx": "normal(0, 0.02)", "ty": "normal(0, 0.02)", "tz": "normal(0, 0.02)"},
            },
            {
                "name": "part_placement",
                "parent": "world",
                "child": "part",
                "pose": start + [0, 0, 0],
                "status": "XXXFFF",
                "bounds": {"tx": [-10, 10], "ty": [-10, 10], "tz": [-10, 16]},
            },
        ],
        "entities": [
            {"name": "host", "frame": "fixture", **ENTITIES[parent_type]},
            {"name": "guest", "frame": "part", **ENTITIES[child_type], **child_override},
        ],
        "relations": [
            {
                "name": "contact",
                "type": kind,
                "parent": "host",
                "child": "guest",
                "close": True,
                "status": status,
                "distributions": distributions,
            }
        ],
        "solver": {"posterior_samples": 20000},
    }


@pytest.mark.parametrize("kind", sorted(CASES))
def test_every_relation_solves(tmp_path, kind):
    path = tmp_path / f"{kind}.yaml"
    path.write_text(yaml.safe_dump(_problem(kind)))
    run = run_bcad("solve", path, "-o", tmp_path / "result.json", "--quiet")
    assert run.returncode == 0, run.stderr
    result = json.loads((tmp_path / "result.json").read_text())
    assert result["warnings"] == []
    link = result["posterior"]["links"]["contact"]
    if link["satisfied"] is not None:
        assert link["satisfied"] > 0.5
    # The scored parameters end where the relation wants them: within 3 posterior std of 0.
    for name in CASES[kind][4]:
        k = ["tx", "ty", "tz", "rx", "ry", "rz"].index(name)
        assert abs(link["weighted"]["mean"][k]) < 3 * link["weighted"]["std"][k] + 1e-9, (name, link["weighted"])


def test_a_point_on_sphere_on_a_tree_link_is_refused(tmp_path):
    problem = _problem("point_on_sphere")
    problem["relations"][0]["close"] = False
    problem["links"][0]["close"] = True  # the fixture's placement closes instead
    path = tmp_path / "tree.yaml"
    path.write_text(yaml.safe_dump(problem))
    run = run_bcad("validate", path)
    assert run.returncode == 2 and "must close a cycle" in run.stderr


def test_the_ur5_probe_touches_the_sphere(tmp_path):
    """At the solution, the tip computed by Pinocchio (UR5 + 150 mm probe, nominal) lies on the sphere."""
    import pinocchio as pin

    run = run_bcad(
        "solve", REPO / "problems" / "relations" / "ur5_probe_sphere.yaml", "-o", tmp_path / "r.json", "--quiet"
    )
    assert run.returncode == 0, run.stderr
    result = json.loads((tmp_path / "r.json").read_text())
    names = [
        "shoulder_pan_joint.rz",
        "shoulder_lift_joint.ry",
        "elbow_joint.ry",
        "wrist_1_joint.ry",
        "wrist_2_joint.rz",
    ]
    q = np.array([result["solution"][f"ur5/{n}"] for n in names] + [0.0])
    model = pin.buildModelFromUrdf(str(REPO / "robots" / "ur5.urdf"))
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    M = data.oMf[model.getFrameId("tool0")].homogeneous
    tip = (M[:3, :3] @ np.array([0, 0, 0.150]) + M[:3, 3]) * 1000.0
    assert abs(np.linalg.norm(tip - np.array([450.0, 100.0, 150.0])) - 12.7) < 0.01
    touch = result["posterior"]["links"]["touch"]
    assert abs(touch["weighted"]["mean"][2]) < 3 * touch["weighted"]["std"][2]
    assert touch["weighted"]["std"][2] < 0.03  # the touch scored within 0.02 mm


def test_the_part_edge_on_rail_example(tmp_path):
    run = run_bcad(
        "solve", REPO / "problems" / "relations" / "part_edge_on_rail.yaml", "-o", tmp_path / "r.json", "--quiet"
    )
    assert run.returncode == 0, run.stderr
    result = json.loads((tmp_path / "r.json").read_text())
    # The rail is the line y = 50 of the table: the part's edge goes on it, square to it, overlapping.
    assert abs(result["solution"]["gantry_axes.ty"] - 50.0) < 0.01
    assert abs(result["solution"]["gantry_axes.rz"]) < 1e-3
    assert -200.0 < result["solution"]["gantry_axes.tx"] < 300.0
    assert result["posterior"]["links"]["along"]["satisfied"] > 0.99


@pytest.mark.parametrize("kind", ["sphere_in_sphere", "cylinder_in_cylinder", "point_on_edge"])
def test_a_relation_on_a_tree_link_is_enforced_by_local_rejection(tmp_path, kind):
    """On a tree link, a relation's L parameters are drawn from their prior restricted to where its
    inequalities hold (Sect. 4.1.2): every drawn pose satisfies it, though the prior alone would not."""
    from bcad.bayes.sampling import FreeParameterSampler
    from bcad.compiler import compile_problem
    from bcad.model import load_problem

    problem = _problem(kind)
    statuses = {"sphere_in_sphere": "LLLFFF", "cylinder_in_cylinder": "LLLLLF", "point_on_edge": "LFFFFF"}[kind]
    spread = {
        "tx": "normal(0, 0.08)",
        "ty": "normal(0, 0.08)",
        "tz": "normal(0, 0.08)",
        "rx": "normal(0, 0.01)",
        "ry": "normal(0, 0.01)",
    }
    if kind == "point_on_edge":
        spread = {"tx": "normal(15, 10)"}
    if kind == "cylinder_in_cylinder":  # the peg halfway in, tilted by about its play over the engaged length
        spread.update(
            {"tx": "normal(0, 0.03)", "ty": "normal(0, 0.03)", "rx": "normal(0, 0.002)", "ry": "normal(0, 0.002)"}
        )
    relation = problem["relations"][0]
    if kind == "cylinder_in_cylinder":
        relation["pose"] = [0, 0, 10, 0, 0, 0]
    relation.update(
        {
            "close": False,
            "status": statuses,
            "distributions": {
                k: v for k, v in spread.items() if statuses["xyz".find(k[1]) + (3 if k[0] == "r" else 0)] == "L"
            },
        }
    )
    problem["links"][1].update(
        {
            "close": True,
            "status": "LLLFFF",
            "distributions": {"tx": "normal(0, 1)", "ty": "normal(0, 1)", "tz": "normal(0, 1)"},
        }
    )
    problem["links"][1].pop("bounds")
    path = tmp_path / "tree.yaml"
    path.write_text(yaml.safe_dump(problem))
    compiled = compile_problem(load_problem(path))
    link = next(k for k, l in enumerate(compiled.graph.links) if l.name == "contact")
    assert link not in compiled.graph.closing_links
    draws = FreeParameterSampler(compiled).draw(np.random.default_rng(3), 20000)
    table = compiled.parameters
    columns = [
        table.l_names.index(f"contact.{p}")
        for p in ("tx", "ty", "tz", "rx", "ry", "rz")
        if f"contact.{p}" in table.l_names
    ]
    names = [table.l_names[c].split(".")[1] for c in columns]
    nominal = np.array(problem["relations"][0].get("pose", [0.0] * 6), dtype=float)
    poses = np.tile(nominal, (len(draws), 1))
    for c, name in zip(columns, names):
        poses[:, ["tx", "ty", "tz", "rx", "ry", "rz"].index(name)] += draws[:, c]
    constraint = compiled.graph.links[link].relation
    assert np.all(constraint.inequalities(poses) <= 1e-12)
    # The same prior without the rejection: a good share of its draws break the relation.
    raw = np.tile(nominal, (len(draws), 1))
    rng = np.random.default_rng(4)
    for name in names:
        mean, std = (float(v) for v in spread[name].removeprefix("normal(").rstrip(")").split(","))
        raw[:, ["tx", "ty", "tz", "rx", "ry", "rz"].index(name)] += rng.normal(mean, std, len(raw))
    assert np.mean(np.any(constraint.inequalities(raw) > 0, axis=1)) > 0.01


ROTATION_CASES = {  # every relation with inequalities (a point on a sphere has none)
    **{kind: case for kind, case in CASES.items() if kind != "point_on_sphere"},
    "point_on_face": ("face", "point", {}, "FFLFFF", {"tz": "normal(0, 0.05)"}),
    "point_on_cylinder": ("cylinder", "point", {}, "FFLFFF", {"tz": "normal(0, 0.05)"}),
    "face_on_face": ("face", "face", {"size": [10, 10]}, "FFLLLF", CASES["cylinder_on_face"][4]),
    "edge_on_face": ("face", "edge", {"end": [10, 0, 0]}, "FFLLLF", CASES["cylinder_on_face"][4]),
}
#: the relations whose distances follow a point's (or a sphere's centre's) position alone
POSITION_ALONE = {
    "point_on_face",
    "point_on_edge",
    "point_in_cylinder",
    "point_on_cylinder",
    "sphere_on_face",
    "sphere_in_sphere",
    "sphere_in_cylinder",
}


@pytest.mark.parametrize("kind", sorted(ROTATION_CASES))
def test_a_relation_said_not_to_depend_on_the_rotation_does_not(monkeypatch, kind):
    """A relation whose distances skip the rotation matrices (a point's position alone) gives the
    distances it gives with them, at poses of every rotation; the others move with the rotation."""
    from bcad.compiler.problem import compile_any
    from bcad.kinematics.se3 import rpy_to_matrix

    monkeypatch.setitem(CASES, kind, ROTATION_CASES[kind])
    compiled = compile_any(_problem(kind))
    relation = next(link.relation for link in compiled.graph.links if link.relation is not None)
    assert relation.inequality_count > 0
    assert relation.depends_on_rotation == (kind not in POSITION_ALONE), kind
    rng = np.random.default_rng(3)
    poses = np.column_stack([rng.uniform(-8, 8, (200, 3)), rng.uniform(-3, 3, (200, 3))])
    translations = poses[:, :3].T
    if relation.curvilinear:
        translations = relation.cartesian(translations)

    def with_rotations(rotations):
        columns = np.transpose(rpy_to_matrix(rotations), (2, 1, 0))
        return relation.inequalities_from(columns, translations).T

    assert np.array_equal(relation.inequalities(poses), with_rotations(poses[:, 3:]))
    turned = with_rotations(rng.uniform(-3, 3, (200, 3)))
    assert np.array_equal(turned, with_rotations(poses[:, 3:])) == (not relation.depends_on_rotation)
