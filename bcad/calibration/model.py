"""Measurements compiled against the kinematic graph: rows, chains and predictions.

Each measurement row is one configuration of the cell: the values of the
robots' X joints are set from the row, and every other parameter is shared
across rows. The parameters to identify are of two kinds:

* the free parameters L (zero offsets, DH or origin errors, base and tool
  placements...): their distributions are the priors, and their posterior
  given the measurements is the answer (its mean and std: the "L reading");
* the X parameters that are no robot joint (a tracker's placement, say):
  unknowns whose value is estimated (the MAP, with the prior the problem
  gives them, or uniform on their bounds), as X are everywhere in bcad.

A measurement predicts the pose of its ``frame`` in its ``reference`` frame
through the spanning tree, for every row and every parameter vector at once
(one batched chain evaluation: rows x parameter vectors as samples).
"""

from __future__ import annotations

import copy
import csv
import functools
import io
import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from bcad.compiler import CompiledProblem
from bcad.compiler.dimensions import cylinder_top, face_edge, nominal_radius
from bcad.compiler.problem import entity_anchor
from bcad.compiler.units import parameter_scale, parameter_scales
from bcad.errors import InputError, listed, quoted
from bcad.kinematics.camera import INTRINSICS, camera_parameters, project
from bcad.kinematics.chain import AffineParameter, Chain, LinkTransform, Samples, Term
from bcad.kinematics.se3 import wrap_angle
from bcad.model.distributions import Normal
from bcad.model.measurement import MAX_ROWS, Measurement
from bcad.model.pose import ANGULAR, PARAMETERS, parameter_unit
from bcad.model.source import read_text
from bcad.relations.geometry import SurfaceCoordinates, cylindrical_coordinates, spherical_coordinates

#: a measurement read in a face's edge frame (:func:`bcad.compiler.dimensions.face_edge`)
EDGE_REFERENCE = re.compile(r"(.+)\.edge\[(\d{1,3})\]")


@dataclass
class CompiledMeasurement:
    """One measurement: its chain, its rows' X values, the measured values and the noise's scale."""

    name: str
    chain: Chain
    slots: list[int]  # measured pose parameters (indices into tx ... rz)
    x_rows: np.ndarray  # (rows, nX): X of every row, internal units
    measured: np.ndarray  # (rows, k), internal units
    scale: np.ndarray  # (k,): the noise's standard deviation per parameter
    mean: np.ndarray  # (k,): the noise's mean
    lines: list[int] | None = None  # the rows' lines in the CSV file (None: inline rows)
    #: a camera's pixels: the camera's index in the model's cameras, and each row's target point
    #: (rows, 3) in the target's frame; the chain runs from the camera's optical frame to the target's
    camera: int | None = None
    points: np.ndarray | None = None
    #: every point of the target (P, 3), by id: what a camera would see from a new configuration
    target_points: np.ndarray | None = None
    #: with joint_noise: each row's configuration (rows sharing joint values are one view), and the
    #: noise's distribution (problem units of the joints)
    views: np.ndarray | None = None
    joint_noise: object | None = None
    #: a noise that is not normal, per measured parameter in its internal unit: the Laplace answer
    #: weighs each residual by the moment-matched Gaussian (``scale``, ``mean``), the importance
    #: check by this density (None: a normal noise, which the Gaussian is)
    noise_densities: list | None = None

    def at_configurations(self, x_rows: np.ndarray) -> CompiledMeasurement:
        """The same measurement read at other configurations (X rows, no values): a pose
        measurement's one row each, a camera's a row per point of its target at each (C x P rows,
        the configurations' rows repeated, point by point): :attr:`per_configuration` rows each."""
        if self.camera is None:
            return replace(
                self, x_rows=x_rows, measured=np.zeros((len(x_rows), len(self.slots))), lines=None, views=None
            )
        count = len(self.target_points)
        return replace(
            self,
            x_rows=np.repeat(x_rows, count, axis=0),
            measured=np.zeros((len(x_rows) * count, 2)),
            lines=None,
            points=np.tile(self.target_points, (len(x_rows), 1)),
            views=None,
        )

    @property
    def per_configuration(self) -> int:
        """Rows of :meth:`at_configurations` per configuration."""
        return 1 if self.camera is None else len(self.target_points)

    @property
    def labels(self) -> list[str]:
        """The measured values' names: pose parameters, or u and v."""
        return ["u", "v"] if self.camera is not None else [PARAMETERS[slot] for slot in self.slots]


@dataclass
class CameraBlock:
    """A camera's parameter vector (:func:`bcad.kinematics.camera.camera_parameters`): its fixed
    values, and the positions in it of the parameters to identify (L), with their priors."""

    name: str
    model: str
    values: np.ndarray  # (P,): every parameter, the identified ones at their prior mean
    free: list[int]  # positions of the identified ones in the vector
    priors: list[object]  # their distributions
    image_size: list[int]  # [width, height], px


