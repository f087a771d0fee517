"""Camera files: ROS camera_info YAML (camera_calibration_parsers' format, ``ost.yaml``) read
and written; OpenCV's FileStorage YAML and Kalibr's camchain read.

    image_width: 1280
    image_height: 1024
    camera_name: camera
    camera_matrix: {rows: 3, cols: 3, data: [fx, 0, cx, 0, fy, cy, 0, 0, 1]}
    distortion_model: plumb_bob
    distortion_coefficients: {rows: 1, cols: 5, data: [k1, k2, p1, p2, k3]}
    rectification_matrix: {rows: 3, cols: 3, data: [1, 0, 0, 0, 1, 0, 0, 0, 1]}
    projection_matrix: {rows: 3, cols: 4, data: [fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0]}

A monocular camera's rectification is the identity and its projection matrix K | 0 (what bcad
writes; it reads K and D, the camera's own numbers). ``distortion_model`` is plumb_bob (5
coefficients; 4 are read with k3 = 0) or rational_polynomial (8).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from bcad.errors import quoted
from bcad.kinematics.camera import DISTORTION
from bcad.model.source import Location, SourceDocument, load_yaml_text, read_text

#: what a camera_info file must have
KEYS = ("image_width", "image_height", "camera_matrix", "distortion_coefficients")


@dataclass
class CameraInfo:
    width: int
    height: int
    model: str
    values: dict[str, float]  # fx, fy, cx, cy and the model's coefficients
    name: str = "camera"


def _numbers(doc: SourceDocument, loc: Location, key: str, count: int | tuple[int, ...]) -> list[float]:
    """The numbers of the entry ``key`` of the mapping at ``loc`` (a list, or a matrix's data
    list), or an :class:`InputError` at the entry, or at its first value that is no finite number."""
    entry = _at(doc.data, loc).get(key)
    where = loc + (key, "data") if isinstance(entry, dict) else loc + (key,)
    values = entry.get("data") if isinstance(entry, dict) else entry
    counts = count if isinstance(count, tuple) else (count,)
    expected = f"{key}: expected {' or '.join(map(str, counts))} finite numbers (its data list)"
    if not isinstance(values, list) or len(values) not in counts:
        raise doc.error(where, expected, key=key not in _at(doc.data, loc))
    for k, v in enumerate(values):
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and abs(v) <= 1e9):
            raise doc.error(where + (k,), expected)
    if isinstance(entry, dict) and "rows" in entry and "cols" in entry:
        # a matrix says its own shape: data of another size is a file that contradicts itself
        shape = entry["rows"], entry["cols"]
        if not all(isinstance(n, int) and not isinstance(n, bool) and 0 < n <= 16 for n in shape) or (
            shape[0] * shape[1] != len(values)
        ):
            raise doc.error(
                loc + (key,),
                f"{key}: its rows and cols do not hold its {len(values)} data values; expected whole numbers "
                f"whose product is {len(values)}",
            )
        if len(values) == 9 and shape != (3, 3):  # a 3 x 3 matrix written as another shape of nine
            raise doc.error(loc + (key,), f"{key}: rows {shape[0]} and cols {shape[1]}; expected a 3 x 3 matrix")
    return [float(v) for v in values]


def _at(data, loc: Location):
    """The value at ``loc`` in the parsed file."""
    for key in loc:
        data = data[key]
    return data


def read_camera_info(path: Path | str, camera: str = "camera") -> CameraInfo:
    """A camera file's image size, distortion model, intrinsics and coefficients: ROS camera_info
    YAML (module docstring), OpenCV's FileStorage YAML of the same keys (``%YAML:1.0``,
    ``!!opencv-matrix``: calibrateCamera's samples write it), or a Kalibr camchain (``cam0:
    {intrinsics: [fu, fv, pu, pv], distortion_model: radtan, distortion_coeffs: [k1, k2, r1, r2],
    resolution: [w, h]}``: the entry named ``camera``, else its only one). A file that is none of
    them is refused without quoting it; a skewed camera matrix (K[0][1] != 0), which bcad does
    not model, is refused."""
    path = Path(path)
    text = read_text(path, "a camera file (ROS camera_info, OpenCV or Kalibr YAML)")
    if text.startswith("%YAML:"):  # OpenCV FileStorage: its own directive and matrix tags
        # the directive as a comment and the tags as spaces: lines and columns stay where they are
        text = "#" + text[1:].replace("!!opencv-matrix", " " * len("!!opencv-matrix"))
    doc = load_yaml_text(path, text)
    data = doc.data
    if isinstance(data, dict) and not all(key in data for key in KEYS):
        chains = {key: value for key, value in data.items() if isinstance(value, dict) and "intrinsics" in value}
        if chains:
            return _kalibr(doc, chains, camera)
    if not isinstance(data, dict) or not all(key in data for key in KEYS):
        raise doc.error(
            (),
            f"not a camera file: expected ROS camera_info or OpenCV YAML (the keys {', '.join(KEYS)}) "
            "or a Kalibr camchain (cam0: {intrinsics, distortion_coeffs, resolution})",
        )
    for key in ("image_width", "image_height"):
        value = data[key]
        if not (isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= 100_000):
            raise doc.error((key,), "image_width and image_height: expected whole numbers of pixels in [1, 100000]")
    size = [data["image_width"], data["image_height"]]
    K = _numbers(doc, (), "camera_matrix", 9)
    matrix = ("camera_matrix", "data") if isinstance(data["camera_matrix"], dict) else ("camera_matrix",)
    skewed = [k for k, expected in ((1, 0.0), (3, 0.0), (6, 0.0), (7, 0.0), (8, 1.0)) if K[k] != expected]
    if skewed:
        raise doc.error(
            matrix + (skewed[0],),
            "camera_matrix: expected [fx, 0, cx, 0, fy, cy, 0, 0, 1] (a skewed camera is not modelled)",
        )
    model = data.get("distortion_model", "plumb_bob")
    if not isinstance(model, str) or model not in DISTORTION:
        raise doc.error(("distortion_model",), f"distortion_model: expected one of {', '.join(DISTORTION)}")
    names = DISTORTION[model]
    coefficients = _numbers(doc, (), "distortion_coefficients", (4, 5) if model == "plumb_bob" else (8,))
    coefficients += [0.0] * (len(names) - len(coefficients))
    for k in (0, 4):
        if not K[k] > 0:
            raise doc.error(matrix + (k,), "camera_matrix: expected positive focal lengths fx, fy (pixels)")
    values = {"fx": K[0], "fy": K[4], "cx": K[2], "cy": K[5], **dict(zip(names, coefficients))}
    name = data.get("camera_name")
    return CameraInfo(size[0], size[1], model, values, name if isinstance(name, str) else "camera")


#: Kalibr's distortion models bcad reads, by bcad's name
KALIBR_MODELS = {"radtan": "plumb_bob", "none": "plumb_bob"}


def _kalibr(doc: SourceDocument, chains: dict, camera: str) -> CameraInfo:
    if camera in chains:
        entry = chains[camera]
    elif len(chains) == 1:
        camera, entry = next(iter(chains.items()))
    else:
        raise doc.error(
            (),
            f"a Kalibr camchain of {len(chains)} cameras: name the bcad camera as its entry "
            f"({', '.join(sorted(map(str, chains))[:8])})",
        )
    shown = quoted(camera)
    if entry.get("camera_model", "pinhole") != "pinhole":
        raise doc.error((camera, "camera_model"), f"{shown}: camera_model: only pinhole cameras are modelled")
    model = entry.get("distortion_model", "radtan")
    if not isinstance(model, str) or model not in KALIBR_MODELS:
        raise doc.error(
            (camera, "distortion_model"),
            f"{shown}: distortion_model: expected radtan or none (equidistant is not modelled)",
        )
    fu, fv, pu, pv = _numbers(doc, (camera,), "intrinsics", 4)
    for k, focal in enumerate((fu, fv)):
        if not focal > 0:
            raise doc.error(
                (camera, "intrinsics", k), f"{shown}: intrinsics: expected positive focal lengths fu, fv (pixels)"
            )
    coefficients = _numbers(doc, (camera,), "distortion_coeffs", (0, 4)) if "distortion_coeffs" in entry else []
    size = entry.get("resolution")
    if not (
        isinstance(size, list)
        and len(size) == 2
        and all(isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 100_000 for v in size)
    ):
        raise doc.error(
            (camera, "resolution"), f"{shown}: resolution: expected [width, height] in whole pixels", key=size is None
        )
    values = {
        "fx": fu,
        "fy": fv,
        "cx": pu,
        "cy": pv,
        **dict(zip(("k1", "k2", "p1", "p2"), coefficients + [0.0] * 4)),
        "k3": 0.0,
    }
    return CameraInfo(size[0], size[1], "plumb_bob", values, str(camera))


def _matrix(rows: int, columns: int, data: list[float]) -> str:
    return f"  rows: {rows}\n  cols: {columns}\n  data: [{', '.join(repr(float(v)) for v in data)}]\n"


def camera_info_text(info: CameraInfo) -> str:
    """The camera as ROS camera_info YAML (every number at full precision: it reads back equal)."""
    v = info.values
    K = [v["fx"], 0.0, v["cx"], 0.0, v["fy"], v["cy"], 0.0, 0.0, 1.0]
    D = [v[name] for name in DISTORTION[info.model]]
    P = [v["fx"], 0.0, v["cx"], 0.0, 0.0, v["fy"], v["cy"], 0.0, 0.0, 0.0, 1.0, 0.0]
    return (
        f"image_width: {info.width}\nimage_height: {info.height}\ncamera_name: {info.name}\n"
        f"camera_matrix:\n{_matrix(3, 3, K)}distortion_model: {info.model}\n"
        f"distortion_coefficients:\n{_matrix(1, len(D), D)}"
        f"rectification_matrix:\n{_matrix(3, 3, [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0])}"
        f"projection_matrix:\n{_matrix(3, 4, P)}"
    )
