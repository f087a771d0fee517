"""Which configurations to measure next: greedy D-optimal selection.

A candidate configuration c measured by every measurement of the problem
adds the whitened Jacobian rows J_c (d predicted / d z at the estimate, z the
whitened parameters) to the posterior information A = Sigma_z^-1. D-optimal
design maximises det A: adding c multiplies it by det(I + J_c A^-1 J_c^T),
and the posterior entropy falls by half the log of that. The greedy choice
takes the candidate of largest gain, adds its rows to A, and repeats K times
(the greedy D-optimal design is within (1 - 1/e) of the best set, as log det
is submodular on information sums).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bcad.calibration.model import CalibrationModel, joint_columns, joint_rows, read_csv_table
from bcad.calibration.solve import STEP, Calibration
from bcad.errors import InputError


@dataclass
class Proposal:
    row: int  # 1-based candidate row
    line: int  # its line in the candidates file
    joints: dict[str, float]  # as written in the file
    entropy_reduction: float  # nats: 1/2 log det(I + J_c A^-1 J_c^T) when it is added
    #: with a task (--for): the task's predicted std (RMS over its readings, problem units) once it is added
    task_std: float | None = None


def read_candidates(model: CalibrationModel, path: Path) -> tuple[list[tuple[int, dict[str, float]]], np.ndarray]:
    """The candidates' rows (line, joints) and their X (C, nX)."""
    _, table = read_csv_table(
        path, "a CSV file of configurations, a column per joint", sorted(joint_columns(model.compiled))
    )
    if not table:
        raise InputError(
            path, "a header and no rows; expected one configuration per row under the header, a column per joint", 2, 1
        )
    rows = [{"joints": row.values, "line": row.line} for row in table]

    def error(r: int, problem: str, joint: str | None = None):
        raise table[r].error(path, problem, joint)

    def header_error(problem: str, joint: str):
        raise table[0].header_error(path, problem, joint)

    x_rows = joint_rows(model.compiled, rows, error, header_error=header_error, measured=False)
    return [(row.line, row.values) for row in table], x_rows


#: candidates' predicted values x parameters (their Jacobian), and candidates x values^2 (their
#: information matrices), at most: about 160 MB and 400 MB
CANDIDATE_JACOBIAN = 20_000_000
CANDIDATE_SPREAD = 50_000_000


