"""Calibration from a camera's pixels: the eye-in-hand example (problems/calibration), its data
written by an independent model of the cell (ur5_camera_truth.py: its own DH product and
projection), identified to within its reported std over fresh noise seeds."""

from __future__ import annotations

import json
import re
import shutil
import sys

import numpy as np
import pytest
from typer.testing import CliRunner

from bcad.calibration.solve import calibrate
from bcad.cli import app
from bcad.compiler import compile_problem
from bcad.model import load_problem

from conftest import REPO, assert_committed_calibration

runner = CliRunner()
EXAMPLE = REPO / "problems" / "calibration"
sys.path.insert(0, str(EXAMPLE))
import ur5_camera_truth as truth  # noqa: E402

MOUNT_NOMINAL = np.array([30.0, -20.0, 50.0, 0.0, 0.0, 1.5708])
BOARD_NOMINAL = np.array([-500.0, 0.0, -100.0, -3.08, 0.0, -0.12])


def _rpy(T: np.ndarray) -> np.ndarray:
    R = T[:3, :3]
    return np.array(
        [
            *T[:3, 3],
            np.arctan2(R[2, 1], R[2, 2]),
            np.arctan2(-R[2, 0], np.hypot(R[2, 1], R[2, 2])),
            np.arctan2(R[1, 0], R[0, 0]),
        ]
    )


def _true_values() -> dict[str, float]:
    values = {
        f"camera_mount.{p}": v for p, v in zip(("tx", "ty", "tz", "rx", "ry", "rz"), truth.MOUNT_TRUE - MOUNT_NOMINAL)
    }
    values.update(
        {
            f"board_placement.{p}": v
            for p, v in zip(("tx", "ty", "tz", "rx", "ry", "rz"), _rpy(truth.board_in_world()) - BOARD_NOMINAL)
        }
    )
    values.update(
        {f"camera.{p}": v for p, v in zip(("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"), truth.CAMERA_TRUE)}
    )
    return values


def _copy_example(folder, seed: int, views: int = 15):
    shutil.copy(EXAMPLE / "ur5_eye_in_hand.yaml", folder / "cell.yaml")
    truth.write_csv(folder / "ur5_camera_views.csv", views, seed)
    return folder / "cell.yaml"


def test_the_eye_in_hand_cell_is_identified_within_its_std(tmp_path):
    """Six noise seeds (and view sets) of 15 views at 0.5 px: every parameter within 4.5 std of
    the truth, and the mean squared z-score (NEES per parameter) near 1: the covariance is
    honest. The hand-eye transform within 0.5 mm and 0.25 degrees (15 views spread by 0.25 rad)."""
    expected = _true_values()
    z = []
    for seed in range(6):
        folder = tmp_path / str(seed)
        folder.mkdir()
        cal = calibrate(compile_problem(load_problem(_copy_example(folder, seed))), check_samples=0)
        names = list(cal.names)
        assert sorted(names) == sorted(expected)
        found = {name: (cal.estimate[k], cal.std[k]) for k, name in enumerate(names)}
        z += [(found[name][0] - value) / found[name][1] for name, value in expected.items()]
        translation = np.array(
            [found[f"camera_mount.{p}"][0] - expected[f"camera_mount.{p}"] for p in ("tx", "ty", "tz")]
        )
        rotation = np.array([found[f"camera_mount.{p}"][0] - expected[f"camera_mount.{p}"] for p in ("rx", "ry", "rz")])
        assert np.linalg.norm(translation) < 0.5 and np.degrees(np.linalg.norm(rotation)) < 0.25
    z = np.array(z)
    assert np.max(np.abs(z)) < 4.5, z
    assert 0.5 < np.mean(z**2) < 1.6, np.mean(z**2)


def test_the_command_reports_pixels_and_exits_0(tmp_path):
    result = runner.invoke(app, ["calibrate", str(_copy_example(tmp_path, 2000)), "--json", "--quiet"])
    assert result.exit_code == 0, result.output
    document = json.loads(result.stdout)
    after = document["residuals"]["after"]["views"]
    assert set(after) == {"u", "v"} and 0.4 < after["u"]["rms"] < 0.6  # the 0.5 px noise
    assert document["parameters"]["camera.fx"]["unit"] == "px" and document["parameters"]["camera.k1"]["unit"] == ""
    assert document["check"]["trusted"] and document["warnings"] == []


@pytest.mark.parametrize(
    "change, fragment",
    [
        (("reference: camera ", "reference: world "), "is no camera; pixels (u,v) are measured by a camera"),
        (("frame: board ", "frame: board_frame "), "a camera's measurement reads the points of a target entity"),
        (("frame: camera_optical\n", "frame: camera_optics\n"), "unknown frame 'camera_optics'"),
        (
            (
                "checkerboard: {rows: 6, columns: 8, square: 25}",
                "checkerboard: {rows: 6, columns: 8, square: 25}\n    points: [[0, 0, 0]]",
            ),
            "exactly one of 'checkerboard'",
        ),
        (("parameters: u,v", "parameters: u"), "a camera's pixels are read as u,v, both and in that order"),
        (("parameters: u,v", "parameters: v,u"), "a camera's pixels are read as u,v, both and in that order"),
    ],
)
def test_a_camera_problem_with_a_mistake_is_exit_2_at_its_line(tmp_path, change, fragment):
    path = _copy_example(tmp_path, 1, views=2)
    text = path.read_text()
    assert change[0] in text
    path.write_text(text.replace(change[0], change[1], 1))
    result = runner.invoke(app, ["calibrate", str(path)])
    assert result.exit_code == 2 and fragment in result.output, result.output
    assert result.output.startswith(f"{path}:")


def test_a_point_id_beyond_the_target_is_exit_2_at_its_csv_line(tmp_path):
    path = _copy_example(tmp_path, 1, views=2)
    data = tmp_path / "ur5_camera_views.csv"
    lines = data.read_text().splitlines()
    cells = lines[5].split(",")
    cells[6] = "48"  # the board has points 0 to 47
    lines[5] = ",".join(cells)
    data.write_text("\n".join(lines) + "\n")
    result = runner.invoke(app, ["calibrate", str(path)])
    column = len(",".join(cells[:6])) + 2
    assert result.exit_code == 2 and f"{data}:6:{column}: point 48: 'board' has points 0 to 47" in result.output, (
        result.output
    )


def test_the_readme_camera_command_runs():
    from conftest import documentation

    readme = documentation()
    line = next(
        line for line in readme.splitlines() if line.startswith("bcad calibrate problems/calibration/ur5_eye_in_hand")
    )
    result = runner.invoke(app, line.split()[1:])
    assert result.exit_code == 0, result.output
    assert "camera.fx" in result.output and "px" in result.output


def test_a_degenerate_set_of_views_is_named_not_answered(tmp_path):
    """Every view turns the camera about a vertical axis: the mount's z and the focal lengths are
    seen only through their priors. The result says so (exit 3, camera_not_identified naming
    them) and their std stays near the prior's, never a confident number."""
    shutil.copy(EXAMPLE / "ur5_eye_in_hand.yaml", tmp_path / "cell.yaml")
    truth.write_csv(tmp_path / "ur5_camera_views.csv", 15, 5, degenerate=True)
    result = runner.invoke(app, ["calibrate", str(tmp_path / "cell.yaml"), "--json", "--quiet"])
    assert result.exit_code == 3, result.output
    document = json.loads(result.stdout)
    warning = next(w for w in document["warnings"] if w["code"] == "camera_not_identified")
    assert "camera_mount.tz" in warning["message"] and "camera.fx" in warning["message"]
    assert document["parameters"]["camera_mount.tz"]["std"] > 0.8 * 10  # its prior: normal(0, 10) mm
    assert any("camera_mount.tz" in entry["combination"] for entry in document["unobservable"])


DH_ERRORS = (
    "      default:\n        status: X\n        dh_error: {theta: 'normal(0, 0.0002)', d: 'normal(0, 0.2)', "
    "a: 'normal(0, 0.2)', alpha: 'normal(0, 0.0002)'}\n"
)
MOUNT = [f"camera_mount.{p}" for p in ("tx", "ty", "tz", "rx", "ry", "rz")]


