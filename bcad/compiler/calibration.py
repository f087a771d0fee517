"""Measure, then plan: a calibration result as the prior of a planning problem's L.

``calibration: [RESULT.json, ...]`` in a problem (or ``--calibration FILE`` on solve and
posterior): every parameter that a result of ``bcad calibrate`` names and that is L in this
problem takes the result's joint posterior instead of its own distribution, correlations kept:
the multivariate normal of the result's Laplace approximation, mean the MAP (``map``; less this
problem's nominal value for a parameter that was X there, whose MAP is a value, not a deviation) and
covariance D R D with D the ``laplace_std`` and R the ``correlation`` matrix (parameters the
matrix does not list are independent of the others). That is the calibrated model itself:
the result's ``estimate`` and ``std`` are the same MAP and Laplace std. Values
are converted from the result's units to the problem's. A parameter the result names but this
problem does not have as L is listed in :attr:`CalibrationPrior.not_applied`; names must match
(``ur5/wrist_3_joint/zero.rz``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bcad.compiler.parameters import DistributionGroup, ParameterTable
from bcad.compiler.units import METRES_PER_UNIT, RADIANS_PER_UNIT
from bcad.errors import InputError, quoted
from bcad.kinematics.chain import Samples
from bcad.model.distributions import HUGE, TINY, MultivariateNormal
from bcad.model.pose import CAMERA_NAMES, LENGTH_NAMES, first_unnamed
from bcad.model.problem import Problem
from bcad.model.source import JsonDocument, path_shown, read_json

#: parameters one result may carry (a full-DH UR5 has 35)
MAX_PARAMETERS = 2000


@dataclass
class CalibrationPrior:
    """What the calibration results changed in a problem."""

    files: list[str] = field(default_factory=list)
    #: per file, the L parameters that took its posterior
    applied: dict[str, list[str]] = field(default_factory=dict)
    #: per file, the parameters it names that are not L here (left as the problem has them)
    not_applied: dict[str, list[str]] = field(default_factory=dict)


def _number(source: JsonDocument, loc: tuple, what: str) -> float:
    """The number at ``loc`` (a missing key is None, refused as not a number)."""
    value = source.data
    for step in loc:
        value = value.get(step) if isinstance(value, dict) else value[step]
    # an integer of 400 digits is too large too (abs() first: float() of it overflows)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not abs(value) <= 1e12:
        raise source.error(
            loc, f"{what} is {repr(value)[:40]}, expected a finite number of at most 1e12 (a bcad calibrate result)"
        )
    return float(value)


def read_posterior(path: Path, problem: Problem) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """The names, MAP (in the problem's internal units), covariance of a calibration result, and
    which of its parameters were X there (their MAP is a value; an L's is a deviation from nominal)."""
    source = read_json(path, "a calibration result (the JSON of bcad calibrate)", "a bcad calibrate result")
    document = source.data
    if not isinstance(document, dict) or not isinstance(document.get("parameters"), dict):
        raise InputError(path, "has no 'parameters' mapping; expected the JSON that bcad calibrate writes")
    if document.get("kind", "calibrate") != "calibrate":
        raise source.error(
            ("kind",),
            f"is a result of kind {quoted(document['kind'], 40)}; expected the JSON that bcad calibrate writes "
            "(kind: calibrate)",
        )
    parameters = document["parameters"]
    if not parameters:
        raise source.error(("parameters",), "names no parameters; expected the JSON that bcad calibrate writes")
    if len(parameters) > MAX_PARAMETERS:
        raise source.error(("parameters",), f"names {len(parameters)} parameters; at most {MAX_PARAMETERS}")
    names = list(parameters)
    unnamed = first_unnamed(names)
    if unnamed is not None:
        # no byte of a file that is not a calibration result is quoted
        raise source.error(
            ("parameters",),
            f"entry {unnamed} of 'parameters' is not named LINK.PARAMETER "
            "(ur5/base.tx, ur5/joint_2/zero.rz); expected the JSON that bcad calibrate writes",
        )
    units = document.get("units") or {}
    length, angle = (units.get("length", "m"), units.get("angle", "rad")) if isinstance(units, dict) else (None, None)
    if (
        not isinstance(length, str)
        or not isinstance(angle, str)
        or length not in METRES_PER_UNIT
        or angle not in RADIANS_PER_UNIT
    ):
        raise source.error(
            ("units",),
            f"units {quoted(units, 60)}: expected a length in {', '.join(METRES_PER_UNIT)} and an angle in rad or deg",
        )
    to_length = METRES_PER_UNIT[length] / METRES_PER_UNIT[problem.units.length]
    to_angle = RADIANS_PER_UNIT[angle]
    mean, std = np.empty(len(names)), np.empty(len(names))
    absolute = np.array(
        [isinstance(parameters[name], dict) and parameters[name].get("kind") == "X" for name in names], bool
    )
    for k, name in enumerate(names):
        entry = parameters[name]
        if not isinstance(entry, dict):
            raise source.error(
                ("parameters", name), f"parameter {quoted(name, 60)}: expected a mapping with its map and laplace_std"
            )
        parameter = name.rsplit(".", 1)[1]
        scale = to_length if parameter in LENGTH_NAMES else 1.0 if parameter in CAMERA_NAMES else to_angle
        given = "map" if "map" in entry or "estimate" not in entry else "estimate"
        mean[k] = scale * _number(source, ("parameters", name, given), f"the map of {quoted(name, 60)}")
        given = "laplace_std" if "laplace_std" in entry or "std" not in entry else "std"
        spread = _number(source, ("parameters", name, given), f"the laplace_std of {quoted(name, 60)}")
        std[k] = scale * spread
        if not TINY <= std[k] <= HUGE:  # a distribution's bounds (bcad.model.distributions)
            raise source.error(
                ("parameters", name, given),
                f"the laplace_std of {quoted(name, 60)} is {spread!r}, expected a positive number "
                f"that is in [{TINY:g}, {HUGE:g}] in the problem's units",
            )
    correlation = np.eye(len(names))
    block = document.get("correlation")
    if block is None and len(names) > 1:
        # calibrate always writes it: without it the parameters would be taken as independent, and
        # their correlations (0.99 on the UR5 example) are what makes a calibrated cell precise
        raise InputError(
            path,
            f"names {len(names)} parameters and no 'correlation'; expected the JSON that bcad calibrate writes, "
            "whose correlation matrix the posterior needs",
        )
    if block is not None:
        listed = block.get("names") if isinstance(block, dict) else None
        matrix = block.get("matrix") if isinstance(block, dict) else None
        if (
            not isinstance(listed, list)
            or not isinstance(matrix, list)
            or len(matrix) != len(listed)
            or any(not isinstance(row, list) or len(row) != len(listed) for row in matrix)
        ):
            raise source.error(("correlation",), "'correlation' needs 'names' and a square 'matrix' of as many rows")
        index = {name: k for k, name in enumerate(names)}
        unknown = [name for name in listed if name not in index]
        if unknown:
            raise source.error(
                ("correlation", "names", listed.index(unknown[0])),
                f"the correlation names {', '.join(quoted(name, 60) for name in unknown[:5])}, which "
                "'parameters' does not",
            )
        positions = [index[name] for name in listed]
        values = np.array(
            [
                [_number(source, ("correlation", "matrix", i, j), "a correlation") for j in range(len(row))]
                for i, row in enumerate(matrix)
            ]
        )
        if np.max(np.abs(values - values.T), initial=0.0) > 1e-9 or np.max(np.abs(values), initial=0.0) > 1.0 + 1e-9:
            raise source.error(
                ("correlation", "matrix"), "the correlation matrix is not symmetric with entries in [-1, 1]"
            )
        correlation[np.ix_(positions, positions)] = values
        np.fill_diagonal(correlation, 1.0)
    if np.min(np.linalg.eigvalsh(correlation)) < -1e-8:
        raise source.error(
            ("correlation", "matrix"), "the correlation matrix is not positive semidefinite: not a posterior covariance"
        )
    return names, mean, correlation * np.outer(std, std), absolute


def apply_calibrations(table: ParameterTable, problem: Problem, nominal: np.ndarray) -> CalibrationPrior:
    """Replace the distributions of the L that the problem's calibration results name by the
    results' joint posteriors (module docstring), in place; what was applied and what not.
    ``nominal``: each L's nominal value (internal units): a parameter that was X in the
    calibration (a robot's base, say) has its MAP as a value, and an L here deviates from this
    problem's nominal, so its mean is the MAP less that."""
    found = CalibrationPrior()
    columns = {parameter.name: k for k, parameter in enumerate(table.l)}
    taken: dict[int, tuple[int, Path]] = {}  # column -> (the entry, its file) that calibrates it
    marks = getattr(problem.source, "value_marks", {})

    def refused(entries: tuple[int, ...], path: Path, message: str) -> InputError:
        # at the first of ``entries`` (the one at fault first) that the problem writes
        # (``--calibration`` adds entries that it does not), else at the result file itself
        written = [index for index in entries if ("calibration", index) in marks]
        return problem.source.error(("calibration", written[0]), message) if written else InputError(path, message)

    for index, text in enumerate(problem.calibration):
        path = problem.source.named_file(("calibration", index), text, "a bcad calibrate result", "calibration result ")
        names, mean, covariance, absolute = read_posterior(path, problem)
        chosen = [k for k, name in enumerate(names) if name in columns]
        found.files.append(str(path))
        found.applied[str(path)] = [names[k] for k in chosen]
        found.not_applied[str(path)] = [name for name in names if name not in columns]
        if not chosen:
            continue
        targets = [columns[names[k]] for k in chosen]
        mean = mean.copy()
        for column, k in zip(targets, chosen):
            if absolute[k]:
                mean[k] -= nominal[column]
        for column, k in zip(targets, chosen):
            if column in taken:
                first, other = taken[column]
                given = (
                    f"{path_shown(str(path))} is given twice"
                    if Path(other).resolve() == Path(path).resolve()
                    else f"'{names[k]}' is calibrated by both {path_shown(str(other))} and {path_shown(str(path))}"
                )
                raise refused((index, first), path, f"{given}; give each parameter one result")
            taken[column] = (index, path)
        replaced = set(targets)
        kept = []
        for group in table.l_groups:
            covered = replaced & set(group.columns)
            if covered and covered != set(group.columns):
                split = ", ".join(table.l[c].name for c in group.columns)
                raise refused(
                    (index,),
                    path,
                    f"{path_shown(str(path))} calibrates part of the joint distribution of {split}; it must name "
                    "all of them or none",
                )
            if not covered:
                kept.append(group)
        table.l_groups = kept + [
            DistributionGroup(MultivariateNormal(mean[chosen], covariance[np.ix_(chosen, chosen)]), tuple(targets))
        ]
    return found


def nominal_deviations(compiled) -> np.ndarray:
    """Every L's nominal deviation (len(parameters.l),): 0 (the file's pose), but a calibrated L's
    is its calibration's MAP, the robot as it was measured to be: what the nominal answer, which
    ignores uncertainty, takes the robot to be."""
    table = compiled.parameters
    calibrated = {name for names in compiled.calibration.applied.values() for name in names}
    deviations = np.zeros(len(table.l))
    for group in table.l_groups:
        columns = list(group.columns)
        if any(table.l[c].name in calibrated for c in columns):
            deviations[columns] = group.distribution.moments()[0]
    return deviations


def nominal_samples(compiled) -> Samples:
    """One sample of every L at its nominal deviation (:func:`nominal_deviations`): the robot as the
    nominal answer, a solve's reach diagnostics and the arm pictures take it."""
    return Samples(nominal_deviations(compiled)[None])
