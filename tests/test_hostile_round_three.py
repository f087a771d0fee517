"""Inputs of a hostile sweep: each once took a traceback, a quadratic scan or an unbounded amount
of work or memory, and is now refused at its place (exit 2) or handled in proportion to its size."""

from __future__ import annotations

import struct
import textwrap
import zipfile
import zlib

import numpy as np
import pytest
from typer.testing import CliRunner

from bcad.cli import app

from conftest import ONE_LINK_GRAPH, REPO, run_bcad

runner = CliRunner()


def chain_problem(links: int) -> str:
    """A serial chain of ``links`` links, frame f0 to f``links``: no cycle."""
    frames = ", ".join(f"f{k}" for k in range(links + 1))
    rows = "".join(
        f"  - {{name: l{k}, parent: f{k}, child: f{k + 1}, pose: [0.1, 0, 0, 0, 0, 0]}}\n" for k in range(links)
    )
    return f"name: chain\nframes: [{frames}]\nlinks:\n{rows}"


def test_graph_prints_a_chain_deeper_than_the_recursion_limit(tmp_path):
    """``bcad graph`` grew its tree by recursion: a chain of 1000 links was a RecursionError (exit
    1). Its tree is grown from a stack: every frame once, each the child of the one before."""
    from bcad.compiler import compile_problem
    from bcad.model import load_problem
    from bcad.report import graph_tree

    path = tmp_path / "chain.yaml"
    path.write_text(chain_problem(1500))
    printed = runner.invoke(app, ["graph", str(path)])
    assert printed.exit_code == 0, printed.output
    node = graph_tree(compile_problem(load_problem(path))).children[0]  # the spanning tree
    depth = 0
    while node.children:
        assert len(node.children) == 1
        node = node.children[0]
        depth += 1
        assert node.label.plain.startswith(f"f{depth} via l{depth - 1}")
    assert depth == 1500


def test_a_wide_csv_header_is_read_in_one_pass_and_a_late_duplicate_named(tmp_path):
    """The header's duplicate check compared each name with all before it: 400,000 columns ran for
    about a quarter of an hour. A duplicate is still named at its own column."""
    from bcad.calibration.model import read_csv_table
    from bcad.errors import InputError

    names = [f"x{k}" for k in range(200_000)]
    path = tmp_path / "wide.csv"
    path.write_text(",".join(["a", *names, "x7"]) + "\n" + ",".join(["1"] * (len(names) + 2)) + "\n")
    with pytest.raises(InputError) as refused:
        read_csv_table(path, "a table", ["a"])
    column = len(",".join(["a", *names])) + 2
    assert refused.value.line == 1 and refused.value.column == column
    assert "the header names the column 'x7' twice" in str(refused.value)