def _hand_eye_nees(tmp_path, seeds, carry_errors: bool) -> list[float]:
    """NEES / 6 of the hand-eye transform on robots whose DH table is off the nominal one by
    0.2 mm and 0.0002 rad per parameter (drawn per seed), from 20 views at 0.5 px."""
    expected = _true_values()
    found = []
    for seed in seeds:
        rng = np.random.default_rng(1000 + seed)
        dh = {
            key: np.array(value, float) + rng.normal(0.0, 0.2 if key in ("a", "d") else 0.0002, 6)
            for key, value in truth.NOMINAL.items()
        }
        folder = tmp_path / f"{carry_errors}-{seed}"
        folder.mkdir()
        text = (EXAMPLE / "ur5_eye_in_hand.yaml").read_text()
        (folder / "cell.yaml").write_text(
            text.replace("      default: {status: X}\n", DH_ERRORS) if carry_errors else text
        )
        truth.write_csv(folder / "ur5_camera_views.csv", 20, seed, dh=dh)
        cal = calibrate(compile_problem(load_problem(folder / "cell.yaml")), check_samples=0)
        names = list(cal.names)
        index = [names.index(name) for name in MOUNT]
        error = np.array([cal.estimate[k] - expected[name] for k, name in zip(index, MOUNT)])
        found.append(float(error @ np.linalg.solve(cal.covariance[np.ix_(index, index)], error)) / 6)
    return found


def test_a_robot_with_errors_is_carried_into_an_honest_hand_eye(tmp_path):
    """The hand-eye fit that trusts the robot's poses is over-confident (NEES / 6 about 16 over 12
    seeds); with the DH errors as L (their priors the robot's tolerance) it is honest (1.12 over
    12 seeds; here 6): bcad's answer carries what it does not know about the robot."""
    carried = _hand_eye_nees(tmp_path, range(6), carry_errors=True)
    assert 0.5 < np.mean(carried) < 1.8, carried
    trusted = _hand_eye_nees(tmp_path, range(3), carry_errors=False)
    assert np.mean(trusted) > 5.0, trusted


OST = """image_width: 800
image_height: 600
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [538.63, 0, 457.698, 0, 539.723, 297.003, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.30678, 0.0825017, 0.0028784, -0.00015829, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [538.63, 0, 457.698, 0, 0, 539.723, 297.003, 0, 0, 0, 1, 0]
"""


def test_a_ros_camera_info_file_reads_and_writes_back_the_same_numbers(tmp_path):
    from bcad.model.camera_info import camera_info_text, read_camera_info

    original = tmp_path / "ost.yaml"
    original.write_text(OST)
    info = read_camera_info(original)
    assert (info.width, info.height, info.model, info.name) == (800, 600, "plumb_bob", "narrow_stereo")
    assert info.values == {
        "fx": 538.63,
        "fy": 539.723,
        "cx": 457.698,
        "cy": 297.003,
        "k1": -0.30678,
        "k2": 0.0825017,
        "p1": 0.0028784,
        "p2": -0.00015829,
        "k3": 0.0,
    }
    written = tmp_path / "back.yaml"
    written.write_text(camera_info_text(info))
    import yaml

    again, source = yaml.safe_load(written.read_text()), yaml.safe_load(OST)
    for key in source:
        assert again[key] == source[key], key  # every number (and the rest) as it was
    assert read_camera_info(written) == info


def test_the_calibrated_camera_is_written_as_camera_info_and_read_back_as_fixed_intrinsics(tmp_path):
    """--camera-info writes the estimate; a problem whose camera names that file (and no
    intrinsics) takes its numbers as fixed and identifies the rest."""
    path = _copy_example(tmp_path, 3)
    result = runner.invoke(
        app, ["calibrate", str(path), "--camera-info", str(tmp_path / "camera.yaml"), "--json", "--quiet"]
    )
    assert result.exit_code == 0, result.output
    document = json.loads(result.stdout)
    from bcad.model.camera_info import read_camera_info

    info = read_camera_info(tmp_path / "camera.yaml")
    for name in ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"):
        assert info.values[name] == document["parameters"][f"camera.{name}"]["estimate"]
    assert document["camera_info"] == {"camera": str(tmp_path / "camera.yaml")}
    text = path.read_text()
    start, end = text.index("    image_size:"), text.index("measurements:")
    path.write_text(text[:start] + "    camera_info: camera.yaml\n\n" + text[end:])
    fixed = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet"])
    assert fixed.exit_code == 0, fixed.output
    parameters = json.loads(fixed.stdout)["parameters"]
    assert not any(name.startswith("camera.") for name in parameters)
    for name in MOUNT:  # the same hand-eye, the intrinsics now known
        before = document["parameters"][name]
        assert abs(parameters[name]["estimate"] - before["estimate"]) < 0.2 * before["std"]
        assert parameters[name]["std"] <= before["std"] * 1.0001


def test_a_file_that_is_not_camera_info_is_refused_unquoted(tmp_path):
    path = _copy_example(tmp_path, 1, views=2)
    (tmp_path / "secret.yaml").write_text("password: hunter2\nimage_width: 3\n")
    text = path.read_text()
    start, end = text.index("    image_size:"), text.index("measurements:")
    path.write_text(text[:start] + "    camera_info: secret.yaml\n\n" + text[end:])
    result = runner.invoke(app, ["calibrate", str(path)])
    assert result.exit_code == 2 and "not a camera file" in result.output, result.output
    assert "hunter2" not in result.output


ROS_INFO = """image_width: {width}
image_height: 1024
camera_matrix:
  rows: 3
  cols: 3
  data: [{fx}, 0, 640, 0, 800, 512, 0, 0, 1]
distortion_model: {model}
distortion_coefficients: {{data: [0, 0, 0, 0, {k3}]}}
"""


@pytest.mark.parametrize(
    ("values", "place", "fragment"),
    [
        ({"fx": "0"}, (6, 10), "expected positive focal lengths"),
        ({"fx": "0, 1"}, (6, 9), "camera_matrix: expected 9 finite numbers"),
        ({"width": "0"}, (1, 14), "image_width and image_height"),
        ({"model": "fisheye"}, (7, 19), "distortion_model: expected one of"),
        ({"k3": ".nan"}, (8, 46), "distortion_coefficients: expected 4 or 5 finite numbers"),
    ],
)
def test_a_camera_info_error_names_the_line_and_column_of_its_value(tmp_path, values, place, fragment):
    """camera_info errors named the file alone: each names the line and column of the value at
    fault (the first one, in a list)."""
    from bcad.errors import InputError
    from bcad.model.camera_info import read_camera_info

    path = tmp_path / "info.yaml"
    path.write_text(ROS_INFO.format(**{"width": "1280", "fx": "800", "model": "plumb_bob", "k3": "0", **values}))
    with pytest.raises(InputError) as error:
        read_camera_info(path)
    assert (error.value.line, error.value.column) == place and fragment in error.value.message, error.value


def test_kalibr_and_opencv_camera_errors_are_placed(tmp_path):
    from bcad.errors import InputError
    from bcad.model.camera_info import read_camera_info

    kalibr = tmp_path / "camchain.yaml"
    kalibr.write_text("cam0:\n  intrinsics: [800, -1, 640, 512]\n  resolution: [1280, 1024]\n")
    opencv = tmp_path / "opencv.yaml"
    opencv.write_text(
        "%YAML:1.0\n---\nimage_width: 1280\nimage_height: 1024\n"
        "camera_matrix: !!opencv-matrix {rows: 3, cols: 3, dt: d, data: [800, 0, 640, 0, 800, 512, 0, 2, 1]}\n"
        "distortion_coefficients: !!opencv-matrix {rows: 1, cols: 5, dt: d, data: [0, 0, 0, 0, 0]}\n"
    )
    for path, place in ((kalibr, (2, 21)), (opencv, (5, 94))):
        with pytest.raises(InputError) as error:
            read_camera_info(path)
        assert (error.value.line, error.value.column) == place, error.value