def joint_columns(compiled: CompiledProblem) -> dict[str, tuple[int, float]]:
    """ROBOT/JOINT -> (X column, factor from the joint's value in problem units to the X parameter)."""
    columns = {}
    for k, parameter in enumerate(compiled.parameters.x):
        link = compiled.graph.links[parameter.link]
        if link.joint is not None:
            name, sign, factor = link.joint
            columns[name] = (k, sign * factor)
    return columns


@dataclass
class CsvRow:
    """A row of a CSV table of numbers: the line it starts on, its values by column, and its
    record's lines as read (to place its cells when a message needs them, :meth:`place`)."""

    line: int
    values: dict[str, float | str]  # a text column's cells as text (:func:`read_csv_table`)
    record: list[str]
    header: list[str]
    #: the header's line and its record's lines (to place a column's name, :meth:`header_error`)
    header_line: int = 1
    header_record: list[str] = field(default_factory=list)

    def place(self, column: str | None = None) -> tuple[int, int]:
        """(line, column), 1-based, where the cell of ``column`` starts; the row's first cell's
        for None or a column the row lacks."""
        starts, _ = cell_places(self.record, self.line)
        index = self.header.index(column) if column in self.header else 0
        return starts[index] if index < len(starts) else (self.line, 1)

    def error(self, path, message: str, column: str | None = None) -> InputError:
        """An :class:`InputError` at the cell of ``column`` (:meth:`place`)."""
        return InputError(path, message, *self.place(column))

    def header_error(self, path, message: str, column: str) -> InputError:
        """An :class:`InputError` at ``column``'s name in the header (a column the file should not
        have: the fault is its name, not a row's value)."""
        starts, _ = cell_places(self.header_record, self.header_line)
        index = self.header.index(column) if column in self.header else 0
        return InputError(path, message, *(starts[index] if index < len(starts) else (self.header_line, 1)))


def cell_places(record: list[str], first: int) -> tuple[list[tuple[int, int]], tuple[int, int]]:
    """Where each cell of a CSV record starts, and where the record ends (its line end), as
    (line, column), 1-based: ``record`` is its lines as the csv module's default dialect reads
    them (line ends as \\n), from line ``first``. The scan follows that dialect's states: a cell
    that opens with a quote runs to its closing quote (a doubled quote is one inside it, a line
    end too), then to the next comma."""
    starts = []
    line, column = first, 1
    state = "start"  # start of a cell, in a plain cell, in a quoted one, after a quote in one
    for text in record:
        for character in text:
            if state == "start":
                starts.append((line, column))
                state = "quoted" if character == '"' else "start" if character == "," else "plain"
                if character == "\n":
                    return starts, (line, column)
            elif state == "quoted":
                state = "quote" if character == '"' else "quoted"
            elif character == "\n":
                return (starts or [(line, column)]), (line, column)
            elif character == ",":
                state = "start"
            elif state == "quote":
                state = "quoted" if character == '"' else "plain"
            if character == "\n":
                line, column = line + 1, 1
            else:
                column += 1
    if state == "start":
        starts.append((line, column))  # an empty last cell, after a comma at the end of the file
    return (starts or [(first, 1)]), (line, column)


def read_csv_table(
    path, what: str, known: list[str], text_columns: tuple[str, ...] = (), refused: dict[str, str] | None = None
) -> tuple[list[str], list[CsvRow]]:
    """A CSV file of numbers: its header and its rows (the cells of ``text_columns`` kept as
    text, stripped: a view's image path, say). A UTF-8 byte order mark before the
    header and any line ends (LF, CRLF, CR alone) are read as they are meant; a cell beyond the
    csv module's limit is an input error at that cell. Errors name the line and column where the
    cell starts (a quoted cell may hold line ends: a row's line is the one it starts on).

    ``known``: the columns such a file may have. A header that names none of them is not a
    file of this kind (a problem may name any file): it is refused without quoting a byte of
    it. In a file of this kind, a bad cell or column name is quoted, shortened. ``refused``: the
    columns it may not have, each with why (an error at the column's name in the header)."""
    text = read_text(path, what).removeprefix("\ufeff")
    lines = list(io.StringIO(text, newline=None))  # universal newlines: CR-only files too
    reader = csv.reader(lines)
    records = _Records(reader, lines)
    try:
        return _read_rows(path, what, known, records, text_columns, refused or {})
    except csv.Error as exc:  # a cell beyond the csv module's limit: placed at the first such cell
        starts, end = cell_places(lines[records.first - 1 : max(reader.line_num, records.first)], records.first)
        ends = [*starts[1:], end]
        limit = csv.field_size_limit()
        long = [at for at, after in zip(starts, ends) if at[0] != after[0] or after[1] - at[1] > limit]
        raise InputError(path, f"not a CSV table of numbers: {exc}", *(long or starts)[0]) from None