def tiny_png(width: int, height: int) -> bytes:
    """A PNG's signature, its header for a ``width`` x ``height`` grey image and a few rows of
    zeros: a few dozen bytes that claim billions of pixels."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    rows = zlib.compress(b"\0" * (width + 1) * 4)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", rows) + chunk(b"IEND", b"")


def test_detect_refuses_an_image_past_the_pixel_limit_as_input(tmp_path):
    """OpenCV refuses an image beyond its pixel limit with an exception, not an empty image: it was
    an internal error (exit 1). It is the same refusal as an unreadable image: exit 2."""
    pytest.importorskip("cv2")
    (tmp_path / "bomb.png").write_bytes(tiny_png(20_000, 20_000))
    (tmp_path / "views.csv").write_text("image,ur5/joint_1\nbomb.png,0\n")
    # in a process of its own: OpenCV reads its pixel limit when it is first imported
    refused = run_bcad("detect", tmp_path / "views.csv", "--checkerboard", "8x6", "-o", tmp_path / "d.csv")
    assert refused.returncode == 2, refused.stderr
    assert "bomb.png: not an image OpenCV reads (PNG, JPEG, ...) of at most 1e+08 pixels" in refused.stderr


def test_detect_refuses_views_whose_images_exceed_the_total(tmp_path, monkeypatch):
    """Each image within the limit, a views table naming many is bounded in all (the search takes
    about 0.2 s a megapixel): refused at the row that passes the total."""
    cv2 = pytest.importorskip("cv2")
    from bcad.calibration import detect

    monkeypatch.setattr(detect, "MAX_TOTAL_PIXELS", 250 * 250)
    cv2.imwrite(str(tmp_path / "view.png"), np.zeros((100, 100), np.uint8))
    (tmp_path / "views.csv").write_text("image,ur5/joint_1\n" + "view.png,0\n" * 10)
    refused = runner.invoke(
        app, ["detect", str(tmp_path / "views.csv"), "--checkerboard", "8x6", "-o", str(tmp_path / "d.csv")]
    )
    assert refused.exit_code == 2, refused.output
    assert "views.csv:8:1: the views' images exceed 6e+04 pixels in all" in refused.output


def test_an_archived_mesh_is_not_expanded_for_a_picture(tmp_path):
    """trimesh reads a zip of meshes too, and a zip of a few MB expands to gigabytes: only a mesh
    whole in its file (STL, OBJ, PLY, OFF, GLB) is read; the archive's link stays a segment."""
    trimesh = pytest.importorskip("trimesh")
    from bcad.compiler import compile_problem
    from bcad.model import load_problem
    from bcad.plot.arms import robot_meshes

    trimesh.creation.box(extents=[0.1, 0.1, 0.1]).export(str(tmp_path / "cube.stl"))
    with zipfile.ZipFile(tmp_path / "cube.zip", "w") as archive:
        archive.write(tmp_path / "cube.stl", "cube.stl")
    links = "".join(
        f'<link name="{name}"><visual><geometry><mesh filename="{mesh}"/></geometry></visual></link>'
        for name, mesh in (("base", "cube.zip"), ("tool", "cube.stl"))
    )
    (tmp_path / "arm.urdf").write_text(
        f'<robot name="arm">{links}<joint name="j" type="revolute"><parent link="base"/><child link="tool"/>'
        '<axis xyz="0 0 1"/><limit lower="-1" upper="1"/></joint></robot>'
    )
    problem = tmp_path / "arm.yaml"
    problem.write_text(
        textwrap.dedent(
            """
            name: arm
            frames: [world]
            robots:
            - {name: arm, urdf: arm.urdf, parent: world, pose: [0, 0, 0, 0, 0, 0]}
            """
        )
    )
    meshes = robot_meshes(compile_problem(load_problem(problem)))
    assert sorted(meshes) == ["arm/tool:cube.stl"]


def with_solver(folder, solver: str):
    path = folder / "one.yaml"
    path.write_text(textwrap.dedent(ONE_LINK_GRAPH).lstrip("\n") + f"solver: {solver}\n")
    return path


@pytest.mark.parametrize(
    ("solver", "place", "fragment"),
    [
        ("{finalist_samples: 10000000}", "7:28", "3 finalists of 10,000,000 importance samples each"),
        ("{finalists: 100, finalist_samples: 2000000}", "7:44", "100 finalists of 2,000,000"),
        ("{estimator: mc, population: 10000, max_samples: 1000000}", "7:37", "the genetic algorithm's settings plan"),
    ],
)
def test_a_search_past_its_budget_is_refused_before_any_work(tmp_path, solver, place, fragment):
    """Each setting within its schema bound, the finalists' samples (10 million each: 160 s on the
    RX90 example) and the GA's schedule (a population of 10,000 up to a million samples: hours)
    were not bounded together, as the posterior's samples are: refused by validate and solve at the
    line of the setting, exit 2."""
    path = with_solver(tmp_path, solver)
    for command in (["validate", str(path)], ["solve", str(path), "-o", str(tmp_path / "r.json")]):
        refused = runner.invoke(app, command)
        assert refused.exit_code == 2, refused.output
        assert f"one.yaml:{place}: {fragment}" in refused.stderr, refused.stderr
    assert not (tmp_path / "r.json").exists()