def test_the_calibrated_urdf_carries_the_camera_mount_at_the_estimate(tmp_path):
    import xml.etree.ElementTree as ElementTree

    path = _copy_example(tmp_path, 4)
    result = runner.invoke(app, ["calibrate", str(path), "--urdf", str(tmp_path / "ur5.urdf"), "--json", "--quiet"])
    assert result.exit_code == 0, result.output
    parameters = json.loads(result.stdout)["parameters"]
    joint = next(
        j for j in ElementTree.parse(tmp_path / "ur5.urdf").getroot().iter("joint") if j.get("name") == "camera_mount"
    )
    assert joint.get("type") == "fixed" and joint.find("parent").get("link") == "link_6"
    assert joint.find("child").get("link") == "camera_optical"
    estimate = MOUNT_NOMINAL + np.array([parameters[name]["estimate"] for name in MOUNT])
    origin = joint.find("origin")
    xyz = np.array(origin.get("xyz").split(), float) * 1000.0  # metres in the URDF, mm in the problem
    rpy = np.array(origin.get("rpy").split(), float)
    np.testing.assert_allclose(xyz, estimate[:3], rtol=0, atol=1e-9)
    np.testing.assert_allclose(rpy, estimate[3:], rtol=0, atol=1e-9)


def test_next_best_views_leave_the_degenerate_set_and_identify_the_camera(tmp_path):
    """From a degenerate set (every view turning about a vertical axis), --propose ranks candidate
    views: the three it picks are among the ten that turn the camera about other axes, not the ten
    that turn it as before; measured, they identify the mount's z and the focal lengths."""
    shutil.copy(EXAMPLE / "ur5_eye_in_hand.yaml", tmp_path / "cell.yaml")
    truth.write_csv(tmp_path / "ur5_camera_views.csv", 15, 5, degenerate=True)
    rng = np.random.default_rng(9)
    candidates = np.vstack([truth.turning_views(rng, 10), truth.views(rng, 10, 0.35)])
    lines = [",".join(truth.JOINTS)] + [",".join(f"{v:.10f}" for v in q) for q in candidates]
    (tmp_path / "candidates.csv").write_text("\n".join(lines) + "\n")
    result = runner.invoke(
        app,
        [
            "calibrate",
            str(tmp_path / "cell.yaml"),
            "--propose",
            "3",
            "--candidates",
            str(tmp_path / "candidates.csv"),
            "--json",
            "--quiet",
        ],
    )
    assert result.exit_code == 3, result.output  # still the degenerate set: camera_not_identified
    picked = [entry["row"] for entry in json.loads(result.stdout)["proposal"]["ranked"]]
    assert all(row > 10 for row in picked), picked
    # measure the picked views (the same truth, 0.5 px) beside the old ones
    extra = np.random.default_rng(10)
    text = (tmp_path / "ur5_camera_views.csv").read_text()
    for row in picked:
        uv = truth.pixels(candidates[row - 1]) + extra.normal(0.0, truth.NOISE, (truth.ROWS * truth.COLUMNS, 2))
        text += "".join(
            ",".join([f"{v:.10f}" for v in candidates[row - 1]] + [str(i), f"{uv[i, 0]:.6f}", f"{uv[i, 1]:.6f}"]) + "\n"
            for i in range(len(uv))
        )
    (tmp_path / "ur5_camera_views.csv").write_text(text)
    after = runner.invoke(app, ["calibrate", str(tmp_path / "cell.yaml"), "--json", "--quiet"])
    assert after.exit_code == 0, after.output
    parameters = json.loads(after.stdout)["parameters"]
    assert parameters["camera_mount.tz"]["identified"] and parameters["camera.fx"]["identified"]


def test_predicted_pixels_of_a_new_view_carry_their_std(tmp_path):
    """--predict at a configuration: the camera's u, v of every target point, each with its std;
    a fresh view's pixels lie within a few of sqrt(std^2 + noise^2) of them."""
    path = _copy_example(tmp_path, 6)
    q = truth.views(np.random.default_rng(77), 1)[0]
    (tmp_path / "new.csv").write_text(",".join(truth.JOINTS) + "\n" + ",".join(f"{v:.10f}" for v in q) + "\n")
    result = runner.invoke(app, ["calibrate", str(path), "--predict", str(tmp_path / "new.csv"), "--json", "--quiet"])
    assert result.exit_code == 0, result.output
    entry = json.loads(result.stdout)["prediction"]["rows"][0]["measurements"]["views"]
    assert entry["noise_std"] == 0.5 and [p["point"] for p in entry["points"]] == list(range(48))
    values = np.array([[p["u"]["value"], p["v"]["value"]] for p in entry["points"]])
    std = np.array([[p["u"]["std"], p["v"]["std"]] for p in entry["points"]])
    assert values.shape == (48, 2) and np.all(std > 0)
    fresh = truth.pixels(q)  # noise-free: the truth itself
    z = (fresh - values) / std
    assert np.sqrt(np.mean(z**2)) < 3.0, np.sqrt(np.mean(z**2))


def test_opencv_filestorage_and_kalibr_camera_files_are_read(tmp_path):
    """A file OpenCV's own FileStorage writes (%YAML:1.0, !!opencv-matrix) and a Kalibr camchain
    (radtan: k1, k2, r1, r2) give the camera's numbers."""
    from bcad.model.camera_info import read_camera_info

    K = np.array([[538.63, 0.0, 457.698], [0.0, 539.723, 297.003], [0.0, 0.0, 1.0]])
    D = np.array([[-0.30678], [0.0825017], [0.0028784], [-0.00015829], [0.011]])
    storage = cv2_module().FileStorage(str(tmp_path / "opencv.yaml"), cv2_module().FILE_STORAGE_WRITE)
    storage.write("image_width", 800)
    storage.write("image_height", 600)
    storage.write("camera_matrix", K)
    storage.write("distortion_coefficients", D)
    storage.release()
    assert (tmp_path / "opencv.yaml").read_text().startswith("%YAML:1.0")
    info = read_camera_info(tmp_path / "opencv.yaml")
    assert (info.width, info.height, info.model) == (800, 600, "plumb_bob")
    assert [info.values[k] for k in ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")] == [
        538.63,
        539.723,
        457.698,
        297.003,
        -0.30678,
        0.0825017,
        0.0028784,
        -0.00015829,
        0.011,
    ]
    (tmp_path / "camchain.yaml").write_text(
        "cam0:\n  camera_model: pinhole\n  intrinsics: [461.629, 460.152, 362.680, 246.049]\n  distortion_model: radtan\n"
        "  distortion_coeffs: [-0.27695497, 0.06712482, 0.00087538, 0.00011556]\n  resolution: [752, 480]\n"
        "  rostopic: /cam0/image_raw\n"
    )
    info = read_camera_info(tmp_path / "camchain.yaml", "camera")
    assert (info.width, info.height, info.name) == (752, 480, "cam0")
    assert [info.values[k] for k in ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")] == [
        461.629,
        460.152,
        362.680,
        246.049,
        -0.27695497,
        0.06712482,
        0.00087538,
        0.00011556,
        0.0,
    ]


def cv2_module():
    return pytest.importorskip("cv2")


def test_the_arms_picture_draws_each_camera_s_field_of_view(tmp_path):
    """The frustum's rays go through the image's corners: (u - cx) / fx, (v - cy) / fy, 1 in the
    optical frame (the intrinsics at their means), and the picture draws it."""
    pytest.importorskip("matplotlib")
    from bcad.plot.arms import camera_frustum

    path = _copy_example(tmp_path, 1, views=2)
    compiled = compile_problem(load_problem(path))
    camera = compiled.problem.cameras[0]
    T = truth.pose_matrix(np.array([10.0, 20.0, 30.0, 0.1, -0.2, 0.3]))
    points = camera_frustum(compiled, camera, T, 100.0)
    local = (points - T[:3, 3]) @ T[:3, :3]  # back into the optical frame
    np.testing.assert_allclose(local[0], 0.0, atol=1e-12)
    np.testing.assert_allclose(local[1], [(0 - 640) / 1100 * 100, (0 - 512) / 1100 * 100, 100.0])
    np.testing.assert_allclose(local[4], [(1280 - 640) / 1100 * 100, (1024 - 512) / 1100 * 100, 100.0])
    result = runner.invoke(app, ["plot", str(path), "--what", "arms", "-o", str(tmp_path / "arms.png")])
    assert result.exit_code == 0 and (tmp_path / "arms.png").stat().st_size > 10_000, result.output