def check_candidate_work(model: CalibrationModel, x_rows: np.ndarray, path: Path) -> None:
    """Refuse (exit 2) candidates whose Jacobians would not fit: a camera reads every point of its
    target at each, so a candidate costs points x 2 rows."""
    values = sum(m.per_configuration * len(m.slots) for m in model.measurements)
    if len(x_rows) * values * len(model.names) > CANDIDATE_JACOBIAN or len(x_rows) * values**2 > CANDIDATE_SPREAD:
        most = max(1, min(CANDIDATE_JACOBIAN // (values * len(model.names)), CANDIDATE_SPREAD // values**2))
        raise InputError(
            path,
            f"{len(x_rows):,} configurations of {values:,} predicted values each ({len(model.names)} "
            f"parameters): at most {most:,} at once (their Jacobians are kept in memory)",
        )


def _candidate_jacobians(model: CalibrationModel, theta: np.ndarray, std: np.ndarray, x_rows: np.ndarray) -> np.ndarray:
    """(C, K, n): d (whitened prediction of every measurement) / d z at each candidate. A camera
    reads every point of its target that it would see there (in front of the lens, inside the
    image, at the estimate); the others add no row (zeros)."""
    blocks = []
    for m in model.measurements:
        probe = model.with_measurements([m.at_configurations(x_rows)])
        J = probe.jacobian(theta, STEP * std) * std  # (C P k, n), of the residuals: -predicted
        seen = probe.visible(theta[None])[0]
        J = J.reshape(len(seen), len(m.slots), -1) * seen[:, None, None]
        blocks.append(J.reshape(len(x_rows), m.per_configuration * len(m.slots), -1))
    return np.concatenate(blocks, axis=1)


def task_jacobian(model: CalibrationModel, calibration: Calibration, path: Path) -> np.ndarray:
    """(T, n): d (reading, in internal units) / d z of every measurement's readings at each task
    configuration of a CSV file, stacked."""
    _, x_rows = read_candidates(model, path)
    check_candidate_work(model, x_rows, path)
    std = calibration.priors.std
    J = _candidate_jacobians(model, calibration.estimate, std, x_rows)  # whitened by the noise
    scale = np.concatenate([np.tile(m.scale, m.per_configuration) for m in model.measurements])
    return (J * scale[None, :, None]).reshape(-1, J.shape[2])


def plan_task_jacobian(
    model: CalibrationModel, calibration: Calibration, plan, x: np.ndarray
) -> tuple[np.ndarray, list[int]]:
    """(T, n): d (each scored parameter of a planning problem's closing links, internal units) /
    d z, at the plan's X (``x``: its configuration) and its L at their means, and the slots
    (tx ... rz) of those rows. The plan's L are matched to the calibrated parameters by name,
    as its ``calibration:`` applies them (a calibrated X, such as the base, is an L deviating
    from the plan's nominal: the same derivative); a calibrated parameter the plan lacks moves
    nothing there (a zero column). Central differences of STEP prior std, as the candidates'."""
    from bcad.compiler.parameters import free_parameter_moments
    from bcad.kinematics.chain import Samples
    from bcad.kinematics.se3 import wrap_angle
    from bcad.model.pose import PARAMETERS

    mean, _ = free_parameter_moments(plan)
    column_of = {name: k for k, name in enumerate(plan.parameters.l_names)}
    matched = [(j, column_of[name]) for j, name in enumerate(model.names) if name in column_of]
    where = plan.problem.source.path
    if not matched:
        raise InputError(
            where,
            "names none of the calibrated parameters as L, so no measurement can change its "
            "closing links' spread (name them as the calibration does: ur5/joint_2/zero.rz ...)",
        )
    std = calibration.priors.std
    calibrated = [j for j, _ in matched]
    steps = STEP * std[calibrated]
    points = np.repeat(mean[None], 1 + 2 * len(matched), axis=0)
    for i, (_, k) in enumerate(matched):
        points[1 + 2 * i, k] += steps[i]
        points[2 + 2 * i, k] -= steps[i]
    batch = Samples(points)
    rows, slots = [], []
    for cycle, chain in zip(plan.graph.cycles, plan.cycle_chains):
        link = plan.graph.links[cycle.closing_link]
        poses = chain.evaluate(x, batch).poses()  # (1 + 2 m, 6)
        for names in link.distributions:
            for name in names:
                slot = PARAMETERS.index(name)
                change = poses[1::2, slot] - poses[2::2, slot]
                if slot >= 3:
                    change = wrap_angle(change)
                row = np.zeros(len(model.names))
                row[calibrated] = change / (2.0 * steps) * std[calibrated]
                rows.append(row)
                slots.append(slot)
    if not rows:
        raise InputError(
            where, "its closing links score no parameter (a distribution on tx ... rz): nothing for --for to reduce"
        )
    return np.array(rows), slots


#: picks x candidates that --propose scores, at most (1e7: about 15 s on a 2-core machine)
PROPOSE_WORK = 10_000_000


def propose(
    model: CalibrationModel,
    calibration: Calibration,
    path: Path,
    count: int,
    task: np.ndarray | None = None,
    unit: float = 1.0,
) -> list[Proposal]:
    """The ``count`` candidates to measure next, greedily: D-optimal (the largest entropy
    reduction, module docstring), or, with a ``task`` Jacobian (:func:`task_jacobian`), those
    that most reduce the task's predicted variance, trace(J_t A^-1 J_t^T) after the candidate's
    rows are added to A (A-optimality on the task: the error at the points that matter, not the
    volume of the whole posterior). ``unit`` converts the task's std to the problem's units."""
    table, x_rows = read_candidates(model, path)
    check_candidate_work(model, x_rows, path)
    picks = min(count, len(x_rows))
    if picks * len(x_rows) > PROPOSE_WORK:
        raise InputError(
            path,
            f"--propose {count} from {len(x_rows):,} candidates: each pick scores every candidate, at "
            f"most {PROPOSE_WORK:.0e} picks x candidates in all, so at most "
            f"{max(1, PROPOSE_WORK // len(x_rows)):,} picks from this file (or fewer candidates)",
        )
    std = calibration.priors.std
    J = _candidate_jacobians(model, calibration.estimate, std, x_rows)
    covariance_z = calibration.covariance / np.outer(std, std)
    information = np.linalg.inv(covariance_z)
    chosen: list[Proposal] = []
    remaining = np.ones(len(x_rows), dtype=bool)
    eye = np.eye(J.shape[1])
    # Per candidate c: J_c A^-1 (C, k, p), M_c = J_c A^-1 J_c^T (C, k, k) and, for a task,
    # T_c = J_c A^-1 J_t^T (C, k, t); after each pick b they are updated by Woodbury
    # (A'^-1 = A^-1 - A^-1 J_b^T G_b^-1 J_b A^-1, G_b = I + M_b) in O(C k^2 p), not recomputed
    # from A^-1 in O(C k p^2).
    projected = np.einsum("cki,ij->ckj", J, np.linalg.inv(information))
    spread = np.einsum("ckj,clj->ckl", projected, J)
    cross = None if task is None else np.einsum("ckj,tj->ckt", projected, task)
    for _ in range(min(count, len(x_rows))):
        gain_matrix = eye + spread
        _, logdet = np.linalg.slogdet(gain_matrix)
        if task is None:
            score = np.where(remaining, logdet, -np.inf)
        else:
            # Woodbury: A'^-1 = A^-1 - A^-1 J_c^T (I + J_c A^-1 J_c^T)^-1 J_c A^-1, so the task's
            # variance falls by trace(T_c^T (I + J_c A^-1 J_c^T)^-1 T_c), T_c = J_c A^-1 J_t^T.
            drop = np.einsum("ckt,ckt->c", cross, np.linalg.solve(gain_matrix, cross))
            score = np.where(remaining, drop, -np.inf)
        best = int(np.argmax(score))
        remaining[best] = False
        information = information + J[best].T @ J[best]
        pair = np.einsum("ckj,lj->ckl", projected, J[best])  # J_c A^-1 J_b^T
        weight = pair @ np.linalg.inv(gain_matrix[best])  # (C, k, k)
        spread = spread - weight @ np.swapaxes(pair, 1, 2)
        if cross is not None:
            cross = cross - weight @ cross[best]
        projected = projected - weight @ projected[best]
        line, joints = table[best]
        task_std = None
        if task is not None:
            after = np.linalg.inv(information)
            task_std = float(np.sqrt(np.mean(np.einsum("ti,ij,tj->t", task, after, task)))) * unit
        chosen.append(Proposal(best + 1, line, joints, 0.5 * float(logdet[best]), task_std))
    return chosen


def predict(model: CalibrationModel, calibration: Calibration, path: Path) -> list[dict]:
    """The calibrated model's prediction of every measurement at each configuration of a CSV file
    (a column per joint): per row and measurement, the measured parameters' values at the MAP and
    their std, the Laplace covariance propagated through the measurement's Jacobian
    (sqrt diag J Sigma J^T). The sensor's noise is not in it: a new reading spreads by
    sqrt(std^2 + noise std^2) about the prediction. ``seen``: per reading, whether the sensor sees
    it there (a camera's point in front of its lens and inside its image)."""
    table, x_rows = read_candidates(model, path)
    check_candidate_work(model, x_rows, path)
    theta, std = calibration.estimate, calibration.priors.std
    covariance_z = calibration.covariance / np.outer(std, std)
    out = [{"row": r + 1, "line": line, "joints": joints, "measurements": {}} for r, (line, joints) in enumerate(table)]
    for m in model.measurements:
        probe = model.with_measurements([m.at_configurations(x_rows)])
        k, per = len(m.slots), m.per_configuration
        values = probe.predictions(theta[None])[0][0].reshape(len(x_rows), per * k)  # a camera: u, v of each point
        J = (probe.jacobian(theta, STEP * std) * std).reshape(len(x_rows), per * k, -1) * np.tile(m.scale, per)[
            None, :, None
        ]
        spread = np.sqrt(np.maximum(np.einsum("rki,ij,rkj->rk", J, covariance_z, J), 0.0))
        seen = probe.visible(theta[None])[0].reshape(len(x_rows), per)  # a camera's points in its image
        for r in range(len(x_rows)):
            out[r]["measurements"][m.name] = {
                "values": values[r],
                "std": spread[r],
                "noise_std": m.scale,
                "seen": seen[r],
            }
    return out