class _Records:
    """The records of a csv reader over ``lines``, each with the lines it spans: ``first`` is
    the 1-based line where the record read last (or being read) starts."""

    def __init__(self, reader, lines: list[str]):
        self.reader, self.lines, self.first = reader, lines, 1

    def __iter__(self):
        return self

    def __next__(self) -> tuple[int, list[str], list[str]]:
        self.first = self.reader.line_num + 1
        cells = next(self.reader)
        return self.first, cells, self.lines[self.first - 1 : self.reader.line_num]


def _read_rows(
    path, what: str, known: list[str], records: _Records, text_columns: tuple[str, ...], refused: dict[str, str]
) -> tuple[list[str], list[CsvRow]]:
    try:
        header_line, cells, header_record = next(records)
    except StopIteration:
        raise InputError(path, f"empty CSV file; expected {what} with a header naming its columns", 1, 1) from None
    header = [cell.strip() for cell in cells]
    if not set(header) & set(known):
        names = ", ".join(known[:8]) + (", ..." if len(known) > 8 else "")
        raise InputError(path, f"not {what}: its first line names none of the columns expected ({names})", 1, 1)
    first_at: dict[str, int] = {}  # each name's first column (looked up, not scanned for: wide headers)
    twice = next((k for k, name in enumerate(header) if first_at.setdefault(name, k) != k), None)
    if twice is not None:
        raise InputError(
            path,
            f"the header names the column {quoted(header[twice])} twice",
            *cell_places(header_record, header_line)[0][twice],
        )
    barred = next((k for k, name in enumerate(header) if name in refused), None)
    if barred is not None:
        raise InputError(
            path,
            f"the header names the column {quoted(header[barred])}: {refused[header[barred]]}",
            *cell_places(header_record, header_line)[0][barred],
        )
    rows = []
    for line, cells, record in records:
        if not any(cell.strip() for cell in cells):
            continue
        if len(cells) != len(header):
            starts, end = cell_places(record, line)
            at = starts[len(header)] if len(cells) > len(header) else end
            raise InputError(path, f"{len(cells)} cells, the header has {len(header)}", *at)
        row = CsvRow(line, {}, record, header, header_line, header_record)
        for column, cell in zip(header, cells):
            if column in text_columns:
                row.values[column] = cell.strip()
                continue
            try:
                row.values[column] = float(cell)
            except ValueError:
                raise row.error(path, f"{quoted(cell)} in column {quoted(column)} is not a number", column) from None
            if not (math.isfinite(row.values[column]) and abs(row.values[column]) <= 1e9):
                raise row.error(
                    path, f"{quoted(cell)} in column {quoted(column)} is not a finite number of at most 1e9", column
                )
        rows.append(row)
        if len(rows) > MAX_ROWS:
            raise InputError(path, f"more than {MAX_ROWS:,} rows", line, 1)
    return header, rows


def _csv_rows(path, measured: list[str], joints: list[str], pixels: bool = False) -> list[dict]:
    """Rows of a CSV file of measurements: {"joints": {...}, "values": [...], "line": n, "point": id};
    a camera's (``pixels``) has a ``point`` column, the id of the target point each row saw."""
    extra = ["point"] if pixels else []
    header, table = read_csv_table(path, "a CSV file of measurements", joints + measured + extra)
    missing = [name for name in measured + extra if name not in header]
    if missing:
        raise InputError(path, f"the header lacks the column(s) {', '.join(missing)}", 1, 1)
    rows = []
    for row in table:
        values = row.values
        point = values.get("point")
        if pixels and not float(point).is_integer():
            raise row.error(path, f"point {point:g} is not a whole number (the id of a target point)", "point")
        rows.append(
            {
                "joints": {c: v for c, v in values.items() if c not in PARAMETERS and c not in ("u", "v", "point")},
                "values": [values[m] for m in measured],
                "line": row.line,
                "point": int(point) if pixels else None,
                "cells": row,
            }
        )
    return rows