def test_a_board_located_by_the_camera_then_touched_has_the_plan_s_spread(tmp_path):
    """Measure, then plan: the plan takes the board's joint posterior from the committed camera
    calibration; at its X*, the spread of the probe tip's height over the board (Table 2, the
    unweighted std of tz) is what an independent Monte Carlo gives: the board placement drawn from
    the calibration's Gaussian (MAP, std, correlations), the tip from the plain DH product."""
    import bcad

    plan = EXAMPLE / "ur5_camera_touch_plan.yaml"
    result = bcad.solve(plan, samples=200_000)
    touch = result.document["posterior"]["links"]["touch"]
    x = [result.document["solution"][f"ur5/joint_{k}.rz"] for k in range(1, 7)]
    calibration = json.loads((EXAMPLE / "ur5_eye_in_hand_calibration.json").read_text())
    names = [f"board_placement.{p}" for p in ("tx", "ty", "tz", "rx", "ry", "rz")]
    every = calibration["correlation"]["names"]
    index = [every.index(name) for name in names]
    correlation = np.array(calibration["correlation"]["matrix"])[np.ix_(index, index)]
    std = np.array([calibration["parameters"][name]["laplace_std"] for name in names])
    mean = np.array([calibration["parameters"][name]["map"] for name in names])
    rng = np.random.default_rng(5)
    deviations = rng.multivariate_normal(mean, correlation * np.outer(std, std), 200_000)
    tip = (truth.flange(np.array(x), truth.NOMINAL) @ np.array([0.0, 0.0, 150.0, 1.0]))[:3]
    # the tip's height over the board's face: (R_board R_face)^T (tip - t_board) . z, the face's normal
    # R_face = Rx(pi) flips z, and the face's origin offset lies in the board's plane
    tx, ty, tz, rx, ry, rz = (BOARD_NOMINAL + deviations).T
    normal = np.stack(
        [
            np.cos(rz) * np.sin(ry) * np.cos(rx) + np.sin(rz) * np.sin(rx),
            np.sin(rz) * np.sin(ry) * np.cos(rx) - np.cos(rz) * np.sin(rx),
            np.cos(ry) * np.cos(rx),
        ],
        axis=1,
    )  # the board's z axis: R = Rz Ry Rx, third column
    heights = -np.einsum("ni,ni->n", tip[None] - np.stack([tx, ty, tz], axis=1), normal)
    mc_std = heights.std()
    mc_se = mc_std / np.sqrt(2 * (len(heights) - 1))
    assert abs(touch["std"][2] - mc_std) < 3 * np.hypot(touch["std_se"][2], mc_se), (touch["std"][2], mc_std)


