"""Measurements compiled against the kinematic graph: rows, chains and predictions (issue 10).

Each measurement row is one configuration of the cell: the values of the
robots' X joints are set from the row, and every other parameter is shared
across rows. The parameters to identify are the problem's free parameters L
(zero offsets, base placements, tool mounts...): their distributions are the
priors of the calibration, and their posterior given the measurements is its
answer (the "L reading" of the issue; with Gaussian priors the MAP is the
posterior mean to first order). A measurement predicts the pose of its
``frame`` in its ``reference`` frame through the spanning tree, for every
row at once (one batched chain evaluation, the rows as samples).
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass

import numpy as np

from bcad.compile import CompiledProblem
from bcad.compile.units import parameter_scale
from bcad.errors import InputError
from bcad.kinematics.chain import Chain, Samples
from bcad.model.measurement import MAX_ROWS, Measurement
from bcad.model.pose import PARAMETERS
from bcad.model.source import read_text
from bcad.solvers.objective import ANGULAR, wrap_angle


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


def _joint_columns(compiled: CompiledProblem) -> dict[str, tuple[int, float]]:
    """ROBOT/JOINT -> (X column, factor from the joint's value in problem units to the X parameter)."""
    columns = {}
    for k, parameter in enumerate(compiled.parameters.x):
        link = compiled.graph.links[parameter.link]
        if link.joint is not None:
            name, sign, factor = link.joint
            columns[name] = (k, sign * factor)
    return columns


def _csv_rows(path, measured: list[str], doc, loc) -> list[dict]:
    """Rows of a CSV file: {"joints": {...}, "values": [...]} with their line numbers."""
    text = read_text(path, "a CSV file of measurements")
    reader = csv.reader(io.StringIO(text))
    try:
        header = [cell.strip() for cell in next(reader)]
    except StopIteration:
        raise InputError(path, "empty CSV file; expected a header naming the joints and the measured parameters", 1) from None
    missing = [name for name in measured if name not in header]
    if missing:
        raise InputError(path, f"the header lacks the measured parameter(s) {', '.join(missing)}", 1)
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
                raise InputError(path, f"'{cell}' in column {column} is not a number", line) from None
            if not (math.isfinite(values[column]) and abs(values[column]) <= 1e9):
                raise InputError(path, f"'{cell}' in column {column} is not a finite number of at most 1e9", line)
        rows.append({"joints": {c: v for c, v in values.items() if c not in PARAMETERS}, "values": [values[m] for m in measured], "line": line})
        if len(rows) > MAX_ROWS:
            raise InputError(path, f"more than {MAX_ROWS:,} rows", line)
    return rows


def compile_measurement(compiled: CompiledProblem, index: int, measurement: Measurement) -> CompiledMeasurement:
    doc = compiled.problem.source
    loc = ("measurements", index)
    units = compiled.problem.units
    graph = compiled.graph
    for key in ("frame", "reference"):
        if getattr(measurement, key) not in graph.frames:
            raise doc.error(loc + (key,), f"unknown frame '{getattr(measurement, key)}'")
    measured = measurement.measured
    if measurement.data is not None:
        rows = _csv_rows(doc.relative_path(measurement.data), measured, doc, loc)
        where = doc.relative_path(measurement.data)
    else:
        rows = [{"joints": row.joints, "values": row.values, "line": None} for row in measurement.rows]
        where = None
    if not rows:
        raise doc.error(loc, f"measurement '{measurement.name}' has no rows (give rows: or data:)")
    joints = _joint_columns(compiled)
    table = compiled.parameters
    not_joints = [table.x[k].name for k in range(len(table.x)) if k not in {c for c, _ in joints.values()}]
    if not_joints:
        raise doc.error(loc, f"calibration sets every X from the rows, but {', '.join(not_joints)} is no robot joint")
    x_rows = np.zeros((len(rows), len(table.x)))
    for r, row in enumerate(rows):
        given = set(row["joints"])
        unknown = sorted(given - set(joints))
        missing = sorted(set(joints) - given)
        if unknown or missing or len(row["values"]) != len(measured):
            problem = (f"unknown joint(s) {', '.join(unknown)}" if unknown else f"no value for joint(s) {', '.join(missing)}"
                       if missing else f"{len(row['values'])} values for the {len(measured)} measured parameters")
            if where is not None:
                raise InputError(where, problem, row["line"])
            raise doc.error(loc + ("rows", r), problem)
        for name, value in row["joints"].items():
            column, factor = joints[name]
            x_rows[r, column] = factor * value
    slots = [PARAMETERS.index(name) for name in measured]
    measured_values = np.array([row["values"] for row in rows], dtype=float)
    measured_values *= np.array([parameter_scale(name, units) for name in measured])
    noise = measurement.noise
    if getattr(noise, "dimension", 1) != 1:
        raise doc.error(loc + ("noise",), "the noise is a distribution of one parameter, applied to each measured one")
    mean, variance = noise.moments()
    scale = np.full(len(slots), math.sqrt(float(variance[0])))
    chain = Chain([(compiled.transforms[i], forward) for i, forward in graph.tree_path(measurement.reference, measurement.frame)])
    return CompiledMeasurement(measurement.name, chain, slots, x_rows, measured_values, scale, np.full(len(slots), float(mean[0])))


class CalibrationModel:
    """Whitened residuals of every measurement as a function of the free parameters L."""

    def __init__(self, compiled: CompiledProblem):
        self.compiled = compiled
        problem = compiled.problem
        if not problem.measurements:
            raise problem.source.error((), "the problem has no measurements: section to calibrate from")
        self.measurements = [compile_measurement(compiled, i, m) for i, m in enumerate(problem.measurements)]
        self.names = compiled.parameters.l_names

    @property
    def residual_count(self) -> int:
        return sum(m.measured.size for m in self.measurements)

    def predictions(self, theta: np.ndarray) -> list[np.ndarray]:
        """Predicted measured values (rows, k) of each measurement for L = theta (nL,)."""
        out = []
        for m in self.measurements:
            samples = Samples(np.repeat(np.asarray(theta, dtype=float)[None], len(m.x_rows), axis=0))
            out.append(m.chain.evaluate(m.x_rows, samples).poses()[:, m.slots])
        return out

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        """(measured - predicted - noise mean) / noise std for every row and parameter, stacked."""
        parts = []
        for m, predicted in zip(self.measurements, self.predictions(theta)):
            difference = m.measured - predicted
            angular = ANGULAR[m.slots]
            difference[:, angular] = wrap_angle(difference[:, angular])
            parts.append(((difference - m.mean) / m.scale).ravel())
        return np.concatenate(parts)

    def jacobian(self, theta: np.ndarray, steps: np.ndarray) -> np.ndarray:
        """d residuals / d theta by central differences (one batched evaluation per measurement)."""
        theta = np.asarray(theta, dtype=float)
        n = len(theta)
        blocks = []
        for m in self.measurements:
            rows = len(m.x_rows)
            points = np.repeat(theta[None], 1 + 2 * n, axis=0)
            points[1 : n + 1] += np.diag(steps)
            points[n + 1 :] -= np.diag(steps)
            samples = Samples(np.repeat(points, rows, axis=0))  # every point for every row
            x = np.tile(m.x_rows, (1 + 2 * n, 1))
            poses = m.chain.evaluate(x, samples).poses()[:, m.slots].reshape(1 + 2 * n, rows, -1)
            difference = poses[1 : n + 1] - poses[n + 1 :]
            angular = ANGULAR[m.slots]
            difference[..., angular] = wrap_angle(difference[..., angular])
            derivative = difference / (2.0 * steps[:, None, None])  # (n, rows, k): d predicted / d theta
            blocks.append(-(derivative / m.scale).reshape(n, -1).T)
        return np.vstack(blocks)