def joint_rows(
    compiled: CompiledProblem,
    rows: list[dict],
    error,
    allow_outside_limits: bool = False,
    header_error=None,
    measured: bool = True,
) -> np.ndarray:
    """X of every row (rows, nX), the joints' columns set from ``row["joints"]`` (problem units);
    ``error(row_index, message, joint)`` raises for an unknown or missing joint, or (unless
    ``allow_outside_limits``) a value beyond the joint's limits; ``joint`` names the value at
    fault (None: the row). ``header_error(message, joint)``, where the rows are a CSV's, raises for
    an unknown joint at its column's name. ``measured``: rows of readings (where the robot was),
    else configurations to go to (candidates, predictions: no setting accepts one beyond)."""
    joints = joint_columns(compiled)
    x_rows = np.tile(np.array(compiled.parameters.x_nominal, dtype=float), (len(rows), 1))
    for r, row in enumerate(rows):
        given = set(row["joints"])
        unknown = sorted(given - set(joints))
        missing = sorted(set(joints) - given)
        if unknown:
            message = f"unknown joint(s) {listed(map(quoted, unknown), 5)}; the problem's X joints are "
            message += listed(sorted(joints))
            if header_error is not None:
                header_error(message, unknown[0])
            error(r, message, unknown[0])
        if missing:
            error(r, f"no value for joint(s) {', '.join(missing)}", None)
        for name, value in row["joints"].items():
            column, factor = joints[name]
            x_rows[r, column] = factor * value
            low, high = compiled.parameters.x_bounds[column]
            slack = 1e-9 * max(1.0, high - low)
            if not allow_outside_limits and not low - slack <= factor * value <= high + slack:
                first, last = sorted((low / factor, high / factor))
                error(
                    r,
                    f"joint {name} = {value:g} is beyond its limits [{first:g}, {last:g}] "
                    "(the robot's, or the problem's bounds for it): "
                    + (
                        "the robot cannot have been there (allow_outside_limits: true on the measurement accepts it)"
                        if measured
                        else "the robot cannot go there; expected a configuration within them"
                    ),
                    name,
                )
    return x_rows


def _constant(matrix: np.ndarray) -> LinkTransform:
    return LinkTransform(tuple(AffineParameter(0.0) for _ in range(6)), matrix)


def _camera_info(compiled: CompiledProblem, index: int):
    """Camera ``index``'s camera_info file, read (None where it names none)."""
    from bcad.model.camera_info import read_camera_info

    camera = compiled.problem.cameras[index]
    if camera.camera_info is None:
        return None
    doc = compiled.problem.source
    return read_camera_info(
        doc.named_file(("cameras", index, "camera_info"), camera.camera_info, "a ROS camera_info file"), camera.name
    )


def camera_blocks(compiled: CompiledProblem, camera_info: Callable) -> list[CameraBlock]:
    """Every camera's parameter vector: numbers fixed, distributions identified. ``camera_info(k)``:
    camera k's camera_info file, read (:func:`_camera_info`, once per model)."""
    doc = compiled.problem.source
    blocks = []
    for index, camera in enumerate(compiled.problem.cameras):
        info = camera_info(index)
        try:
            camera.check_coefficients(info)
        except ValueError as exc:
            raise doc.error(("cameras", index, "distortion"), str(exc)) from None
        values, free, priors = [], [], []
        for k, (_name, value) in enumerate(camera.values(info).items()):
            if isinstance(value, (int, float)):
                values.append(float(value))
            else:
                values.append(float(value.moments()[0][0]))
                free.append(k)
                priors.append(value)
        blocks.append(CameraBlock(camera.name, camera.model(info), np.array(values), free, priors, camera.size(info)))
    return blocks


def _pixel_ends(compiled: CompiledProblem, loc, measurement: Measurement, cameras: dict, entities: dict):
    """A camera's measurement: (camera index, its optical frame, the target entity)."""
    doc = compiled.problem.source
    camera = cameras[measurement.reference]
    target = entities.get(measurement.frame)
    if target is None or target.type != "target":
        raise doc.error(
            loc + ("frame",),
            f"'{measurement.frame}': a camera's measurement reads the points of a "
            "target entity (type: target, with a checkerboard or points) as its frame",
        )
    if measurement.parameters != "u,v":
        raise doc.error(
            loc + ("parameters",), f"a camera measures pixels: parameters: u,v (not {measurement.parameters})"
        )
    return list(cameras).index(measurement.reference), camera.frame, target