def test_the_committed_camera_calibration_is_what_calibrate_writes(tmp_path):
    out = tmp_path / "fresh.json"
    result = runner.invoke(app, ["calibrate", str(EXAMPLE / "ur5_eye_in_hand.yaml"), "-o", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    assert_committed_calibration(out, EXAMPLE / "ur5_eye_in_hand_calibration.json")


EYE_TO_HAND = """
name: ur5-eye-to-hand
units: {length: mm, angle: rad}
frames: [world, camera_optical, board_frame]
robots:
  - name: ur5
    parent: world
    dh:
      - {a: 0, alpha: 1.5707963267948966, d: 89.159, theta: 0, limits: [-6.2832, 6.2832]}
      - {a: -425, alpha: 0, d: 0, theta: 0, limits: [-6.2832, 6.2832]}
      - {a: -392.25, alpha: 0, d: 0, theta: 0, limits: [-3.1416, 3.1416]}
      - {a: 0, alpha: 1.5707963267948966, d: 109.15, theta: 0, limits: [-6.2832, 6.2832]}
      - {a: 0, alpha: -1.5707963267948966, d: 94.65, theta: 0, limits: [-6.2832, 6.2832]}
      - {a: 0, alpha: 0, d: 82.3, theta: 0, limits: [-6.2832, 6.2832]}
    joints:
      default: {status: X}
links:
  - name: camera_mount          # the camera on a stand, looking up at the flange
    parent: world
    child: camera_optical
    pose: [-400, -100, -50, 0, 0, 1.5708]
    status: LLLLLL
    distributions: {tx: 'normal(0, 20)', ty: 'normal(0, 20)', tz: 'normal(0, 20)', rx: 'normal(0, 0.05)', ry: 'normal(0, 0.05)', rz: 'normal(0, 0.05)'}
  - name: board_mount           # the board held by the robot
    parent: ur5/link_6
    child: board_frame
    pose: [-85, -60, 20, 0, 0, 0]
    status: LLLLLL
    distributions: {tx: 'normal(0, 5)', ty: 'normal(0, 5)', tz: 'normal(0, 5)', rx: 'normal(0, 0.05)', ry: 'normal(0, 0.05)', rz: 'normal(0, 0.05)'}
entities:
  - {name: board, type: target, frame: board_frame, checkerboard: {rows: 6, columns: 8, square: 25}}
cameras:
  - name: camera
    frame: camera_optical
    image_size: [1280, 1024]
    intrinsics: {fx: 'normal(1100, 50)', fy: 'normal(1100, 50)', cx: 'normal(640, 50)', cy: 'normal(512, 50)'}
    distortion: {k1: 'normal(0, 0.3)', k2: 'normal(0, 0.3)', p1: 'normal(0, 0.01)', p2: 'normal(0, 0.01)'}
measurements:
  - {name: views, reference: camera, frame: board, parameters: 'u,v', noise: 'normal(0, 0.5)', data: views.csv}
"""


def test_an_eye_to_hand_camera_is_identified_within_its_std(tmp_path):
    """The camera on a stand looking up, the board held by the robot: both placements, the
    intrinsics and the distortion, from 15 views written by the plain DH product and projection
    here; over four seeds every parameter within 4.5 std of the truth, mean squared z near 1."""
    camera_true = np.array([-406.3, -109.2, -53.6, 0.004, -0.003, 1.5708 + 0.01])
    board_true = np.array([-87.5, -62.5, 20.0, 0.01, -0.02, 0.015])
    C, B = truth.pose_matrix(camera_true), truth.pose_matrix(board_true)
    expected = {
        **{
            f"camera_mount.{p}": v
            for p, v in zip(("tx", "ty", "tz", "rx", "ry", "rz"), camera_true - [-400, -100, -50, 0, 0, 1.5708])
        },
        **{
            f"board_mount.{p}": v
            for p, v in zip(("tx", "ty", "tz", "rx", "ry", "rz"), board_true - [-85, -60, 20, 0, 0, 0])
        },
        **{f"camera.{p}": v for p, v in zip(("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"), truth.CAMERA_TRUE)},
    }

    def seen(q):
        points = (
            np.linalg.inv(C) @ truth.flange(q, truth.NOMINAL) @ B @ np.column_stack([truth.corners(), np.ones(48)]).T
        )
        x, y = points[0] / points[2], points[1] / points[2]
        fx, fy, cx, cy, k1, k2, p1, p2, k3 = truth.CAMERA_TRUE
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
        u = fx * (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)) + cx
        v = fy * (y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y) + cy
        inside = (points[2] > 0) & (u > 20) & (u < 1260) & (v > 20) & (v < 1004)
        return np.column_stack([u, v]), bool(np.all(inside))

    z = []
    for seed in range(4):
        rng = np.random.default_rng(seed)
        lines, count = [",".join(truth.JOINTS + ["point", "u", "v"])], 0
        while count < 15:
            q = truth.HOME + rng.normal(0.0, 0.25, 6)
            uv, ok = seen(q)
            if not ok:
                continue
            count += 1
            uv = uv + rng.normal(0.0, 0.5, uv.shape)
            lines += [
                ",".join([f"{v:.10f}" for v in q] + [str(i), f"{uv[i, 0]:.6f}", f"{uv[i, 1]:.6f}"]) for i in range(48)
            ]
        folder = tmp_path / str(seed)
        folder.mkdir()
        (folder / "views.csv").write_text("\n".join(lines) + "\n")
        (folder / "cell.yaml").write_text(EYE_TO_HAND)
        cal = calibrate(compile_problem(load_problem(folder / "cell.yaml")), check_samples=0)
        z += [(cal.estimate[k] - expected[name]) / cal.std[k] for k, name in enumerate(cal.names)]
    z = np.array(z)
    assert np.max(np.abs(z)) < 4.5 and 0.4 < np.mean(z**2) < 1.8, (np.max(np.abs(z)), np.mean(z**2))


def test_the_residuals_picture_draws_measured_minus_predicted(tmp_path):
    pytest.importorskip("matplotlib")
    from bcad.calibration.model import CalibrationModel
    from bcad.plot.figures import draw_residuals

    path = _copy_example(tmp_path, 8)
    compiled = compile_problem(load_problem(path))
    model = CalibrationModel(compiled)
    cal = calibrate(compiled, model, check_samples=0)
    _, drawn = draw_residuals(model, cal.residuals_after, tmp_path / "r.png")
    views = drawn["views"]
    predicted = model.predictions(cal.estimate[None])[0][0]
    np.testing.assert_allclose(views["pixels"] - views["residuals"], predicted, atol=1e-9)
    assert len(np.unique(views["views"])) == 15 and 0.4 < np.sqrt(np.mean(views["residuals"] ** 2)) < 0.6
    result = runner.invoke(app, ["plot", str(path), "--what", "residuals", "-o", str(tmp_path / "residuals.png")])
    assert result.exit_code == 0 and (tmp_path / "residuals.png").stat().st_size > 10_000, result.output
    tracker = runner.invoke(
        app, ["plot", str(EXAMPLE / "ur5_tracker.yaml"), "--what", "residuals", "-o", str(tmp_path / "t.png")]
    )
    assert tracker.exit_code == 2 and "measures no pixels" in tracker.output


def test_validate_counts_the_cameras_and_their_parameters_to_identify():
    result = runner.invoke(app, ["validate", str(EXAMPLE / "ur5_eye_in_hand.yaml")])
    assert result.exit_code == 0, result.output
    assert re.search(r"Number of cameras\s*│\s*1\b", result.output)
    assert re.search(r"Camera parameters with a distribution \(L\)\s*│\s*8\b", result.output)


def test_encoder_noise_is_carried_by_each_view_s_joint_errors(tmp_path):
    """Each view's joint readings off by 0.005 degrees (encoder noise) on a robot whose DH table is
    off too: with joint_noise on the measurement, every view gets its own joint errors (L, that
    prior), and the hand-eye's NEES / 6 comes near 1 (1.09 over 12 seeds of 20 views, all within
    the 95 % ellipsoid); without, it is over-confident (2.33, a third within). Here 3 seeds of 15."""
    encoder = float(np.radians(0.005))
    found = {False: [], True: []}
    for seed in range(3):
        rng = np.random.default_rng(2000 + seed)
        dh = {
            key: np.array(value, float) + rng.normal(0.0, 0.2 if key in ("a", "d") else np.radians(0.01), 6)
            for key, value in truth.NOMINAL.items()
        }
        lines = [",".join(truth.JOINTS + ["point", "u", "v"])]
        for q in truth.views(rng, 15):
            uv = truth.pixels(q + rng.normal(0.0, encoder, 6), dh=dh) + rng.normal(0.0, 0.5, (48, 2))
            lines += [
                ",".join([f"{v:.10f}" for v in q] + [str(i), f"{uv[i, 0]:.6f}", f"{uv[i, 1]:.6f}"]) for i in range(48)
            ]
        (tmp_path / "ur5_camera_views.csv").write_text("\n".join(lines) + "\n")
        text = (
            (EXAMPLE / "ur5_eye_in_hand.yaml")
            .read_text()
            .replace("      default: {status: X}\n", DH_ERRORS.replace("0.0002", repr(float(np.radians(0.01)))))
        )
        for noisy in (False, True):
            extra = f"    joint_noise: normal(0, {encoder!r})\n" if noisy else ""
            (tmp_path / "cell.yaml").write_text(
                text.replace("    noise: normal(0, 0.5)       # px\n", "    noise: normal(0, 0.5)       # px\n" + extra)
            )
            cal = calibrate(compile_problem(load_problem(tmp_path / "cell.yaml")), check_samples=0)
            names = list(cal.names)
            assert (sum("@views:" in name for name in names) == 15 * 6) == noisy
            index = [names.index(name) for name in MOUNT]
            expected = _true_values()
            error = np.array([cal.estimate[k] - expected[name] for k, name in zip(index, MOUNT)])
            found[noisy].append(float(error @ np.linalg.solve(cal.covariance[np.ix_(index, index)], error)) / 6)
    assert 0.3 < np.mean(found[True]) < 1.8, found
    assert np.mean(found[False]) > np.mean(found[True]), found


def _board_image(cv2, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A rendered view of the example's board (a pinhole without distortion: the homography
    K [r1 r2 t] of the board's plane) and its inner corners' true pixels (48, 2)."""
    K = np.array([[1105.0, 0.0, 652.0], [0.0, 1098.0, 508.0], [0.0, 0.0, 1.0]])
    T = np.linalg.inv(truth.camera_in_world(q)) @ truth.board_in_world()
    H = K @ np.column_stack([T[:3, 0], T[:3, 1], T[:3, 3]])  # board (x, y, 1) in mm -> pixels
    scale, margin = 8.0, 50.0  # texture px per mm; white border (mm)
    squares = np.zeros((int((175 + 2 * margin) * scale), int((225 + 2 * margin) * scale)), np.uint8) + 255
    for r in range(7):
        for c in range(9):
            if (r + c) % 2 == 0:
                x0, y0 = (margin + c * 25) * scale, (margin + r * 25) * scale
                squares[int(y0) : int(y0 + 25 * scale), int(x0) : int(x0 + 25 * scale)] = 0
    # a square's edge lies between texture pixels (their centres at whole coordinates): texture pixel
    # (i, j) is board ((i + 1/2) / scale - margin - 25, (j + 1/2) / scale - margin - 25) mm
    offset = 0.5 / scale - margin - 25
    to_board = np.array([[1 / scale, 0, offset], [0, 1 / scale, offset], [0, 0, 1.0]])
    # rendered 4 times finer, then each 4 x 4 block averaged (antialiased): an image pixel's centre
    # x is the fine image's 4 x + 1.5
    fine = np.array([[4.0, 0.0, 1.5], [0.0, 4.0, 1.5], [0.0, 0.0, 1.0]])
    image = cv2.warpPerspective(
        squares, fine @ H @ to_board, (1280 * 4, 1024 * 4), flags=cv2.INTER_LINEAR, borderValue=128
    )
    image = cv2.resize(image, (1280, 1024), interpolation=cv2.INTER_AREA)
    corners = H @ np.column_stack([truth.corners()[:, :2], np.ones(48)]).T
    return image, (corners[:2] / corners[2]).T


def test_detect_finds_the_corners_of_rendered_views(tmp_path):
    """Views rendered from the example's truth (antialiased): every inner corner within 0.15 px of
    where the camera puts it (0.09 at most here) and no bias, numbered as the target's points; a view without the board is skipped and
    counted (exit 3)."""
    cv2 = cv2_module()
    q_all, rendered = [], []
    for q in truth.views(np.random.default_rng(3), 20):  # those whose whole board (its border squares too) is in view
        image, corners = _board_image(cv2, q)
        if len(q_all) < 4 and np.all((corners > 80) & (corners < np.array([1200, 944]))):
            q_all.append(q)
            rendered.append((image, corners))
    lines, expected = ["image," + ",".join(truth.JOINTS)], []
    for k, (q, (image, corners)) in enumerate(zip(q_all, rendered)):
        cv2.imwrite(str(tmp_path / f"view{k}.png"), image)
        lines.append(f"view{k}.png," + ",".join(f"{v:.10f}" for v in q))
        expected.append(corners)
    (tmp_path / "views.csv").write_text("\n".join(lines) + "\n")
    result = runner.invoke(
        app, ["detect", str(tmp_path / "views.csv"), "--checkerboard", "8x6", "-o", str(tmp_path / "d.csv")]
    )
    assert result.exit_code == 0, result.output
    rows = (tmp_path / "d.csv").read_text().splitlines()
    assert rows[0] == ",".join(truth.JOINTS + ["point", "u", "v"]) and len(rows) == 1 + 4 * 48
    found = np.array([[float(v) for v in row.split(",")] for row in rows[1:]])
    assert np.all(found[:, 6] == np.tile(np.arange(48), 4))
    error = found[:, 7:9] - np.vstack(expected)
    assert np.max(np.abs(error)) < 0.15 and np.all(np.abs(error.mean(axis=0)) < 0.01), error
    cv2.imwrite(str(tmp_path / "blank.png"), np.full((1024, 1280), 200, np.uint8))
    (tmp_path / "views.csv").write_text(
        "\n".join(lines + ["blank.png," + ",".join(f"{v:.10f}" for v in q_all[0])]) + "\n"
    )
    missed = runner.invoke(
        app, ["detect", str(tmp_path / "views.csv"), "--checkerboard", "8x6", "-o", str(tmp_path / "d.csv")]
    )
    assert missed.exit_code == 3 and "board_not_found" in missed.output and "blank.png" in missed.output


def test_detect_refuses_what_it_cannot_read(tmp_path, monkeypatch):
    (tmp_path / "secret.csv").write_text("password,hunter2\n1,2\n")
    foreign = runner.invoke(
        app, ["detect", str(tmp_path / "secret.csv"), "--checkerboard", "8x6", "-o", str(tmp_path / "d.csv")]
    )
    assert foreign.exit_code == 2 and "columns expected (image)" in foreign.output and "hunter2" not in foreign.output
    # a views file's cells are read as a measurement's: an error names the line and column of its cell
    (tmp_path / "bad.csv").write_text('image,ur5/joint_1\nview0.png,0.1\n"view1.png",  nan\n')
    cell = runner.invoke(
        app, ["detect", str(tmp_path / "bad.csv"), "--checkerboard", "8x6", "-o", str(tmp_path / "d.csv")]
    )
    assert cell.exit_code == 2 and "bad.csv:3:13: " in cell.output and "not a finite number" in cell.output, cell.output
    bad = runner.invoke(
        app, ["detect", str(tmp_path / "secret.csv"), "--checkerboard", "8by6", "-o", str(tmp_path / "d.csv")]
    )
    assert bad.exit_code == 2 and "COLUMNSxROWS" in bad.output
    # OpenCV's pattern needs 3 corners a side at least; a size out of range is named as such
    for size in ("2x2", "201x2", "100000x100000"):
        refused = runner.invoke(
            app, ["detect", str(tmp_path / "secret.csv"), "--checkerboard", size, "-o", str(tmp_path / "d.csv")]
        )
        assert refused.exit_code == 2 and "each from 3 to 1000" in refused.output, (size, refused.output)
    # images too small to hold the board (OpenCV's search fails under 15 pixels a side): not found, exit 3
    cv2 = cv2_module()
    for side in (3, 5, 14, 20):
        cv2.imwrite(str(tmp_path / f"tiny{side}.png"), np.zeros((side, side), np.uint8))
    (tmp_path / "tiny.csv").write_text("image,j1\n" + "".join(f"tiny{side}.png,0.1\n" for side in (3, 5, 14, 20)))
    for size in ("3x3", "8x6"):
        tiny = runner.invoke(
            app, ["detect", str(tmp_path / "tiny.csv"), "--checkerboard", size, "-o", str(tmp_path / "d.csv")]
        )
        assert tiny.exit_code == 3 and "board_not_found" in tiny.output and "4 image(s)" in tiny.output, tiny.output
    (tmp_path / "views.csv").write_text("image,ur5/joint_1\nnot_an_image.png,0.1\n")
    (tmp_path / "not_an_image.png").write_text("plain text\n")
    unreadable = runner.invoke(
        app, ["detect", str(tmp_path / "views.csv"), "--checkerboard", "8x6", "-o", str(tmp_path / "d.csv")]
    )
    assert unreadable.exit_code == 2 and "not an image OpenCV reads" in unreadable.output
    # a views table with a column the detections write (its header was written with it twice), or
    # with no views ("0 of 0 views", exit 0)
    for text, place, fragment in (
        (
            "image,ur5/joint_1,point\nnot_an_image.png,0.1,3\n",
            "1:19",
            "the header names the column 'point': the detections write it",
        ),
        ("image,ur5/joint_1\n", "2:1", "a header and no views"),
    ):
        (tmp_path / "odd.csv").write_text(text)
        odd = runner.invoke(
            app, ["detect", str(tmp_path / "odd.csv"), "--checkerboard", "8x6", "-o", str(tmp_path / "d.csv")]
        )
        assert odd.exit_code == 2 and f"odd.csv:{place}: {fragment}" in odd.stderr, odd.output
    import builtins

    real_import = builtins.__import__

    def without_opencv(name, *args, **kwargs):
        if name == "cv2":
            raise ImportError("no cv2")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", without_opencv)
    missing = runner.invoke(
        app, ["detect", str(tmp_path / "views.csv"), "--checkerboard", "8x6", "-o", str(tmp_path / "d.csv")]
    )
    assert missing.exit_code == 2 and "pip install 'bcad[vision]'" in missing.output


def test_robust_loss_names_corrupted_detections(tmp_path):
    """Four detections moved by 40 px (a corner matched to the wrong place): --robust lists their
    CSV lines among its outliers, and the hand-eye stays where the clean data put it."""
    path = _copy_example(tmp_path, 11)
    clean = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet", "--check-samples", "0"])
    data = tmp_path / "ur5_camera_views.csv"
    lines = data.read_text().splitlines()
    for line in (10, 200, 400, 650):
        cells = lines[line - 1].split(",")
        cells[7] = repr(float(cells[7]) + 40.0)
        lines[line - 1] = ",".join(cells)
    data.write_text("\n".join(lines) + "\n")
    robust = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet", "--robust", "--check-samples", "0"])
    assert robust.exit_code == 0, robust.output
    document = json.loads(robust.stdout)
    flagged = {o["line"] for o in document["robust"]["outliers"]}
    # each of 720 clean rows passes the chi (2 dof) 99.9 % point with probability 0.999: a clean
    # row or two may be flagged as well
    assert {10, 200, 400, 650} <= flagged and len(flagged) <= 6, flagged
    before = json.loads(clean.stdout)["parameters"]
    for name in MOUNT:
        assert abs(document["parameters"][name]["estimate"] - before[name]["estimate"]) < 0.5 * before[name]["std"]


def test_one_wild_pixel_does_not_break_the_robust_loss_down(tmp_path):
    """One pixel far off dragged the least-squares answer so far that reweighting from it called
    nearly every other row an outlier (u 50,000 px off: fx 415 px where the truth is 1105, exit 0);
    reweighted from the priors too, the wild row alone is flagged and the intrinsics are the
    truth's. (A pixel outside the image is no reading at all, exit 2: the wild one is the image's
    far corner, 1250 px from the truth's 429, 116.)"""
    path = _copy_example(tmp_path, 2000)
    data = tmp_path / "ur5_camera_views.csv"
    lines = data.read_text().splitlines()
    cells = lines[1].split(",")
    cells[7], cells[8] = "1279.5", "1023.5"
    lines[1] = ",".join(cells)
    data.write_text("\n".join(lines) + "\n")
    result = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet", "--robust", "--check-samples", "0"])
    assert result.exit_code == 0, result.output
    document = json.loads(result.stdout)
    flagged = {o["line"] for o in document["robust"]["outliers"]}
    assert 2 in flagged and len(flagged) <= 3, flagged
    true = _true_values()
    for name in ("camera.fx", "camera.fy", "camera.cx", "camera.cy"):
        found = document["parameters"][name]
        assert abs(found["estimate"] - true[name]) < 4 * found["std"], (name, found, true[name])


def test_pixels_and_tracker_rows_calibrate_together(tmp_path):
    """A camera's views and a laser tracker's positions of the flange, on a robot whose DH table is
    off: one calibration of both. The tracker pins the DH errors the camera alone leaves near their
    prior (joint 2's a: its std falls by half or more), the hand-eye stays within 4 std of the
    truth, and the command exits 0."""
    rng = np.random.default_rng(31)
    dh = {
        key: np.array(value, float) + rng.normal(0.0, 0.2 if key in ("a", "d") else 0.0002, 6)
        for key, value in truth.NOMINAL.items()
    }
    text = (EXAMPLE / "ur5_eye_in_hand.yaml").read_text().replace("      default: {status: X}\n", DH_ERRORS)
    (tmp_path / "camera.yaml").write_text(text)
    truth.write_csv(tmp_path / "ur5_camera_views.csv", 15, 31, dh=dh)
    q = truth.views(rng, 30, 0.6)
    flange_positions = np.array([truth.flange(row, dh)[:3, 3] for row in q]) + rng.normal(0.0, 0.05, (30, 3))
    lines = [",".join(truth.JOINTS + ["tx", "ty", "tz"])] + [
        ",".join(f"{v:.10f}" for v in [*row, *position]) for row, position in zip(q, flange_positions)
    ]
    (tmp_path / "tracker.csv").write_text("\n".join(lines) + "\n")
    tracker = (
        "  - {name: tracker, frame: ur5/link_6, reference: world, parameters: 'tx,ty,tz', "
        "noise: 'normal(0, 0.05)', data: tracker.csv}\n"
    )
    (tmp_path / "both.yaml").write_text(text + tracker)
    alone = calibrate(compile_problem(load_problem(tmp_path / "camera.yaml")), check_samples=0)
    both = calibrate(compile_problem(load_problem(tmp_path / "both.yaml")), check_samples=0)
    k_alone, k_both = list(alone.names).index("ur5/joint_2/dh.tx"), list(both.names).index("ur5/joint_2/dh.tx")
    assert both.std[k_both] < 0.5 * alone.std[k_alone], (both.std[k_both], alone.std[k_alone])
    expected = _true_values()
    for name in MOUNT:
        k = list(both.names).index(name)
        assert abs(both.estimate[k] - expected[name]) < 4 * both.std[k], name
    result = runner.invoke(app, ["calibrate", str(tmp_path / "both.yaml"), "--json", "--quiet"])
    assert result.exit_code == 0, result.output
    assert set(json.loads(result.stdout)["residuals"]["after"]) == {"views", "tracker"}


def test_two_cameras_on_the_flange_are_identified_each_with_its_own_parameters(tmp_path):
    """A stereo pair: the example's camera and a second one 60 mm beside it with other intrinsics,
    each its own mount, intrinsics and distortion (their parameters follow each other in the
    parameter vector); both within 4.5 std of their truths."""
    second_mount = np.array([92.0, -16.0, 57.0, -0.01, 0.015, 1.5708 - 0.03])
    second_camera = np.array([980.0, 985.0, 630.0, 520.0, -0.08, 0.05, -0.0006, 0.0004, 0.0])
    text = (EXAMPLE / "ur5_eye_in_hand.yaml").read_text()
    text = text.replace(
        "frames: [world, camera_optical, board_frame]", "frames: [world, camera_optical, right_optical, board_frame]"
    )
    text = text.replace(
        "  - name: board_placement",
        "  - name: right_mount\n    parent: ur5/link_6\n    child: right_optical\n"
        "    pose: [90, -20, 50, 0, 0, 1.5708]\n    status: LLLLLL\n    distributions: {tx: 'normal(0, 10)', "
        "ty: 'normal(0, 10)', tz: 'normal(0, 10)', rx: 'normal(0, 0.05)', ry: 'normal(0, 0.05)', "
        "rz: 'normal(0, 0.05)'}\n  - name: board_placement",
    )
    text = text.replace(
        "measurements:\n",
        "  - name: right\n    frame: right_optical\n    image_size: [1280, 1024]\n"
        "    intrinsics: {fx: 'normal(1000, 50)', fy: 'normal(1000, 50)', cx: 'normal(640, 50)', "
        "cy: 'normal(512, 50)'}\n    distortion: {k1: 'normal(0, 0.3)', k2: 'normal(0, 0.3)', "
        "p1: 'normal(0, 0.01)', p2: 'normal(0, 0.01)'}\n\nmeasurements:\n",
    )
    text += (
        "  - {name: right_views, reference: right, frame: board, parameters: 'u,v', noise: 'normal(0, 0.5)', "
        "data: right.csv}\n"
    )
    (tmp_path / "stereo.yaml").write_text(text)
    rng = np.random.default_rng(44)
    q = truth.views(rng, 15, 0.35)
    left = [",".join(truth.JOINTS + ["point", "u", "v"])]
    right = [left[0]]
    for row in q:
        for lines, mount, camera in ((left, truth.MOUNT_TRUE, truth.CAMERA_TRUE), (right, second_mount, second_camera)):
            T = np.linalg.inv(truth.flange(row, truth.NOMINAL) @ truth.pose_matrix(mount)) @ truth.board_in_world()
            p = T @ np.column_stack([truth.corners(), np.ones(48)]).T
            uv = project_reference(p[:3].T, camera) + rng.normal(0.0, 0.5, (48, 2))
            inside = (p[2] > 0) & np.all((uv > 0) & (uv < [1280, 1024]), axis=1)
            lines += [
                ",".join([f"{v:.10f}" for v in row] + [str(i), f"{uv[i, 0]:.6f}", f"{uv[i, 1]:.6f}"])
                for i in range(48)
                if inside[i]
            ]
    (tmp_path / "ur5_camera_views.csv").write_text("\n".join(left) + "\n")
    (tmp_path / "right.csv").write_text("\n".join(right) + "\n")
    cal = calibrate(compile_problem(load_problem(tmp_path / "stereo.yaml")), check_samples=0)
    expected = {
        **_true_values(),
        **{
            f"right_mount.{p}": v
            for p, v in zip(("tx", "ty", "tz", "rx", "ry", "rz"), second_mount - [90, -20, 50, 0, 0, 1.5708])
        },
        **{f"right.{p}": v for p, v in zip(("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"), second_camera)},
    }
    names = list(cal.names)
    assert sorted(names) == sorted(expected)
    z = np.array([(cal.estimate[k] - expected[name]) / cal.std[k] for k, name in enumerate(names)])
    assert np.max(np.abs(z)) < 4.5, dict(zip(names, np.round(z, 2)))


def project_reference(points: np.ndarray, camera: np.ndarray) -> np.ndarray:
    """OpenCV's projectPoints of points (N, 3) in a camera's optical frame (the test's reference)."""
    cv2 = cv2_module()
    matrix = np.array([[camera[0], 0, camera[2]], [0, camera[1], camera[3]], [0, 0, 1.0]])
    pixels, _ = cv2.projectPoints(points.astype(float), np.zeros(3), np.zeros(3), matrix, camera[4:])
    return pixels[:, 0]


def _with_camera(path, camera_block: str) -> None:
    """Replace the example's camera block (from image_size to measurements:) by ``camera_block``."""
    text = path.read_text()
    start, end = text.index("    image_size:"), text.index("measurements:")
    path.write_text(text[:start] + camera_block + "\n" + text[end:])


@pytest.mark.parametrize(
    "camera_block, fragment",
    [
        ("    image_size: [1280, 1024]\n    intrinsics: {fx: 0, fy: 1100, cx: 640, cy: 512}\n", "greater than 0"),
        (
            "    image_size: [1280, 1024]\n    intrinsics: {fx: 'normal(-5, 1)', fy: 1100, cx: 640, cy: 512}\n",
            "positive mean",
        ),
        (
            "    image_size: [1280, 1024]\n    intrinsics: {fx: 'uniform(-100, 1000)', fy: 1100, cx: 640, cy: 512}\n",
            "fx: the focal length's distribution reaches -100 px; expected one above 0 pixels",
        ),
        (
            "    image_size: [1280, 1024]\n    intrinsics: {fx: 1100, fy: 1100, cx: 640}\n",
            "a camera needs intrinsics (cy)",
        ),
        (
            "    distortion: {k4: 0.1}\n    image_size: [1280, 1024]\n    intrinsics: {fx: 1100, fy: 1100, cx: 640, cy: 512}\n",
            "k4: not coefficients of plumb_bob",
        ),
        (
            # the example's pixels reach u = 1252: a 640 x 480 image cannot have read them
            "    image_size: [640, 480]\n    intrinsics: {fx: 1100, fy: 1100, cx: 320, cy: 240}\n",
            "lies outside the 640 x 480 image of camera",
        ),
        ("    camera_info: list_model.yaml\n", "distortion_model: expected one of"),
        ("    camera_info: zero_focal.yaml\n", "positive focal lengths"),
        (
            "    camera_info: four_columns.yaml\n",
            "distortion_coefficients: its rows and cols do not hold its 5 data values",
        ),
        ("    camera_info: huge_rows.yaml\n", "camera_matrix: its rows and cols do not hold its 9 data values"),
        ("    camera_info: column.yaml\n", "camera_matrix: rows 9 and cols 1; expected a 3 x 3 matrix"),
    ],
)
def test_a_camera_that_cannot_be_is_exit_2(tmp_path, camera_block, fragment):
    path = _copy_example(tmp_path, 1, views=2)
    (tmp_path / "list_model.yaml").write_text(
        OST.replace("distortion_model: plumb_bob", "distortion_model: [plumb_bob]")
    )
    (tmp_path / "zero_focal.yaml").write_text(OST.replace("data: [538.63, 0, 457.698", "data: [0, 0, 457.698"))
    (tmp_path / "four_columns.yaml").write_text(OST.replace("  cols: 5\n", "  cols: 4\n"))
    (tmp_path / "huge_rows.yaml").write_text(OST.replace("  rows: 3\n", "  rows: 0x" + "F" * 5000 + "\n", 1))
    (tmp_path / "column.yaml").write_text(OST.replace("  rows: 3\n  cols: 3\n", "  rows: 9\n  cols: 1\n", 1))
    _with_camera(path, camera_block)
    result = runner.invoke(app, ["calibrate", str(path), "--check-samples", "0"])
    assert result.exit_code == 2 and fragment in result.output, result.output


def test_camera_info_under_partial_intrinsics_and_another_model(tmp_path):
    """The file gives what the problem does not: fx, fy from the problem (distributions), cx, cy and
    the coefficients from the file; a rational_polynomial camera over a plumb_bob file reads k4..k6 as 0."""
    path = _copy_example(tmp_path, 1)
    (tmp_path / "ost.yaml").write_text(OST.replace("800", "1280").replace("600", "1024"))
    _with_camera(
        path,
        "    camera_info: ost.yaml\n    distortion_model: rational_polynomial\n"
        "    intrinsics: {fx: 'normal(1100, 50)', fy: 'normal(1100, 50)'}\n",
    )
    compiled = compile_problem(load_problem(path))
    from bcad.calibration.model import CalibrationModel

    block = CalibrationModel(compiled).cameras[0]
    assert block.model == "rational_polynomial" and block.free == [0, 1]
    np.testing.assert_allclose(
        block.values[2:], [457.698, 297.003, -0.30678, 0.0825017, 0.0028784, -0.00015829, 0, 0, 0, 0]
    )
    assert runner.invoke(app, ["plot", str(path), "--what", "arms", "-o", str(tmp_path / "a.png")]).exit_code == 0


def test_two_measurements_of_one_name_are_refused(tmp_path):
    path = _copy_example(tmp_path, 1, views=2)
    text = path.read_text()
    path.write_text(
        text + "  - {name: views, reference: camera, frame: board, parameters: 'u,v', noise: 'normal(0, 1)', "
        "data: ur5_camera_views.csv}\n"
    )
    result = runner.invoke(app, ["calibrate", str(path)])
    assert result.exit_code == 2 and "duplicate measurement name 'views'" in result.output, result.output


def test_views_are_numbered_as_they_come_and_unseen_points_have_no_prediction(tmp_path):
    path = _copy_example(tmp_path, 5, views=4)
    text = path.read_text().replace(
        "    noise: normal(0, 0.5)       # px\n",
        "    noise: normal(0, 0.5)       # px\n    joint_noise: normal(0, 0.0001)\n",
    )
    path.write_text(text)
    result = runner.invoke(app, ["calibrate", str(path), "--json", "--quiet", "--check-samples", "0"])
    assert result.exit_code in (0, 3), result.output
    first = (tmp_path / "ur5_camera_views.csv").read_text().splitlines()[1].split(",")
    compiled = compile_problem(load_problem(path))
    from bcad.calibration.model import CalibrationModel

    model = CalibrationModel(compiled)
    m = model.measurements[0]
    assert m.views[0] == 0 and float(first[0]) == pytest.approx(m.x_rows[0, 0])
    # a configuration looking away from the board: its points are not predicted
    away = truth.HOME + np.array([np.pi, 0, 0, 0, 0, 0])
    (tmp_path / "away.csv").write_text(",".join(truth.JOINTS) + "\n" + ",".join(f"{v:.10f}" for v in away) + "\n")
    result = runner.invoke(
        app,
        ["calibrate", str(path), "--predict", str(tmp_path / "away.csv"), "--json", "--quiet", "--check-samples", "0"],
    )
    points = json.loads(result.stdout)["prediction"]["rows"][0]["measurements"]["views"]["points"]
    assert all(not p["seen"] and p["u"]["value"] is None for p in points)


def test_too_many_candidate_views_are_refused_before_their_jacobians(tmp_path):
    path = _copy_example(tmp_path, 1, views=2)
    q = truth.views(np.random.default_rng(1), 1)[0]
    (tmp_path / "many.csv").write_text(
        ",".join(truth.JOINTS) + "\n" + "\n".join([",".join(f"{v:.6f}" for v in q)] * 25_000) + "\n"
    )
    result = runner.invoke(
        app,
        ["calibrate", str(path), "--propose", "1", "--candidates", str(tmp_path / "many.csv"), "--check-samples", "0"],
    )
    assert result.exit_code == 2 and "at most" in result.output and "at once" in result.output, result.output


def test_a_pixel_outside_the_image_is_placed_at_its_cell(tmp_path):
    """A row whose v lies beyond the image's height while its u is inside is refused at its v cell,
    and one at the image's far corner (half a pixel beyond the last pixel centre) is read."""
    path = _copy_example(tmp_path, 3, views=2)
    data = tmp_path / "ur5_camera_views.csv"
    lines = data.read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[1].split(",")
    cells[header.index("u")], cells[header.index("v")] = "1279.5", "1023.5"  # the sensor's far corner
    lines[1] = ",".join(cells)
    cells = lines[2].split(",")
    cells[header.index("u")], cells[header.index("v")] = "600", "1025"
    lines[2] = ",".join(cells)
    data.write_text("\n".join(lines) + "\n")
    result = runner.invoke(app, ["calibrate", str(path), "--check-samples", "0"])
    column = len(",".join(cells[: header.index("v")])) + 2
    assert result.exit_code == 2
    assert f"ur5_camera_views.csv:3:{column}: pixel (u, v) = (600, 1025) lies outside the 1280 x 1024 image" in (
        result.stderr
    )
