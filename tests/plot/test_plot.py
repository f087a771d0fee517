"""`bcad plot`: each picture is compared with what it must show, not only written."""

from __future__ import annotations

import json
import shutil
import sys

import numpy as np
import pytest

from bcad.bayes.result import DesignResult
from bcad.worstcase.result import MaxErrorResult

from conftest import REPO, run_bcad, rx90_solved

pytest.importorskip("matplotlib")
RX90 = REPO / "problems" / "rx90_face_on_face.yaml"


@pytest.fixture(scope="module")
def rx90_result(tmp_path_factory):
    """A folder with the RX90 example solved by each backend (bayes.json, nominal.json)."""
    folder = tmp_path_factory.mktemp("rx90")
    for backend in ("bayes", "nominal"):
        shutil.copyfile(rx90_solved(tmp_path_factory, backend), folder / f"{backend}.json")
    return folder


def _non_blank(path) -> float:
    import matplotlib.image as image

    pixels = image.imread(str(path))
    return float(pixels[..., :3].std())


def test_the_drawn_arms_are_the_forward_kinematics(rx90_result):
    """Each arm's drawn segments join its base and joint frames, where Pinocchio puts them."""
    import pinocchio as pin

    from bcad.compiler import compile_problem
    from bcad.model import load_problem
    from bcad.plot.arms import draw_arms
    from bcad.plot.render import solution_of

    compiled = compile_problem(load_problem(RX90))
    x, _ = solution_of(compiled, rx90_result / "bayes.json")
    figure, (drawing,) = draw_arms(compiled, [("bayes", x, {})], RX90)
    model = pin.buildModelFromUrdf(str(REPO / "robots" / "rx90.urdf"))
    data = model.createData()
    solution = json.loads((rx90_result / "bayes.json").read_text())["solution"]
    for arm, base in (
        ("arm1", np.eye(4)),
        ("arm2", np.array([[-1, 0, 0, 1000], [0, -1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])),
    ):
        q = np.array([solution[f"{arm}/joint_{k}.rz"] for k in range(1, 7)])
        pin.forwardKinematics(model, data, q)
        expected = [base[:3, 3]] + [(base @ np.append(data.oMi[j].translation * 1000.0, 1.0))[:3] for j in range(1, 7)]
        np.testing.assert_allclose(drawing.segments[arm], np.array(expected), atol=1e-9)
    assert set(drawing.ellipsoids) == set()  # no samples given: no ellipsoid


def test_a_cell_of_plain_links_is_drawn_as_its_chain(tmp_path):
    """The planar arm (plain links, no robot): each link but the closing one is a segment from
    its parent frame's origin to its child's, at the arm's closed-form forward kinematics (links
    1.0 and 0.8 m, joint angles q1 and q1 + q2); the legend names no robot."""
    from bcad.compiler import compile_problem
    from bcad.model import load_problem
    from bcad.plot.arms import draw_arms

    compiled = compile_problem(load_problem(REPO / "problems" / "studies" / "planar_2r.yaml"))
    q1, q2 = 0.7, -1.9
    figure, (drawing,) = draw_arms(compiled, [("q", np.array([q1, q2]), {})], tmp_path)
    elbow = np.array([np.cos(q1), np.sin(q1), 0.0])
    tip = elbow + 0.8 * np.array([np.cos(q1 + q2), np.sin(q1 + q2), 0.0])
    np.testing.assert_allclose(drawing.links["arm1"], [np.zeros(3), elbow], atol=1e-12)
    np.testing.assert_allclose(drawing.links["arm2"], [elbow, tip], atol=1e-12)
    np.testing.assert_allclose(drawing.links["line"], [np.zeros(3), [1.2, 0.0, 0.0]], atol=1e-12)
    assert "reach" not in drawing.links and not drawing.segments  # the closing link; no robot
    labels = [text.get_text() for legend in figure.legends for text in legend.get_texts()]
    assert not any(label.startswith("robot") for label in labels) and any(label.startswith("links") for label in labels)


def test_arms_side_by_side_as_png_and_svg(rx90_result, tmp_path):
    run = run_bcad(
        "plot",
        RX90,
        "--what",
        "arms",
        "--at",
        rx90_result / "bayes.json",
        "--at",
        rx90_result / "nominal.json",
        "-o",
        tmp_path / "arms.png",
        "--samples",
        "5e3",
    )
    assert run.returncode == 0, run.stderr
    assert _non_blank(tmp_path / "arms.png") > 0.05
    run = run_bcad(
        "plot",
        RX90,
        "--what",
        "arms",
        "--at",
        rx90_result / "bayes.json",
        "-o",
        tmp_path / "arms.svg",
        "--samples",
        "5e3",
    )
    assert run.returncode == 0, run.stderr
    svg = (tmp_path / "arms.svg").read_text()
    for name in ["arm1", "arm2", "face1", "face2", "table", "gripper1", "part2", "contact: 95 % ellipsoid"]:
        assert name in svg, name


def test_the_graph_dashes_its_closing_links(tmp_path):
    from bcad.compiler import compile_problem
    from bcad.model import load_problem
    from bcad.plot.figures import draw_graph

    compiled = compile_problem(load_problem(RX90))
    _, drawn = draw_graph(compiled, RX90)
    closing = {compiled.graph.links[i].name for i in compiled.graph.closing_links}
    assert {name for name, link in drawn["links"].items() if link["dashed"]} == closing == {"contact"}
    assert len(drawn["links"]) == len(compiled.graph.links)
    run = run_bcad("plot", RX90, "--what", "graph", "-o", tmp_path / "graph.svg")
    assert run.returncode == 0
    svg = (tmp_path / "graph.svg").read_text()
    assert all(link.name in svg for link in compiled.graph.links)
    assert all(link.status in svg for link in compiled.graph.links)


def test_the_relaxation_is_fig_2(tmp_path):
    from bcad.compiler import compile_problem
    from bcad.model import load_problem
    from bcad.plot.figures import draw_relaxation

    compiled = compile_problem(load_problem(RX90))
    _, drawn = draw_relaxation(compiled, RX90)
    d, curves, width = drawn["distance"], drawn["curves"], drawn["width"]
    inside = d <= 0
    for temperature, values in curves.items():
        assert np.all(values[inside] == 1.0)
        if temperature > 0:  # Sect. 4.2.1: exp(-(d/w)^2 / T) outside
            np.testing.assert_allclose(values[~inside], np.exp(-((d[~inside] / width) ** 2) / temperature))
    assert np.all(curves[0.0][~inside] == 0.0)
    assert np.all(curves[0.01][~inside] <= curves[1.0][~inside])  # colder is stricter
    run = run_bcad("plot", RX90, "--what", "relaxation", "-o", tmp_path / "fig2.png")
    assert run.returncode == 0 and _non_blank(tmp_path / "fig2.png") > 0.05


def test_the_corner_plot_carries_table_2(rx90_result, tmp_path):
    run = run_bcad(
        "plot",
        RX90,
        "--what",
        "posterior",
        "--at",
        rx90_result / "bayes.json",
        "-o",
        tmp_path / "corner.svg",
        "--samples",
        "2e4",
    )
    assert run.returncode == 0, run.stderr
    svg = (tmp_path / "corner.svg").read_text()
    run = run_bcad("posterior", RX90, "--at", rx90_result / "bayes.json", "--samples", "2e4", "--json")
    weighted = json.loads(run.stdout)["posterior"]["links"]["contact"]["weighted"]
    assert f"tx {weighted['mean'][0]:.3g}±{weighted['std'][0]:.2g}" in svg
    assert "Too few points" not in run.stderr


def test_the_error_set_stays_inside_the_certified_bound(tmp_path):
    from bcad.model.clearance import load_chain_problem
    from bcad.plot.figures import draw_error
    from bcad.worstcase.error_map import build_error_map
    from bcad.worstcase.run import maxerror_document
    from bcad.worstcase.statistics import error_samples

    path = REPO / "problems" / "clearance" / "rx90_candle.yaml"
    problem = load_chain_problem(path)
    document = maxerror_document(problem, tol=1e-6, model="first-order")
    rotations, translations = error_samples(
        build_error_map(problem), problem.name, problem.units.length, 20000, np.random.default_rng(0)
    )
    _, drawn = draw_error(MaxErrorResult.model_validate(document), rotations, translations, path)
    for kind in ("rotation", "translation"):
        # Sampled clearances reach close to the certified maximum and never past its bound
        # (the sampled model is exact, the bound first-order: second-order terms are ~1e-6 of it).
        assert 0.5 * drawn[kind]["max"] < drawn[kind]["sampled_max"] <= drawn[kind]["bound"] * (1 + 1e-3)
    run = run_bcad("plot", path, "--what", "error", "-o", tmp_path / "error.png", "--samples", "5e3")
    assert run.returncode == 0 and _non_blank(tmp_path / "error.png") > 0.02


def test_the_html_view_is_offline(rx90_result, tmp_path):
    pytest.importorskip("plotly")
    run = run_bcad(
        "plot",
        RX90,
        "--what",
        "arms",
        "--at",
        rx90_result / "bayes.json",
        "-o",
        tmp_path / "arms.html",
        "--samples",
        "2e3",
    )
    assert run.returncode == 0, run.stderr
    html = (tmp_path / "arms.html").read_text()
    assert "plotly" in html and "arm1" in html
    assert 'src="http' not in html  # the library is embedded: no script from the network


def test_solve_plot_writes_the_usual_figures(tmp_path):
    """On the planar arm (a solve of a few seconds: the figures are what is tested here)."""
    planar = REPO / "problems" / "studies" / "planar_2r.yaml"
    pictures = tmp_path / "new" / "pictures"  # created, as batch's --out
    run = run_bcad("solve", planar, "--samples", "2e4", "--quiet", "-o", tmp_path / "r.json", "--plot", pictures)
    assert run.returncode == 0, run.stderr
    for name in ("arms", "graph", "posterior"):
        assert _non_blank(pictures / f"planar_2r_{name}.png") > 0.02
    (tmp_path / "a_file").write_text("")
    refused = run_bcad("solve", planar, "--quiet", "--plot", tmp_path / "a_file")
    assert refused.returncode == 2 and "--plot: a file, not a folder" in refused.stderr


def test_solve_plot_on_too_few_samples_for_a_corner_plot_keeps_the_result(tmp_path):
    """Two posterior samples: the corner plot is left out with a note, the other figures and the
    solve's result are written, and the exit code is the result's (3: too few samples)."""
    planar = REPO / "problems" / "studies" / "planar_2r.yaml"
    run = run_bcad("solve", planar, "--samples", "2", "--quiet", "-o", tmp_path / "r.json", "--plot", tmp_path)
    assert run.returncode == 3, run.stderr
    assert "note: no posterior figure: a corner plot of 3 parameters needs more samples" in run.stderr
    assert sorted(path.name for path in tmp_path.glob("*.png")) == ["planar_2r_arms.png", "planar_2r_graph.png"]
    assert json.loads((tmp_path / "r.json").read_text())["posterior"]["samples"] == 2


def test_without_matplotlib_plot_says_how_to_install_it(monkeypatch, tmp_path):
    from typer.testing import CliRunner

    from bcad.cli import app

    monkeypatch.setitem(sys.modules, "matplotlib", None)
    result = CliRunner().invoke(app, ["plot", str(RX90), "--what", "graph", "-o", str(tmp_path / "g.png")])
    assert result.exit_code == 2 and "pip install 'bcad[plot]'" in result.stderr
    assert not (tmp_path / "g.png").exists()


def test_the_readme_plot_commands_make_the_committed_pictures(tmp_path, tmp_path_factory):
    """The Pictures page's seven commands (run by docs/pictures.py, which reads them from the page)
    make pictures equal to the committed docs/*.png: the same size, and at most 0.5 % of the
    pixels off by more than 0.1 (font rasterisation aside, a stale picture differs in several
    percent: a moved arm, another ellipsoid). Its first command is the quick start's solve with
    -o: the suite's run of that (:func:`conftest.quick_start_solved`) stands for it."""
    import importlib.util

    import matplotlib.image as image

    from conftest import quick_start_result

    spec = importlib.util.spec_from_file_location("pictures", REPO / "docs" / "pictures.py")
    pictures = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(pictures)
    commands = pictures.readme_commands()
    assert len(commands) == 7 and all(words[0] in ("solve", "plot") for words in commands)
    assert commands[0] == ["solve", "problems/rx90_face_on_face.yaml", "-o", "bayes.json"]
    made = pictures.make_pictures(tmp_path, results={"bayes.json": quick_start_result(tmp_path_factory)})
    assert sorted(p.name for p in made) == sorted(
        f"{n}.png" for n in ("fig5_arms", "fig4_graph", "fig2_relaxation", "corner", "error")
    )
    for path in made:
        assert _non_blank(path) > 0.02
        fresh, committed = image.imread(str(path))[..., :3], image.imread(str(REPO / "docs" / path.name))[..., :3]
        assert fresh.shape == committed.shape, (path.name, fresh.shape, committed.shape)
        off = np.mean(np.max(np.abs(fresh - committed), axis=-1) > 0.1)
        assert off <= 0.005, (
            f"docs/{path.name} differs from what its command makes in {off:.1%} of its pixels: python docs/pictures.py"
        )


def test_batch_plot_draws_the_sweep_and_the_cells(tmp_path):
    """A sweep of the planar arm's zero error: the line plot carries each point's log objective,
    which falls as the error grows (I(X) = a Gaussian whose width grows with it)."""
    from bcad.plot.sweep import draw_sweep, sweep_series

    (tmp_path / "plots").mkdir()
    run = run_bcad(
        "batch",
        REPO / "problems" / "studies" / "planar_2r.yaml",
        "--out",
        tmp_path / "study",
        "--sweep",
        "links.zero2.distributions.rz.std=0.01,0.03,0.1",
        "--plot",
        tmp_path / "plots",
        "--quiet",
    )
    assert run.returncode == 0, run.stderr
    assert _non_blank(tmp_path / "plots" / "planar_2r__links.zero2.distributions.rz.std.png") > 0.02
    assert len(list((tmp_path / "plots").glob("*_arms.png"))) == 3
    lines = [json.loads(line) for line in (tmp_path / "study" / "summary.jsonl").read_text().splitlines()]
    (((name, key), slices),) = sweep_series(lines).items()
    _, drawn = draw_sweep(name, key, slices, tmp_path)
    (drawn,) = drawn["slices"]
    assert drawn["values"] == [0.01, 0.03, 0.1] and drawn["held"] == {}
    by_value = {line["point"][key]: line["log_objective"] for line in lines}
    assert drawn["log_objective"] == [by_value[v] for v in drawn["values"]]
    assert drawn["log_objective"][0] > drawn["log_objective"][1] > drawn["log_objective"][2]


def test_a_sweep_over_two_keys_draws_every_slice_labelled_with_what_it_holds(tmp_path):
    """A 3 x 3 grid: the plot of one key drew the first slice of the other key's values and
    dropped the rest, without saying which value it held. Every slice is a line now, each
    labelled with the other key's value, in the order of those values (2, 4, 10: not as text),
    and every summary line is drawn once per key."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    from bcad.plot.sweep import draw_sweep, sweep_series

    stds, starts = (0.01, 0.02, 0.05), (10, 2, 4)
    lines = [
        {
            "file": "planar_2r.yaml",
            "kind": "solve",
            "status": "ok",
            "point": {"links.zero2.distributions.rz.std": std, "solver.search_starts": start},
            "log_objective": -10 * std - 0.001 * start,
            "log_objective_se": 0.003,
        }
        for std in stds
        for start in starts
    ]
    series = sweep_series(lines)
    assert set(series) == {
        ("planar_2r.yaml", "links.zero2.distributions.rz.std"),
        ("planar_2r.yaml", "solver.search_starts"),
    }
    std_key = ("planar_2r.yaml", "links.zero2.distributions.rz.std")
    figure, drawn = draw_sweep(*std_key, series[std_key], tmp_path)
    assert [entry["held"] for entry in drawn["slices"]] == [
        {"solver.search_starts": "2"},
        {"solver.search_starts": "4"},
        {"solver.search_starts": "10"},
    ]
    for entry, start in zip(drawn["slices"], sorted(starts)):
        assert entry["values"] == list(stds)
        assert entry["log_objective"] == [-10 * std - 0.001 * start for std in stds]
    labels = [text.get_text() for text in figure.axes[0].get_legend().get_texts()]
    assert labels == [
        "log p(X*) I(X*) ± 2 se, solver.search_starts=2",
        "log p(X*) I(X*) ± 2 se, solver.search_starts=4",
        "log p(X*) I(X*) ± 2 se, solver.search_starts=10",
    ]
    _, drawn = draw_sweep(
        "planar_2r.yaml", "solver.search_starts", series[("planar_2r.yaml", "solver.search_starts")], tmp_path
    )
    assert len(drawn["slices"]) == 3 and all(entry["values"] == [2.0, 4.0, 10.0] for entry in drawn["slices"])


def test_a_clearance_sweep_draws_each_error_on_its_own_axis_in_its_unit(tmp_path):
    """A translation (length) and a rotation (angle) are never read off one axis: each has its
    own, labelled with the problem's unit, and the points are the summaries' certified maxima."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    from bcad.plot.sweep import draw_sweep, sweep_series

    problem = tmp_path / "rr.yaml"
    problem.write_text((REPO / "problems" / "clearance" / "2r.yaml").read_text() + "units: {length: mm, angle: deg}\n")
    sweep = ["--sweep", "clearance.rot_z=0.0005,0.002,0.004", "--quiet"]
    run = run_bcad("batch", problem, "--out", tmp_path / "study", *sweep)
    assert run.returncode == 0, run.stderr
    lines = [json.loads(line) for line in (tmp_path / "study" / "summary.jsonl").read_text().splitlines()]
    (((name, key), slices),) = sweep_series(lines).items()
    figure, drawn = draw_sweep(name, key, slices, tmp_path)
    assert drawn["axes"] == {
        "translation": "translation error, certified maximum (mm)",
        "rotation": "rotation error, certified maximum (deg)",
    }
    (drawn,) = drawn["slices"]
    by_value = {line["point"][key]: line["rotation"]["max"] for line in lines}
    assert drawn["rotation"] == [by_value[v] for v in (0.0005, 0.002, 0.004)]
    assert drawn["rotation"][0] < drawn["rotation"][1] < drawn["rotation"][2]
    assert len(figure.axes) == 2


def test_a_urdf_mesh_is_drawn_where_the_link_is(tmp_path):
    """A link's visual mesh (an STL cube, found beside the URDF) is drawn at the link's frame."""
    trimesh = pytest.importorskip("trimesh")
    import yaml

    from bcad.compiler import compile_problem
    from bcad.model import load_problem
    from bcad.plot.arms import draw_arms

    trimesh.creation.box(extents=[0.1, 0.1, 0.1]).export(str(tmp_path / "cube.stl"))
    (tmp_path / "arm.urdf").write_text("""<robot name="a"><link name="base"/>
      <link name="tool"><visual><origin xyz="0 0 0.05"/><geometry><mesh filename="cube.stl"/></geometry></visual></link>
      <joint name="j" type="revolute"><parent link="base"/><child link="tool"/><origin xyz="0.5 0 0"/><axis xyz="0 0 1"/>
        <limit lower="-3" upper="3" effort="1" velocity="1"/></joint></robot>""")
    (tmp_path / "p.yaml").write_text(
        yaml.safe_dump(
            {
                "name": "m",
                "units": {"length": "mm"},
                "frames": ["w"],
                "robots": [{"name": "r", "urdf": "arm.urdf", "parent": "w"}],
            }
        )
    )
    compiled = compile_problem(load_problem(tmp_path / "p.yaml"))
    _, (drawing,) = draw_arms(compiled, [("q = 0.5", np.array([0.5]), {})], tmp_path)
    ((name, triangles),) = drawing.meshes.items()
    assert name == "r/tool:cube.stl"
    # The cube's centre: the joint at (500, 0, 0) mm, turned by 0.5 rad, the mesh 50 mm up: (500, 0, 50).
    np.testing.assert_allclose(triangles.reshape(-1, 3).mean(axis=0), [500.0, 0.0, 50.0], atol=1e-6)
    assert np.ptp(triangles.reshape(-1, 3)[:, 2]) == pytest.approx(100.0)


def test_plot_refuses_more_samples_than_it_can_hold(tmp_path):
    run = run_bcad("plot", RX90, "--what", "arms", "--samples", "1e9", "-o", tmp_path / "a.png")
    assert run.returncode == 2 and "at most" in run.stderr and not (tmp_path / "a.png").exists()


def test_fig_5_panels_share_limits_and_magnification_and_show_both_ellipsoids(rx90_result):
    """One set of limits and one magnification for both panels; beside the weighted
    ellipsoid, the prior propagation's (wider: the scores only narrow the posterior); a legend;
    titles with the log objective and Table 2's std of the scored parameters; the contact inset."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    from bcad.bayes.model import BayesModel
    from bcad.bayes.result import DesignResult
    from bcad.bayes.run import posterior_document
    from bcad.compiler import compile_problem
    from bcad.model import load_problem
    from bcad.plot.arms import draw_arms
    from bcad.plot.render import panel_title, solution_of

    compiled = compile_problem(load_problem(RX90))
    model = BayesModel(compiled)
    panels, documents = [], []
    for name in ("bayes.json", "nominal.json"):
        x, seed = solution_of(compiled, rx90_result / name)
        kept: dict = {}
        document = posterior_document(compiled, x, samples=5000, seed=seed, kept=kept, model=model)
        documents.append(document)
        panels.append((panel_title(name, DesignResult.model_validate(document)), x, kept))
    figure, drawings = draw_arms(compiled, panels, RX90)
    np.testing.assert_array_equal(drawings[0].limits, drawings[1].limits)
    magnifications = {d.ellipsoids["contact"][2] for d in drawings} | {
        d.prior_ellipsoids["contact"][2] for d in drawings
    }
    assert len(magnifications) == 1
    for drawing in drawings:
        weighted, prior = drawing.ellipsoids["contact"][1], drawing.prior_ellipsoids["contact"][1]
        assert np.trace(prior) > np.trace(weighted)
        assert set(drawing.inset) == {"link", "prior", "weighted"} and drawing.inset["link"] == "contact"
    legend = [text.get_text() for legend in figure.legends for text in legend.get_texts()]
    assert any("weighted posterior" in label for label in legend) and any(
        "prior propagation" in label for label in legend
    )
    titles = [axes.get_title() for axes in figure.axes if axes.name == "3d"]
    for title, document in zip(titles, documents):
        assert f"log p(X) I(X) = {document['objective']['log_value']:.2f}" in title
        assert "(5,000 samples drawn here)" in title  # the picture's own estimate, not the file's
        std = document["posterior"]["links"]["contact"]["std"][2]
        assert f"tz {std:.3g}" in title


def test_the_graph_puts_the_closing_link_between_neighbours_and_labels_apart():
    import matplotlib

    matplotlib.use("Agg", force=True)
    from bcad.compiler import compile_problem
    from bcad.model import load_problem
    from bcad.plot.figures import draw_graph

    compiled = compile_problem(load_problem(RX90))
    figure, drawn = draw_graph(compiled, RX90)
    assert drawn["links"]["contact"]["closing"] and drawn["links"]["contact"]["gap"] in (1, len(drawn["frames"]) - 1)
    figure.canvas.draw()
    renderer = figure.canvas.get_renderer()
    boxes = [_rotated_box(text, renderer) for text in drawn["texts"]]
    overlapping = [
        (drawn["texts"][i].get_text(), drawn["texts"][j].get_text())
        for i in range(len(boxes))
        for j in range(i + 1, len(boxes))
        if _quads_overlap(boxes[i], boxes[j])
    ]
    assert not overlapping, overlapping[:5]
    # The check itself sees two labels drawn on top of each other.
    assert _quads_overlap(boxes[0], boxes[0] + 1.0)


def _rotated_box(text, renderer) -> np.ndarray:
    """The four corners (display pixels) of a text's box, rotated as drawn (rotation_mode anchor:
    the aligned corner or edge of the unrotated box at the text's position)."""
    rotation = text.get_rotation()
    text.set_rotation(0)
    extent = text.get_window_extent(renderer)
    text.set_rotation(rotation)
    width, height = extent.width, extent.height
    ax = {"left": 0.0, "center": width / 2, "right": width}[text.get_horizontalalignment()]
    ay = {"bottom": 0.0, "baseline": 0.0, "center": height / 2, "center_baseline": height / 2, "top": height}[
        text.get_verticalalignment()
    ]
    corners = np.array([[0, 0], [width, 0], [width, height], [0, height]]) - [ax, ay]
    theta = np.radians(rotation)
    R = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    anchor = text.get_transform().transform(text.get_position())
    return corners @ R.T + anchor


def _quads_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Separating-axis test for two convex quadrilaterals (touching counts as apart)."""
    for quad in (a, b):
        for k in range(4):
            edge = quad[(k + 1) % 4] - quad[k]
            axis = np.array([-edge[1], edge[0]])
            pa, pb = a @ axis, b @ axis
            if pa.max() <= pb.min() + 1e-9 or pb.max() <= pa.min() + 1e-9:
                return False
    return True


def test_the_corner_plot_has_units_a_legend_and_its_own_bins_for_the_weights(rx90_result):
    import matplotlib

    matplotlib.use("Agg", force=True)
    from bcad.bayes.run import posterior_document
    from bcad.compiler import compile_problem
    from bcad.model import load_problem
    from bcad.plot.figures import draw_posterior
    from bcad.plot.render import solution_of

    compiled = compile_problem(load_problem(RX90))
    x, seed = solution_of(compiled, rx90_result / "bayes.json")
    kept: dict = {}
    document = posterior_document(compiled, x, samples=20000, seed=seed, kept=kept)
    figure, drawn = draw_posterior(compiled, DesignResult.model_validate(document), kept, None, RX90)
    assert drawn["labels"][:3] == ["tx (mm)", "ty (mm)", "tz (mm)"] and drawn["labels"][3] == "rx (rad)"
    legend = [text.get_text() for legend in figure.legends for text in legend.get_texts()]
    assert legend == ["prior propagation (Table 2 mean, std)", "weighted posterior (Table 2 w mean, w std)"]
    # tz is scored N(0, 0.5 mm): its weighted bins span a few weighted stds, far inside the prior's spread
    low, high = drawn["weighted_range"][2]
    entry = document["posterior"]["links"]["contact"]
    assert high - low < 10 * entry["weighted"]["std"][2] < entry["std"][2] * 2
    assert "Table 2 w mean ± w std" in drawn["title"]
    # the weighted moments' Monte Carlo precision: their effective sample size
    assert f"20000 samples, {entry['effective_samples']:.0f} effective)" in drawn["title"]


def test_the_error_plot_reads_in_micro_units_and_shows_the_maximum(tmp_path):
    import matplotlib

    matplotlib.use("Agg", force=True)
    from bcad.compiler.units import angle_scale
    from bcad.model.clearance import load_chain_problem
    from bcad.numerics.seeding import stream
    from bcad.plot.figures import draw_error, readable_unit
    from bcad.worstcase.error_map import build_error_map
    from bcad.worstcase.run import maxerror_document
    from bcad.worstcase.statistics import error_samples

    assert readable_unit(4.811e-4, "rad") == (1e6, "µrad")
    assert readable_unit(0.3, "mm") == (1e3, "µm")
    assert readable_unit(3.0, "mm") == (1.0, "mm")
    path = REPO / "problems" / "clearance" / "rx90_candle.yaml"
    problem = load_chain_problem(path)
    document = maxerror_document(problem, tol=1e-6, model="first-order")
    rotations, translations = error_samples(
        build_error_map(problem), problem.name, problem.units.length, 2000, stream(0, "clearance")
    )
    result = MaxErrorResult.model_validate(document)
    figure, drawn = draw_error(result, rotations / angle_scale(problem.units), translations, path)
    assert drawn["rotation"]["unit"] == "µrad"
    texts = [t.get_text() for axes in figure.axes for t in axes.texts]
    maximum = document["rotation"]["max"] * drawn["rotation"]["factor"]
    assert f"max {maximum:.4g}" in texts


def test_the_prior_ellipsoid_is_table_2s_std(rx90_result):
    """The grey ellipsoid is the prior's propagation: its axes' spread is Table 2's std (every
    sample, those a relation rules out included), the red one Table 2's w std."""
    from bcad.bayes.run import posterior_document
    from bcad.compiler import compile_problem
    from bcad.model import load_problem
    from bcad.plot.arms import closing_ellipsoids, robot_chains
    from bcad.plot.render import solution_of

    compiled = compile_problem(load_problem(RX90))
    x, seed = solution_of(compiled, rx90_result / "bayes.json")
    kept: dict = {}
    document = posterior_document(compiled, x, samples=20000, seed=seed, kept=kept)
    _, _, transforms = robot_chains(compiled, x)
    entry = closing_ellipsoids(compiled, kept, transforms)["contact"]
    table = document["posterior"]["links"]["contact"]
    np.testing.assert_allclose(np.sqrt(np.diag(entry["local"]["prior"][1])), table["std"][:3], rtol=1e-3)


