"""Checkerboard corners in images, as the rows of a camera measurement (``bcad detect``).

The estimation never needs images: a camera measurement reads a CSV of detected points (joint
values, ``point``, ``u``, ``v``). This turns images into that CSV with OpenCV (the optional
extra ``pip install 'bcad[vision]'``): ``findChessboardCorners`` with pattern size (columns,
rows) of inner corners, refined by ``cornerSubPix``. A corner's id is OpenCV's order, r columns
+ c: the target's ``checkerboard`` numbering (:mod:`bcad.kinematics.camera`). OpenCV numbers a
board from the corner it finds first in the image, so every view must see the board the same
way up (no view turned by more than a quarter turn about the lens's axis from another), or a
board whose numbering is fixed by its markers (ChArUco, AprilGrid: written as ``points``).

The views file: a CSV with an ``image`` column (a path, relative to the file) and the view's
joint values (``ROBOT/JOINT`` columns), copied to each of its corners' rows. An image that is not
a regular file of at most :data:`MAX_IMAGE_BYTES`, or decodes to more than
:data:`MAX_IMAGE_PIXELS`, is an input error; a view whose board is not found is skipped and
counted, as is an image too small to hold the board with squares of :data:`MIN_SQUARE_PIXELS`
(OpenCV's search stops with an error on images under 15 pixels a side).
"""

from __future__ import annotations

import csv
import io
import os
from dataclasses import dataclass
from pathlib import Path

from bcad.calibration.model import read_csv_table
from bcad.errors import InputError, install_hint
from bcad.io import record_input
from bcad.model.source import check_confined

#: an image file's bytes and decoded pixels, at most
MAX_IMAGE_BYTES = 100_000_000
MAX_IMAGE_PIXELS = 100_000_000
#: the views' images' pixels in all, at most: the board's search takes about 0.2 s per megapixel
#: on two cores (a views table naming one large image a hundred times would run for half an hour)
MAX_TOTAL_PIXELS = 2_000_000_000
#: views in one file, at most
MAX_VIEWS = 10_000
#: pixels a side of a board's square, at least: a smaller image holds no board (skipped, not searched)
MIN_SQUARE_PIXELS = 4
#: inner corners along a board's side: OpenCV's pattern needs more than 2
MIN_CORNERS, MAX_CORNERS = 3, 1000


@dataclass
class Detections:
    header: list[str]  # the views' columns but image, then point, u, v
    rows: list[list[str]]
    views: int  # views read
    missed: list[str]  # images whose board was not found


def _opencv(where):
    # a decompression bomb is refused by OpenCV itself beyond this many pixels (read at import)
    os.environ.setdefault("OPENCV_IO_MAX_IMAGE_PIXELS", str(MAX_IMAGE_PIXELS))
    try:
        import cv2
    except ImportError:
        raise InputError(where, f"bcad detect needs OpenCV: {install_hint('vision')}") from None
    return cv2


def _image(cv2, path: Path):
    """The image at ``path`` in grey levels, or an :class:`InputError`."""
    import numpy as np

    check_confined(path, "an image")
    try:
        info = path.stat()
    except OSError:
        raise InputError(path, "no such image file") from None
    import stat

    if not stat.S_ISREG(info.st_mode) or info.st_size > MAX_IMAGE_BYTES:
        raise InputError(path, f"not an image file of at most {MAX_IMAGE_BYTES // 1_000_000} MB")
    record_input(path)
    data = np.fromfile(path, dtype=np.uint8)
    try:
        image = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE)
    except cv2.error:  # OpenCV refuses a header beyond its pixel limit itself (a few bytes of PNG)
        image = None
    if image is None:
        raise InputError(path, f"not an image OpenCV reads (PNG, JPEG, ...) of at most {MAX_IMAGE_PIXELS:.0e} pixels")
    return image


def detect_checkerboard(views: Path, columns: int, rows: int) -> Detections:
    """Every view's inner corners (module docstring)."""
    cv2 = _opencv(views)
    # the views' table read as a measurement's is: its errors at the line and column of the cell
    written = "the detections write it; expected the image column and the joints"
    header, table = read_csv_table(
        views,
        "a CSV file of views (an image column and the joints)",
        ["image"],
        text_columns=("image",),
        refused=dict.fromkeys(("point", "u", "v"), written),
    )
    if not table:
        raise InputError(views, "a header and no views; expected a row per view (its image and joints)", 2, 1)
    copied = [name for name in header if name != "image"]
    found, missed = [], []
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
    if len(table) > MAX_VIEWS:
        raise table[MAX_VIEWS].error(views, f"more than {MAX_VIEWS:,} views")
    pixels = 0
    for row in table:
        values = row.values
        image_path = Path(values["image"]).expanduser()
        image_path = image_path if image_path.is_absolute() else views.parent / image_path
        image = _image(cv2, image_path)
        pixels += image.size
        if pixels > MAX_TOTAL_PIXELS:
            raise row.error(
                views,
                f"the views' images exceed {MAX_TOTAL_PIXELS:.0e} pixels in all; expected fewer or smaller views",
                "image",
            )
        short, long = sorted(image.shape)
        if short < MIN_SQUARE_PIXELS * (min(columns, rows) + 1) or long < MIN_SQUARE_PIXELS * (max(columns, rows) + 1):
            missed.append(values["image"])  # too small to hold the board
            continue
        try:
            ok, corners = cv2.findChessboardCorners(
                image, (columns, rows), cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
            )
        except cv2.error as error:
            reason = str(error).strip().splitlines()[-1][-200:] if str(error).strip() else "an error"
            raise InputError(image_path, f"OpenCV could not search it for the board: {reason}") from None
        if not ok:
            missed.append(values["image"])
            continue
        corners = cv2.cornerSubPix(image, corners, (5, 5), (-1, -1), criteria)
        for point, (u, v) in enumerate(corners.reshape(-1, 2)):
            found.append([repr(values[name]) for name in copied] + [str(point), repr(float(u)), repr(float(v))])
    return Detections(copied + ["point", "u", "v"], found, len(table), missed)


def detections_text(detections: Detections) -> str:
    """The detections as the CSV a camera measurement reads (cells quoted where CSV needs it)."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(detections.header)
    writer.writerows(detections.rows)
    return out.getvalue()
