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
import io
import math
import re
from dataclasses import dataclass

import numpy as np

from bcad.compile import CompiledProblem
from bcad.compile.compiler import entity_anchor
from bcad.compile.dimensions import cylinder_top, face_edge, nominal_radius
from bcad.compile.relations import SurfaceCoordinates, cylindrical_coordinates, spherical_coordinates
from bcad.compile.units import parameter_scale
from bcad.errors import InputError, quoted
from bcad.kinematics.chain import AffineParameter, Chain, LinkTransform, Samples, Term
from bcad.model.measurement import MAX_ROWS, Measurement
from bcad.model.pose import PARAMETERS
from bcad.model.source import read_text
from bcad.kinematics.se3 import wrap_angle
from bcad.model.pose import ANGULAR


#: a measurement read in a face's edge frame (:func:`bcad.compile.dimensions.face_edge`)
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


def joint_columns(compiled: CompiledProblem) -> dict[str, tuple[int, float]]:
    """ROBOT/JOINT -> (X column, factor from the joint's value in problem units to the X parameter)."""
    columns = {}
    for k, parameter in enumerate(compiled.parameters.x):
        link = compiled.graph.links[parameter.link]
        if link.joint is not None:
            name, sign, factor = link.joint
            columns[name] = (k, sign * factor)
    return columns


def read_csv_table(path, what: str, known: list[str]) -> tuple[list[str], list[tuple[int, dict[str, float]]]]:
    """A CSV file of numbers: its header and its rows as (line, {column: value}). A UTF-8 byte
    order mark before the header and any line ends (LF, CRLF, CR alone) are read as they are
    meant; a cell beyond the csv module's limit is an input error on its line.

    ``known``: the columns such a file may have. A header that names none of them is not a
    file of this kind (a problem may name any file): it is refused without quoting a byte of
    it. In a file of this kind, a bad cell or column name is quoted, shortened."""
    text = read_text(path, what).removeprefix("\ufeff")
    reader = csv.reader(io.StringIO(text, newline=None))  # universal newlines: CR-only files too
    try:
        return _read_rows(path, what, known, reader)
    except csv.Error as exc:
        raise InputError(path, f"not a CSV table of numbers: {exc}", reader.line_num or None) from None


def _read_rows(path, what: str, known: list[str], reader) -> tuple[list[str], list[tuple[int, dict[str, float]]]]:
    try:
        header = [cell.strip() for cell in next(reader)]
    except StopIteration:
        raise InputError(path, f"empty CSV file; expected {what} with a header naming its columns", 1) from None
    if not set(header) & set(known):
        names = ", ".join(known[:8]) + (", ..." if len(known) > 8 else "")
        raise InputError(path, f"not {what}: its first line names none of the columns expected ({names})", 1)
    if len(set(header)) != len(header):
        raise InputError(path, "the header names a column twice", 1)
    rows = []
    for line, cells in enumerate(reader, start=2):
        if not any(cell.strip() for cell in cells):
            continue
        if len(cells) != len(header):
            raise InputError(path, f"{len(cells)} cells, the header has {len(header)}", line)
        values = {}
        for column, cell in zip(header, cells):
            try:
                values[column] = float(cell)
            except ValueError:
                raise InputError(path, f"{quoted(cell)} in column {quoted(column)} is not a number", line) from None
            if not (math.isfinite(values[column]) and abs(values[column]) <= 1e9):
                raise InputError(path, f"{quoted(cell)} in column {quoted(column)} is not a finite number of at most 1e9", line)
        rows.append((line, values))
        if len(rows) > MAX_ROWS:
            raise InputError(path, f"more than {MAX_ROWS:,} rows", line)
    return header, rows


def _csv_rows(path, measured: list[str], joints: list[str]) -> list[dict]:
    """Rows of a CSV file of measurements: {"joints": {...}, "values": [...], "line": n}."""
    header, table = read_csv_table(path, "a CSV file of measurements", joints + measured)
    missing = [name for name in measured if name not in header]
    if missing:
        raise InputError(path, f"the header lacks the measured parameter(s) {', '.join(missing)}", 1)
    return [
        {"joints": {c: v for c, v in values.items() if c not in PARAMETERS}, "values": [values[m] for m in measured], "line": line}
        for line, values in table
    ]