def test_the_genetic_plan_bounds_what_the_algorithm_evaluates():
    """genetic_sample_evaluations is an upper bound of the GA's own count (its schedule at the
    highest initial temperature the settings allow), and the default RX90 plan is within budget."""
    from bcad.bayes.genetic_search import solve_bayes
    from bcad.bayes.model import BayesModel
    from bcad.bayes.work import MAX_SEARCH_WORK, genetic_sample_evaluations, posterior_work
    from bcad.compiler import compile_problem
    from bcad.model import load_problem
    from bcad.model.solver import SolverSettings

    compiled = compile_problem(load_problem(REPO / "problems" / "rx90_face_on_face.yaml"))
    planned = genetic_sample_evaluations(compiled.problem.solver, len(compiled.parameters.x))
    assert planned * posterior_work(compiled) <= MAX_SEARCH_WORK
    settings = SolverSettings(
        estimator="mc",
        population=8,
        elite=1,
        initial_samples=16,
        max_samples=64,
        selection_samples=256,
        refine_samples=64,
        refine_iterations=2,
        reranked=2,
        max_initial_draws=50,
    )
    model = BayesModel(compiled)
    found = solve_bayes(model, settings, seed=3)
    planned = genetic_sample_evaluations(settings, len(compiled.parameters.x))
    assert 0 < found.genetic.sample_evaluations <= planned


def test_a_file_that_is_not_a_problem_is_refused_without_quoting_it(tmp_path):
    """A password file read as a problem (or as ``--for``'s task) echoed its first line twice, the
    hash with it, as an unknown key. A mapping none of whose keys is a problem's is not a problem,
    said without quoting it; an unknown key beside known ones is quoted once, cut to 24 characters."""
    shadow = tmp_path / "shadow"
    shadow.write_text("root:*:20228:0:99999:7:::\nalice:$6$saltsalt$4fQ9hashhashhash:19000:0:99999:7:::\n")
    refused = runner.invoke(app, ["validate", str(shadow)])
    assert refused.exit_code == 2
    assert refused.stderr.startswith(f"{shadow}:1:1: not a bcad problem: none of its keys is one of name, ")
    assert "root" not in refused.stderr.replace(str(tmp_path), "") and "hash" not in refused.stderr
    typo = tmp_path / "typo.yaml"
    typo.write_text("name: x\nframes: [a]\nan_unknown_key_holding_a_secret_value: 1\n")
    refused = runner.invoke(app, ["validate", str(typo)])
    assert refused.exit_code == 2
    assert refused.stderr.startswith(f"{typo}:3:1: unknown key 'an_unknown_key_holding_a…'; expected one of: name")
    assert "secret" not in refused.stderr


@pytest.mark.parametrize(
    ("text", "place", "complaint"),
    [
        ("<robot><SECRET_TAG></x></robot>", "1:24", "Opening and ending tag mismatch"),
        ('<robot><link name="a"\n', "2:1", "Couldn't find end of Start Tag"),
        ('<robot SECRET_KEY="1" SECRET_KEY="2"/>', "1:37", "an attribute redefined"),
        ("<robot>&SECRET_ENTITY;</robot>", "1:23", "an entity not defined"),
    ],
)
def test_a_urdf_that_is_not_xml_is_refused_without_its_names(tmp_path, text, place, complaint):
    """libxml2's complaints quote the file's tag, attribute and entity names ("Opening and ending
    tag mismatch: SECRET_TAG line 1 and x"): a file that is not a URDF was shown in part. The
    complaint is said without them, at its line and column."""
    (tmp_path / "arm.urdf").write_text(text)
    problem = tmp_path / "arm.yaml"
    problem.write_text("name: arm\nframes: [world]\nrobots:\n- {name: arm, urdf: arm.urdf, parent: world}\n")
    refused = runner.invoke(app, ["validate", str(problem)])
    assert refused.exit_code == 2
    assert refused.stderr.strip() == f"{tmp_path / 'arm.urdf'}:{place}: cannot parse the URDF: {complaint}"


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("name: x\nframes: [a, b]\n7: 1\n", "3:1: unknown key '7'"),
        (
            "name: x\nframes: [a, b]\nlinks:\n- {name: l, parent: a, child: b, 5: 1}\n",
            "4:34: links[0]: unknown key '5'",
        ),
        (
            "name: x\nframes: [a, b]\nlinks:\n- name: l\n  parent: a\n  child: b\n  1.5: 1\n",
            "7:3: links[0]: unknown key '1.5'",
        ),
    ],
)
def test_an_unknown_key_that_reads_as_a_number_is_found_at_its_place(write_problem, text, expected):
    """A key that YAML reads as a number was looked up as its text and not found: the error fell
    back to its mapping's place, or 1:1 at the top. It is looked up as the file has it."""
    path = write_problem(text)
    refused = runner.invoke(app, ["validate", str(path)])
    assert refused.exit_code == 2 and refused.stderr.startswith(f"{path}:{expected};"), refused.stderr