def compile_measurement(
    compiled: CompiledProblem, index: int, measurement: Measurement, camera_info: Callable
) -> CompiledMeasurement:
    """Measurement ``index``: its rows read and checked, its chain; ``camera_info(k)`` reads camera
    k's camera_info file (:func:`camera_blocks`'s, read once), where a camera's image size is in it."""
    doc = compiled.problem.source
    loc = ("measurements", index)
    units = compiled.problem.units
    graph = compiled.graph
    entities = {entity.name: entity for entity in compiled.problem.entities}
    cameras = {camera.name: camera for camera in compiled.problem.cameras}
    ends = {}  # frame or reference -> (graph frame, constant transform from it to the named frame)
    camera_index, target = None, None
    if measurement.reference in cameras:
        camera_index, optical, target = _pixel_ends(compiled, loc, measurement, cameras, entities)
        ends["reference"] = (optical, np.eye(4))
    elif measurement.parameters == "u,v":
        raise doc.error(
            loc + ("reference",),
            f"'{measurement.reference}' is no camera; pixels (u,v) are measured by a "
            f"camera of cameras: ({', '.join(cameras) or 'none in this problem'})",
        )
    reference_moves: list = []  # how uncertain dimensions move the reference: (pose parameter, L column, coefficient)
    parameter_columns = {p.name: k for k, p in enumerate(compiled.parameters.l)}
    for key in ("frame", "reference"):
        if key in ends:
            continue
        name = getattr(measurement, key)
        edge = EDGE_REFERENCE.fullmatch(name) if key == "reference" else None
        if name in graph.frames:
            ends[key] = (name, np.eye(4))
        elif name in entities:
            ends[key] = entity_anchor(entities[name], units)
        elif edge is not None and edge.group(1) in entities and entities[edge.group(1)].type == "face":
            face = entities[edge.group(1)]
            count = len(face.polygon())
            if int(edge.group(2)) >= count:
                raise doc.error(loc + (key,), f"'{name}': the face '{face.name}' has edges 0 to {count - 1}")
            host, to_face = entity_anchor(face, units)
            to_edge, reference_moves = face_edge(face, int(edge.group(2)), parameter_columns)
            ends[key] = (host, to_face @ to_edge)
        elif (
            key == "reference"
            and name.endswith(".top")
            and entities.get(name[:-4]) is not None
            and entities[name[:-4]].type == "cylinder"
        ):
            cylinder = entities[name[:-4]]
            host, to_cylinder = entity_anchor(cylinder, units)
            to_top, reference_moves = cylinder_top(cylinder, parameter_columns)
            ends[key] = (host, to_cylinder @ to_top)
        else:
            raise doc.error(
                loc + (key,),
                f"unknown frame or entity '{name}' (a face's edge: FACE.edge[k]; a cylinder's end: CYLINDER.top)",
            )
    measured = measurement.measured
    if measurement.data is not None:
        where = doc.named_file(loc + ("data",), measurement.data, "a CSV file of the measurement's rows")
        rows = _csv_rows(where, measured, sorted(joint_columns(compiled)), camera_index is not None)
    else:
        rows = [
            {"joints": row.joints, "values": row.values, "line": None, "point": row.point} for row in measurement.rows
        ]
        where = None
    if not rows and where is not None:
        raise InputError(where, "a header and no rows; expected a row per reading under the header", 2, 1)
    if not rows:
        raise doc.error(loc, f"measurement '{measurement.name}' has no rows (give rows: or data:)")

    def row_error(r: int, problem: str, column: str | None = None):
        """An error of row ``r``, at the cell (or the key) of ``column`` where one is at fault."""
        if where is not None:
            raise rows[r]["cells"].error(where, problem, column)
        key = () if column is None else ("point",) if column == "point" else ("joints", column)
        raise doc.error(loc + ("rows", r) + key, problem)

    def header_error(problem: str, column: str):
        raise rows[0]["cells"].header_error(where, problem, column)

    for r, row in enumerate(rows):
        if len(row["values"]) != len(measured):
            row_error(r, f"{len(row['values'])} values for the {len(measured)} measured parameters")
    x_rows = joint_rows(
        compiled, rows, row_error, measurement.allow_outside_limits, header_error if where is not None else None
    )
    points = None
    if camera_index is not None:
        corners = target.corner_points()
        for r, row in enumerate(rows):
            if row["point"] is None or not 0 <= row["point"] < len(corners):
                row_error(
                    r,
                    f"point {row['point']}: '{target.name}' has points 0 to {len(corners) - 1} (a camera's row names "
                    "the target point it saw)",
                    "point",
                )
        points = np.array([corners[int(row["point"])] for row in rows], dtype=float)
        slots = [0, 1]  # u and v: no angle among them
        measured_values = np.array([row["values"] for row in rows], dtype=float)
        to_internal = np.ones(2)  # pixels
        camera = cameras[measurement.reference]
        width, height = camera.size(None if camera.image_size is not None else camera_info(camera_index))
        # a pixel is read where the sensor is: OpenCV's pixel centres at 0 ... width - 1, so the
        # sensor spans [-0.5, width - 0.5]; half a pixel more on each side for a sub-pixel corner
        off = np.abs(measured_values - 0.5 * (np.array([width, height]) - 1)) > 0.5 * np.array([width, height]) + 0.5
        outside = np.flatnonzero(off.any(axis=1))
        if len(outside):
            r = int(outside[0])
            u, v = measured_values[r]
            others = f"; {len(outside)} rows of {len(rows)} are" if len(outside) > 1 else ""
            row_error(
                r,
                f"pixel (u, v) = ({u:g}, {v:g}) lies outside the {width} x {height} image of camera "
                f"'{measurement.reference}'{others}; expected the pixels the camera read, or the camera's image_size",
                ("u" if off[r, 0] else "v") if where is not None else None,
            )
    else:
        slots = [PARAMETERS.index(name) for name in measured]
        measured_values = np.array([row["values"] for row in rows], dtype=float)
        to_internal = np.array([parameter_scale(name, units) for name in measured])
        measured_values *= to_internal
    noise = measurement.noise
    if getattr(noise, "dimension", 1) != 1:
        raise doc.error(loc + ("noise",), "the noise is a distribution of one parameter, applied to each measured one")
    mean, variance = noise.moments()
    # the noise is in each measured parameter's problem unit, as its values: an angle's in radians
    # inside, as the values are (a gyro's 0.01 deg read as 0.01 rad made it 57 times too loose)
    scale = math.sqrt(float(variance[0])) * to_internal
    # An entity's frame: its host frame's, then the entity's constant pose (a point on a probe, a face
    # on a part: the tz of a probe tip in a face's frame is its distance to the face's plane).
    reference, to_reference = ends["reference"]
    frame, to_frame = ends["frame"]
    steps = [(compiled.transforms[i], forward) for i, forward in graph.tree_path(reference, frame)]
    # Measured in a sphere: spherical coordinates about its centre, as point_on_sphere's pose
    # (R longitude, R latitude, distance to the surface); in a cylinder: cylindrical coordinates,
    # as point_on_cylinder's (R theta, height along the axis, distance to the lateral surface).
    # A probe touching either reads tz = 0.
    surface = entities.get(measurement.reference)
    coordinates = None
    if surface is not None and surface.type in ("sphere", "cylinder"):
        to_coordinates = spherical_coordinates if surface.type == "sphere" else cylindrical_coordinates
        coordinates = SurfaceCoordinates(
            to_coordinates, nominal_radius(surface), parameter_columns.get(f"{surface.name}.radius")
        )
    first = []
    if reference_moves:
        # A face edge or a cylinder's top moved by uncertain dimensions: the chain from the
        # reference starts with the inverse of the move (:func:`bcad.compiler.dimensions.face_edge`)
        moved = [
            tuple(
                Term("l", column, coefficient) for parameter, column, coefficient in reference_moves if parameter == k
            )
            for k in range(6)
        ]
        first = [(LinkTransform(tuple(AffineParameter(0.0, terms) for terms in moved)), True)]
    chain = Chain(
        first + [(_constant(np.linalg.inv(to_reference)), True)] + steps + [(_constant(to_frame), True)], coordinates
    )
    lines = [row["line"] for row in rows] if where is not None else None
    views = None
    if measurement.joint_noise is not None:
        if getattr(measurement.joint_noise, "dimension", 1) != 1:
            raise doc.error(
                loc + ("joint_noise",), "the joint noise is a distribution of one value, applied to each joint"
            )
        _, first, inverse = np.unique(x_rows, axis=0, return_index=True, return_inverse=True)
        order = np.argsort(np.argsort(first))  # views numbered as they first appear in the rows
        views = order[inverse.ravel()]
    return CompiledMeasurement(
        measurement.name,
        chain,
        slots,
        x_rows,
        measured_values,
        scale,
        float(mean[0]) * to_internal,
        lines,
        camera_index,
        points,
        None if target is None else np.array(target.corner_points(), dtype=float),
        views,
        measurement.joint_noise,
        None if isinstance(noise, Normal) else [noise.scaled(float(factor)) for factor in to_internal],
    )