def test_the_graph_order_walks_a_long_chain_without_recursion():
    """circle_order on a 5000-frame chain (beyond Python's recursion limit): depth first, in order
    (without a cycle the path is the first frame alone, and it ends the circle)."""
    from types import SimpleNamespace

    from bcad.plot.figures import circle_order

    frames = [f"f{k}" for k in range(5000)]
    links = [SimpleNamespace(parent=a, child=b) for a, b in zip(frames, frames[1:])]
    graph = SimpleNamespace(frames=frames, links=links, closing_links=[], cycles=[])
    assert circle_order(SimpleNamespace(graph=graph)) == frames[1:] + frames[:1]


def test_plot_draws_uncertain_dimensions_at_their_nominal_and_refuses_a_corner_without_spread(rx90_result, tmp_path):
    """A face whose size is a distribution: the arms (png and html) are drawn; a corner plot of
    one sample has nothing to draw and says so (exit 2, not a traceback)."""
    text = RX90.read_text().replace("../robots/", f"{REPO}/robots/")
    problem = tmp_path / "sized.yaml"
    problem.write_text(text.replace("size: [40, 40]}", "size: ['normal(40, 0.1)', 40]}"))
    for name in ("arms.png", "arms.html"):
        run = run_bcad(
            "plot",
            problem,
            "--what",
            "arms",
            "--at",
            rx90_result / "bayes.json",
            "--samples",
            "2000",
            "-o",
            tmp_path / name,
        )
        assert run.returncode == 0, run.stderr
        assert (tmp_path / name).stat().st_size > 1000
    run = run_bcad(
        "plot",
        RX90,
        "--what",
        "posterior",
        "--at",
        rx90_result / "bayes.json",
        "--samples",
        "1",
        "-o",
        tmp_path / "one.png",
    )
    assert run.returncode == 2 and "the same in all 1 samples" in run.stderr, run.stderr