def joint_rows(compiled: CompiledProblem, rows: list[dict], error, allow_outside_limits: bool = False) -> np.ndarray:
    """X of every row (rows, nX), the joints' columns set from ``row["joints"]`` (problem units);
    ``error(row_index, message)`` raises for an unknown or missing joint, or (unless
    ``allow_outside_limits``) a value beyond the joint's limits."""
    joints = joint_columns(compiled)
    x_rows = np.tile(np.array(compiled.parameters.x_nominal, dtype=float), (len(rows), 1))
    for r, row in enumerate(rows):
        given = set(row["joints"])
        unknown = sorted(given - set(joints))
        missing = sorted(set(joints) - given)
        if unknown:
            error(r, f"unknown joint(s) {', '.join(map(quoted, unknown[:5]))}; the problem's X joints are {', '.join(sorted(joints))}")
        if missing:
            error(r, f"no value for joint(s) {', '.join(missing)}")
        for name, value in row["joints"].items():
            column, factor = joints[name]
            x_rows[r, column] = factor * value
            low, high = compiled.parameters.x_bounds[column]
            slack = 1e-9 * max(1.0, high - low)
            if not allow_outside_limits and not low - slack <= factor * value <= high + slack:
                first, last = sorted((low / factor, high / factor))
                error(r, f"joint {name} = {value:g} is beyond its limits [{first:g}, {last:g}] "
                         "(the robot's, or the problem's bounds for it): the robot cannot have been there "
                         "(allow_outside_limits: true on the measurement accepts it)")
    return x_rows


def _constant(matrix: np.ndarray) -> LinkTransform:
    return LinkTransform(tuple(AffineParameter(0.0) for _ in range(6)), matrix)