#: the pixel of a point a camera cannot see (behind its lens)
UNSEEN_PIXEL = 1e7
#: parameters to identify at most, and residuals x parameters (the Jacobian's size) at most
MAX_PARAMETERS = 2000
MAX_JACOBIAN = 20_000_000
#: rows x parameter vectors per batched chain evaluation (bounds the memory of every evaluation)
CHUNK = 1 << 16


class CalibrationModel:
    """Whitened residuals of every measurement as a function of the parameters to identify:
    the X that are no robot joint (``kinds`` "X"), then every L (``kinds`` "L")."""

    def __init__(self, compiled: CompiledProblem):
        self.compiled = compiled
        problem = compiled.problem
        if not problem.measurements:
            raise problem.source.error((), "the problem has no measurements: section to calibrate from")
        if problem.configurations:
            # A measurement's rows are its configurations already, each with its own joint values.
            raise problem.source.error(
                ("configurations",),
                "calibrate reads each measurement row's joint values as its "
                "configuration; remove configurations: (they are for solve and posterior)",
                key=True,
            )
        self.measurements = []
        rows = 0
        camera_info = functools.cache(lambda k: _camera_info(compiled, k))  # each file read once
        for index, measurement in enumerate(problem.measurements):
            self.measurements.append(compile_measurement(compiled, index, measurement, camera_info))
            rows += len(self.measurements[-1].x_rows)
            if rows > MAX_ROWS:  # the rows of all measurements together, read one file at a time
                raise problem.source.error(
                    ("measurements", index),
                    f"the measurements hold more than {MAX_ROWS:,} rows "
                    "together (a calibration from 100,000 rows takes about 40 s); use fewer rows",
                )
        table = compiled.parameters
        joints = {column for column, _ in joint_columns(compiled).values()}
        self.x_columns = [k for k in range(len(table.x)) if k not in joints]
        #: the cameras' parameter vectors; the identified ones follow the L in the parameter vector
        self.cameras = camera_blocks(compiled, camera_info)
        camera_names = [
            f"{block.name}.{camera_parameters(block.model)[k]}" for block in self.cameras for k in block.free
        ]
        self.l_count = len(table.l)
        #: per measurement with joint_noise: (first position, views, X columns of the joints, factors,
        #: the noise), its parameters after the cameras': every view's error of every joint
        self.joint_errors: dict[str, tuple[int, int, list[int], np.ndarray, object]] = {}
        joints = sorted(joint_columns(compiled).items())
        error_names = []
        self.camera_count = len(camera_names)
        start = len(self.x_columns) + self.l_count + len(camera_names)
        for m in self.measurements:
            if m.views is None:
                continue
            count = int(m.views.max()) + 1
            self.joint_errors[m.name] = (
                start + len(error_names),
                count,
                [c for _, (c, _) in joints],
                np.array([f for _, (_, f) in joints]),
                m.joint_noise,
            )
            for view in range(count):
                for name, (column, _) in joints:
                    parameter = table.x[column].name.rsplit(".", 1)[1]
                    error_names.append(f"{name}@{m.name}:{view + 1}.{parameter}")
        self.names = [table.x[k].name for k in self.x_columns] + table.l_names + camera_names + error_names
        self.kinds = ["X"] * len(self.x_columns) + ["L"] * (len(table.l) + len(camera_names) + len(error_names))
        n = len(self.names)
        if n > MAX_PARAMETERS or n * self.residual_count > MAX_JACOBIAN:
            raise problem.source.error(
                ("measurements",),
                f"{n} parameters to identify from {self.residual_count} measured values: "
                f"at most {MAX_PARAMETERS} parameters and {MAX_JACOBIAN:,} parameters x values",
            )

    def with_measurements(self, measurements: list[CompiledMeasurement]) -> CalibrationModel:
        """The same model predicting other measurements (candidate configurations, say)."""
        other = copy.copy(self)
        other.measurements = measurements
        return other

    @property
    def residual_count(self) -> int:
        return sum(m.measured.size for m in self.measurements)

    def residual_blocks(self, whitened: np.ndarray) -> list[np.ndarray]:
        """Stacked whitened residuals (residual_count,) back into each measurement's (rows, k),
        in the sensor's units (internal units; pixels for a camera): r std + noise mean."""
        blocks, start = [], 0
        for m in self.measurements:
            blocks.append(whitened[start : start + m.measured.size].reshape(m.measured.shape) * m.scale + m.mean)
            start += m.measured.size
        return blocks

    @property
    def row_of_residual(self) -> np.ndarray:
        """For each stacked residual, the index of its measurement row (rows numbered across measurements)."""
        parts, first = [], 0
        for m in self.measurements:
            rows, k = m.measured.shape
            parts.append(np.repeat(np.arange(first, first + rows), k))
            first += rows
        return np.concatenate(parts)

    def predictions(self, thetas: np.ndarray) -> list[np.ndarray]:
        """Predicted measured values (S, rows, k) of each measurement for S parameter vectors (S, n)."""
        thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
        count, nx = len(thetas), len(self.x_columns)
        out = []
        for m in self.measurements:
            rows = len(m.x_rows)
            x = np.tile(m.x_rows, (count, 1))
            if nx:
                x[:, self.x_columns] = np.repeat(thetas[:, :nx], rows, axis=0)
            if m.views is not None and m.name in self.joint_errors:
                # each view's joint readings are off by its own errors (encoder noise)
                start, views, columns, factors, _ = self.joint_errors[m.name]
                errors = thetas[:, start : start + views * len(columns)].reshape(count, views, len(columns))
                x[:, columns] += (errors[:, m.views, :] * factors).reshape(count * rows, len(columns))
            samples = Samples(np.repeat(thetas[:, nx : nx + self.l_count], rows, axis=0))  # every vector for every row
            transform = m.chain.evaluate(x, samples)
            if m.camera is None:
                out.append(transform.poses()[:, m.slots].reshape(count, rows, -1))
                continue
            # the target's points in the optical frame (R p + t; columns[k] is R's column k), then the pixels
            points = np.tile(m.points, (count, 1)).T
            seen = np.einsum("kin,kn->in", transform.columns, points) + transform.translations
            parameters = np.repeat(self.camera_vectors(thetas, m.camera), rows, axis=0)
            pixels = project(seen.T, parameters, self.cameras[m.camera].model).reshape(count, rows, 2)
            # a point at or behind the lens plane (NaN): far off every image, so that a least-squares
            # step that puts it there is refused, and the residuals stay finite
            out.append(np.where(np.isfinite(pixels), pixels, UNSEEN_PIXEL))
        return out

    def camera_vectors(self, thetas: np.ndarray, camera: int) -> np.ndarray:
        """A camera's whole parameter vector (S, P) for parameter vectors thetas (S, n)."""
        start = len(self.x_columns) + self.l_count + sum(len(block.free) for block in self.cameras[:camera])
        block = self.cameras[camera]
        vectors = np.tile(block.values, (len(thetas), 1))
        vectors[:, block.free] = thetas[:, start : start + len(block.free)]
        return vectors

    def visible(self, thetas: np.ndarray) -> list[np.ndarray]:
        """Per measurement, which rows (rows,) its sensor sees at the parameter vector ``theta``:
        every row of a pose measurement; a camera's points in front of its lens that land in its
        image."""
        found = []
        for m, predicted in zip(self.measurements, self.predictions(np.atleast_2d(thetas)[:1])):
            if m.camera is None:
                found.append(np.ones(len(m.x_rows), dtype=bool))
                continue
            width, height = self.cameras[m.camera].image_size
            u, v = predicted[0, :, 0], predicted[0, :, 1]
            found.append((u >= 0) & (u <= width) & (v >= 0) & (v <= height))
        return found

    def unit_of(self, k: int) -> str:
        """The unit of parameter k as reported: the problem's length or angle unit, px for a
        camera's fx, fy, cx, cy, nothing for its distortion coefficients."""
        parameter = self.names[k].rsplit(".", 1)[1]
        first_camera = len(self.x_columns) + self.l_count
        if first_camera <= k < first_camera + self.camera_count:
            return "px" if parameter in INTRINSICS else ""
        # a pose parameter, or a view's joint error (the joint's unit)
        return parameter_unit(parameter, self.compiled.problem.units)

    def output_scales(self) -> np.ndarray:
        """Factors from internal units to the problem's, per parameter to identify (pixels,
        distortion coefficients and the views' joint errors, in the joints' units, as they are)."""
        graph_names = self.names[: len(self.x_columns) + self.l_count]
        return np.concatenate(
            [parameter_scales(self.compiled, graph_names), np.ones(len(self.names) - len(graph_names))]
        )

    def residuals_batch(self, thetas: np.ndarray) -> np.ndarray:
        """(measured - predicted - noise mean) / noise std, stacked: (S, residual_count);
        evaluated CHUNK rows x vectors at a time."""
        thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
        rows = max(1, sum(len(m.x_rows) for m in self.measurements))
        step = max(1, CHUNK // rows)
        if len(thetas) <= step:
            return self._residuals_chunk(thetas)
        return np.concatenate(
            [self._residuals_chunk(thetas[start : start + step]) for start in range(0, len(thetas), step)]
        )

    def _residuals_chunk(self, thetas: np.ndarray) -> np.ndarray:
        parts = []
        for m, predicted in zip(self.measurements, self.predictions(thetas)):
            difference = m.measured[None] - predicted
            angular = ANGULAR[m.slots]
            difference[..., angular] = wrap_angle(difference[..., angular])
            parts.append(((difference - m.mean) / m.scale).reshape(len(difference), -1))
        return np.concatenate(parts, axis=1)

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        return self.residuals_batch(theta[None])[0]

    def jacobian(self, theta: np.ndarray, steps: np.ndarray, central: bool = True) -> np.ndarray:
        """d residuals / d theta by central differences (all 2n points in one batched evaluation),
        or forward ones (n + 1 points: half the work, an error of order step x curvature)."""
        theta = np.asarray(theta, dtype=float)
        n = len(theta)
        if central:
            r = self.residuals_batch(np.concatenate([theta + np.diag(steps), theta - np.diag(steps)]))
            difference = r[:n] - r[n:]
        else:
            r = self.residuals_batch(np.concatenate([theta + np.diag(steps), theta[None]]))
            difference, steps = r[:n] - r[n], steps / 2.0
        # Angular residuals wrap: a difference across the cut is the short way round.
        angular, scale = self._angular_residuals
        difference[:, angular] = wrap_angle(difference[:, angular] * scale) / scale
        return (difference / (2.0 * steps[:, None])).T

    def noise_densities(self) -> list[tuple[np.ndarray, object, float, float]]:
        """Per measured parameter whose noise is not normal: its stacked residual columns, the
        noise's density in the parameter's internal unit, and the whitening's scale and mean (a
        residual r is the difference (r scale + mean) that the density weighs)."""
        found, start = [], 0
        for m in self.measurements:
            k = len(m.slots)
            if m.noise_densities is not None:
                for slot, density in enumerate(m.noise_densities):
                    columns = start + slot + k * np.arange(len(m.x_rows))
                    found.append((columns, density, float(m.scale[slot]), float(m.mean[slot])))
            start += k * len(m.x_rows)
        return found

    @property
    def _angular_residuals(self) -> tuple[np.ndarray, np.ndarray]:
        """Which stacked residuals are angles, and their noise std (to wrap differences in radians)."""
        mask, scale = [], []
        for m in self.measurements:
            mask.append(np.tile(ANGULAR[m.slots], len(m.x_rows)))
            scale.append(np.tile(m.scale, len(m.x_rows)))
        mask, scale = np.concatenate(mask), np.concatenate(scale)
        return mask, scale[mask]