@pytest.mark.parametrize("samples", ["7", "10"])
def test_a_corner_plot_of_fewer_samples_than_parameters_is_exit_2(rx90_result, tmp_path, samples):
    """Six moving parameters and 7 or 10 samples (a few of them weighted): the plotting library
    would stop on an assertion; bcad says what it needs (exit 2)."""
    run = run_bcad(
        "plot",
        RX90,
        "--what",
        "posterior",
        "--at",
        rx90_result / "bayes.json",
        "--samples",
        samples,
        "-o",
        tmp_path / "few.png",
    )
    assert run.returncode == 2 and "needs more samples than that" in run.stderr, run.stderr


@pytest.mark.parametrize(
    ("problem", "moving"), [("studies/planar_2r.yaml", 3), ("studies/planar_2r.yaml", 2), ("studies/planar_2r.yaml", 1)]
)
def test_a_corner_of_few_parameters_keeps_its_title_and_legend_clear(problem, moving):
    """The planar arm's reach moves in three parameters; with all but one or two held at their
    first sample's value, the corner is of one or two: drawn 7 inches wide, the title within the
    figure and above the diagonal's titles, the legend within it and off every other cell."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    from bcad.bayes.run import posterior_document
    from bcad.compiler import compile_problem
    from bcad.model import load_problem
    from bcad.plot.figures import draw_posterior

    path = REPO / "problems" / problem
    compiled = compile_problem(load_problem(path))
    kept: dict = {}
    document = posterior_document(compiled, np.array(compiled.parameters.x_nominal), samples=4000, seed=0, kept=kept)
    poses = kept["reach/poses"]
    columns = np.flatnonzero(np.ptp(poses, axis=0) > 0)
    assert len(columns) == 3
    poses[:, columns[moving:]] = poses[0, columns[moving:]]
    figure, drawn = draw_posterior(compiled, DesignResult.model_validate(document), kept, None, path)
    assert len(drawn["labels"]) == moving and min(figure.get_size_inches()) >= 7.0 - 1e-9
    renderer = figure.canvas.get_renderer()
    title, frame = figure._suptitle.get_window_extent(renderer), figure.bbox
    assert frame.x0 <= title.x0 and title.x1 <= frame.x1 and title.y1 <= frame.y1, (title, frame)
    assert max(axes.title.get_window_extent(renderer).y1 for axes in figure.axes if axes.get_title()) <= title.y0
    legend = (figure.legends or [figure.axes[0].get_legend()])[0].get_window_extent(renderer)
    assert frame.x0 <= legend.x0 and legend.x1 <= frame.x1 and legend.y1 <= title.y0, (legend, title)
    others = [axes for axes in figure.axes if axes.has_data() and not (moving == 1 and axes is figure.axes[0])]
    assert not any(legend.overlaps(axes.get_window_extent(renderer)) for axes in others), legend


@pytest.mark.parametrize("problem", ["studies/planar_2r.yaml", "rx90_face_on_face.yaml"])
def test_the_corner_plot_s_title_stays_within_the_figure(problem):
    """A corner of three parameters (the planar arm's reach) is narrower than its title: the title
    is wrapped to the figure's width, above the diagonal's own titles. At the RX90's nominal X no
    sample scores (the faces miss each other): the prior's propagation is drawn alone, and said so."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    from bcad.bayes.run import posterior_document
    from bcad.compiler import compile_problem
    from bcad.model import load_problem
    from bcad.plot.figures import draw_posterior

    path = REPO / "problems" / problem
    compiled = compile_problem(load_problem(path))
    kept: dict = {}
    document = posterior_document(compiled, np.array(compiled.parameters.x_nominal), samples=4000, seed=0, kept=kept)
    figure, drawn = draw_posterior(compiled, DesignResult.model_validate(document), kept, None, path)
    renderer = figure.canvas.get_renderer()
    title = figure._suptitle.get_window_extent(renderer)
    frame = figure.bbox
    assert frame.x0 <= title.x0 and title.x1 <= frame.x1 and title.y1 <= frame.y1, (title, frame)
    highest = max(axes.title.get_window_extent(renderer).y1 for axes in figure.axes if axes.get_title())
    assert highest <= title.y0, (highest, title)
    legend = [text.get_text() for legend in figure.legends for text in legend.get_texts()]
    scored = document["posterior"]["links"][drawn["link"]]["weighted"]["mean"] is not None
    assert scored == (problem != "rx90_face_on_face.yaml")
    assert ("no weighted posterior to draw" in drawn["title"]) == (not scored)
    assert len(legend) == (2 if scored else 1)


TURN_IN_DEGREES = """
name: turn-in-degrees
units: {length: mm, angle: deg}
frames: [a, m, b]
links:
  - {name: unknown, parent: a, child: m, status: FFFFFX, bounds: {rz: [-90, 90]}}
  - {name: free, parent: m, child: b, status: FFFFFL, distributions: {rz: 'normal(0, 2)'}}
  - {name: measured, parent: a, child: b, pose: [0, 0, 0, 0, 0, 30], status: FFFFFL, close: true,
     distributions: {rz: 'normal(0, 1)'}}
"""


def test_the_corner_plot_draws_angles_in_the_problems_unit(write_problem):
    """A problem in degrees: the corner's angle axis and its weighted bins are in degrees, as its
    label and Table 2 (the samples are kept in radians)."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    from bcad.bayes.run import posterior_document
    from bcad.compiler import compile_problem
    from bcad.model import load_problem
    from bcad.plot.figures import draw_posterior

    path = write_problem(TURN_IN_DEGREES)
    compiled = compile_problem(load_problem(path))
    kept: dict = {}
    x = np.array([np.radians(29.0)])  # internal units
    document = posterior_document(compiled, x, samples=5000, seed=0, kept=kept)
    _, drawn = draw_posterior(compiled, DesignResult.model_validate(document), kept, None, path)
    assert drawn["labels"] == ["rz (deg)"]
    entry = document["posterior"]["links"]["measured"]
    assert abs(entry["mean"][5] - 29.0) < 0.2  # Table 2, in degrees
    low, high = drawn["weighted_range"][0]
    assert low < entry["weighted"]["mean"][5] < high and high - low < 20.0