def compile_measurement(compiled: CompiledProblem, index: int, measurement: Measurement) -> CompiledMeasurement:
    doc = compiled.problem.source
    loc = ("measurements", index)
    units = compiled.problem.units
    graph = compiled.graph
    entities = {entity.name: entity for entity in compiled.problem.entities}
    ends = {}  # frame or reference -> (graph frame, constant transform from it to the named frame)
    reference_moves: list = []  # how uncertain dimensions move the reference: (pose parameter, L column, coefficient)
    parameter_columns = {p.name: k for k, p in enumerate(compiled.parameters.l)}
    for key in ("frame", "reference"):
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
        elif key == "reference" and name.endswith(".top") and entities.get(name[:-4]) is not None \
                and entities[name[:-4]].type == "cylinder":
            cylinder = entities[name[:-4]]
            host, to_cylinder = entity_anchor(cylinder, units)
            to_top, reference_moves = cylinder_top(cylinder, parameter_columns)
            ends[key] = (host, to_cylinder @ to_top)
        else:
            raise doc.error(loc + (key,), f"unknown frame or entity '{name}' (a face's edge: FACE.edge[k]; a cylinder's end: CYLINDER.top)")
    measured = measurement.measured
    if measurement.data is not None:
        where = doc.relative_path(measurement.data)
        rows = _csv_rows(where, measured, sorted(joint_columns(compiled)))
    else:
        rows = [{"joints": row.joints, "values": row.values, "line": None} for row in measurement.rows]
        where = None
    if not rows:
        raise doc.error(loc, f"measurement '{measurement.name}' has no rows (give rows: or data:)")

    def row_error(r: int, problem: str):
        if where is not None:
            raise InputError(where, problem, rows[r]["line"])
        raise doc.error(loc + ("rows", r), problem)

    for r, row in enumerate(rows):
        if len(row["values"]) != len(measured):
            row_error(r, f"{len(row['values'])} values for the {len(measured)} measured parameters")
    x_rows = joint_rows(compiled, rows, row_error, measurement.allow_outside_limits)
    slots = [PARAMETERS.index(name) for name in measured]
    measured_values = np.array([row["values"] for row in rows], dtype=float)
    measured_values *= np.array([parameter_scale(name, units) for name in measured])
    noise = measurement.noise
    if getattr(noise, "dimension", 1) != 1:
        raise doc.error(loc + ("noise",), "the noise is a distribution of one parameter, applied to each measured one")
    mean, variance = noise.moments()
    scale = np.full(len(slots), math.sqrt(float(variance[0])))
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
        coordinates = SurfaceCoordinates(to_coordinates, nominal_radius(surface), parameter_columns.get(f"{surface.name}.radius"))
    first = []
    if reference_moves:
        # A face edge or a cylinder's top moved by uncertain dimensions: the chain from the
        # reference starts with the inverse of the move (:func:`bcad.compile.dimensions.face_edge`)
        moved = [tuple(Term("l", column, coefficient) for parameter, column, coefficient in reference_moves if parameter == k)
                 for k in range(6)]
        first = [(LinkTransform(tuple(AffineParameter(0.0, terms) for terms in moved)), True)]
    chain = Chain(first + [(_constant(np.linalg.inv(to_reference)), True)] + steps + [(_constant(to_frame), True)], coordinates)
    lines = [row["line"] for row in rows] if where is not None else None
    return CompiledMeasurement(measurement.name, chain, slots, x_rows, measured_values, scale, np.full(len(slots), float(mean[0])), lines)


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
            raise problem.source.error(("configurations",), "calibrate reads each measurement row's joint values as its "
                                       "configuration; remove configurations: (they are for solve and posterior)", key=True)
        self.measurements = []
        rows = 0
        for index, measurement in enumerate(problem.measurements):
            self.measurements.append(compile_measurement(compiled, index, measurement))
            rows += len(self.measurements[-1].x_rows)
            if rows > MAX_ROWS:  # the rows of all measurements together, read one file at a time
                raise problem.source.error(("measurements", index), f"the measurements hold more than {MAX_ROWS:,} rows "
                                           "together (a calibration from 100,000 rows takes about 40 s); use fewer rows")
        table = compiled.parameters
        joints = {column for column, _ in joint_columns(compiled).values()}
        self.x_columns = [k for k in range(len(table.x)) if k not in joints]
        self.names = [table.x[k].name for k in self.x_columns] + table.l_names
        self.kinds = ["X"] * len(self.x_columns) + ["L"] * len(table.l)
        n = len(self.names)
        if n > MAX_PARAMETERS or n * self.residual_count > MAX_JACOBIAN:
            raise problem.source.error(("measurements",), f"{n} parameters to identify from {self.residual_count} measured values: "
                                       f"at most {MAX_PARAMETERS} parameters and {MAX_JACOBIAN:,} parameters x values")

    def with_measurements(self, measurements: list[CompiledMeasurement]) -> "CalibrationModel":
        """The same model predicting other measurements (candidate configurations, say)."""
        other = copy.copy(self)
        other.measurements = measurements
        return other

    @property
    def residual_count(self) -> int:
        return sum(m.measured.size for m in self.measurements)

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
            samples = Samples(np.repeat(thetas[:, nx:], rows, axis=0))  # every vector for every row
            out.append(m.chain.evaluate(x, samples).poses()[:, m.slots].reshape(count, rows, -1))
        return out

    def residuals_batch(self, thetas: np.ndarray) -> np.ndarray:
        """(measured - predicted - noise mean) / noise std, stacked: (S, residual_count);
        evaluated CHUNK rows x vectors at a time."""
        thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
        rows = max(1, sum(len(m.x_rows) for m in self.measurements))
        step = max(1, CHUNK // rows)
        if len(thetas) <= step:
            return self._residuals_chunk(thetas)
        return np.concatenate([self._residuals_chunk(thetas[start : start + step]) for start in range(0, len(thetas), step)])

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

    @property
    def _angular_residuals(self) -> tuple[np.ndarray, np.ndarray]:
        """Which stacked residuals are angles, and their noise std (to wrap differences in radians)."""
        mask, scale = [], []
        for m in self.measurements:
            mask.append(np.tile(ANGULAR[m.slots], len(m.x_rows)))
            scale.append(np.tile(m.scale, len(m.x_rows)))
        mask, scale = np.concatenate(mask), np.concatenate(scale)
        return mask, scale[mask]
