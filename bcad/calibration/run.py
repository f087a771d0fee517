"""The calibration family's run: the joint MAP and its Laplace covariance from the problem's
measurements, the importance check, the proposals and predictions asked for, as the result
document (:class:`bcad.calibration.result.CalibrationResult`), checked against its model before
it leaves."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from bcad.arguments import COMMAND_LINE, MAX_SAMPLES, Spelling, file_path, random_seed, whole_number
from bcad.errors import InputError
from bcad.model.pose import PARAMETERS, parameter_unit

if TYPE_CHECKING:
    from bcad.compiler import CompiledProblem

#: the importance-sampling check's default size, and its budget: samples x measured values
#: (each sample predicts every measurement; 3e7 values take about 10 s on a 2-core machine)
DEFAULT_CHECK_SAMPLES, CHECK_VALUES = 1000, 30_000_000
#: a default check draws up to DEFAULT_CHECK_SAMPLES_MOST samples while they predict at most
#: DEFAULT_CHECK_VALUES values in all (about a second), DEFAULT_CHECK_SAMPLES at least: a heavy tail
#: shows in the largest weights only once enough samples reach it (a 3R arm's two zero errors of
#: prior std 1 rad seen by one tracker reading: k̂ -0.76 from 1000 samples, 1.29 from 4000, 2.6 from
#: 20,000), and a small file's samples cost little
DEFAULT_CHECK_SAMPLES_MOST, DEFAULT_CHECK_VALUES = 4000, 1_500_000
#: the fewest samples a check asked for may have: fewer cannot judge the Laplace answer (the Pareto
#: k of the largest weights needs a tail of them; 1 sample gave k nan and "far from Gaussian")
MIN_CHECK_SAMPLES = 100


#: the most candidates ``--propose`` may pick
MAX_PROPOSE = 100_000


@dataclass(frozen=True)
class CalibrateOptions:
    """A calibration's options, checked (the keywords of :func:`calibration_run`)."""

    robust: bool = False
    check_samples: int | None = None  # None: check_sample_count's default (1000..4000, fewer for a large file)
    seed: int = 0
    propose: int = 0
    candidates: Path | None = None
    predict: Path | None = None
    task: Path | None = None
    spelling: Spelling = COMMAND_LINE  # how the checks that need the problem name their option


def calibrate_options(
    *, robust, check_samples, seed, propose, candidates, predict, task, spelling: Spelling
) -> CalibrateOptions:
    """The options of ``bcad calibrate`` / ``bcad.calibrate``, each checked, and checked together:
    ``propose`` ranks ``candidates`` (each needs the other) and ``task`` directs ``propose``."""
    if not isinstance(robust, bool):
        raise spelling.error("robust", robust, "True or False")
    paths = {
        name: file_path(value, name, spelling)
        for name, value in zip(("candidates", "predict", "task"), (candidates, predict, task))
    }
    options = CalibrateOptions(
        robust=robust,
        check_samples=None
        if check_samples is None
        else whole_number(check_samples, "check_samples", spelling, 0, MAX_SAMPLES),
        seed=random_seed(seed, spelling),
        propose=whole_number(propose, "propose", spelling, 0, MAX_PROPOSE),
        **paths,
        spelling=spelling,
    )
    task_name = "for" if spelling.call is None else "task"
    if options.propose and options.candidates is None:
        raise InputError(spelling.where("propose"), f"needs {spelling.name('candidates')} (the configurations to rank)")
    if options.candidates is not None and not options.propose:
        raise InputError(spelling.where("candidates"), f"needs {spelling.name('propose')} (how many to pick)")
    if options.task is not None and not options.propose:
        raise InputError(
            spelling.where(task_name),
            f"directs {spelling.name('propose')}; give {spelling.name('propose')} and {spelling.name('candidates')}",
        )
    return options


def check_sample_count(model, requested: int | None, where, spelling: Spelling = COMMAND_LINE) -> int:
    """The check's samples: ``requested``, or where it is None DEFAULT_CHECK_VALUES / (measured
    values) within DEFAULT_CHECK_SAMPLES..DEFAULT_CHECK_SAMPLES_MOST; at most CHECK_VALUES /
    (measured values) (a default check of a large file is made smaller, and said in the result's
    check.samples; an explicit one over the budget is refused)."""
    values = max(1, model.residual_count)
    most = max(1, CHECK_VALUES // values)
    if requested is None:
        default = min(DEFAULT_CHECK_SAMPLES_MOST, max(DEFAULT_CHECK_SAMPLES, DEFAULT_CHECK_VALUES // values))
        return min(default, most)
    expected = None
    if 0 < requested < MIN_CHECK_SAMPLES:
        expected = f"0 (no check) or at least {MIN_CHECK_SAMPLES}; fewer samples cannot judge the Laplace answer"
    elif requested > most:
        expected = (
            f"at most {most:,} samples here (or 0: no check): the check predicts all {values:,} measured values "
            f"per sample, at most {CHECK_VALUES:.0e} values in all"
        )
    if expected is not None:
        if spelling.call is not None:
            raise spelling.error("check_samples", requested, expected)
        raise InputError(where, f"--check-samples {requested}: {expected}")
    return requested


def _plan_task(
    model, calibration, path: Path, plan_configuration: Callable
) -> tuple[np.ndarray, list[int], float, str]:
    """``--for PLAN.yaml``: the task Jacobian of a planning problem's closing links (what its
    relation or closing link scores: the error at the drilling point) at the plan's configuration
    (``plan_configuration(plan)``: the caller's, since solving a plan is another family's work);
    its rows' slots, the factor to the plan's units, and that unit's name."""
    from bcad.calibration.propose import plan_task_jacobian
    from bcad.compiler import compile_problem
    from bcad.compiler.units import pose_scales
    from bcad.model import load_problem

    plan = compile_problem(load_problem(path))
    if not plan.graph.cycles:
        raise InputError(path, "the plan has no cycle, so no closing link to direct --propose at")
    if plan.parameters.x and plan_configuration is None:
        raise ValueError("a task from a plan needs plan_configuration: the plan's X (bcad.api passes the nominal one)")
    x = plan_configuration(plan) if plan.parameters.x else np.zeros(0)
    rows, slots = plan_task_jacobian(model, calibration, plan, x)
    return rows, slots, float(pose_scales(plan)[min(slots)]), parameter_unit(PARAMETERS[min(slots)], plan.problem.units)


def calibration_run(
    compiled: CompiledProblem,
    *,
    robust: bool = False,
    check_samples: int | None = None,
    seed: int = 0,
    propose: int = 0,
    candidates: Path | None = None,
    urdf: bool = False,
    predict: Path | None = None,
    task: Path | None = None,
    plan_configuration: Callable | None = None,
    started: float | None = None,
    spelling: Spelling = COMMAND_LINE,
) -> tuple[dict, dict[str, str]]:
    """The result of ``bcad calibrate`` and, with ``urdf``, the calibrated robots' URDF texts;
    its ``seconds`` count from ``started`` (a ``time.perf_counter()``: the command's start, so
    that reading and compiling the problem count), or from this call."""
    from bcad.calibration.model import CalibrationModel
    from bcad.calibration.report import calibration_document
    from bcad.calibration.solve import calibrate as run_calibration

    start = time.perf_counter() if started is None else started
    model = CalibrationModel(compiled)
    check_samples = check_sample_count(model, check_samples, compiled.problem.source.path, spelling)
    calibration = run_calibration(compiled, model, robust=robust, check_samples=check_samples, seed=seed)
    proposals = None
    if propose:
        from bcad.calibration.propose import propose as rank_candidates

        if candidates is None:
            raise InputError(compiled.problem.source.path, "proposing configurations needs candidates (a CSV file)")
        task_rows = None
        unit = 1.0
        if task is not None:
            from bcad.compiler.units import pose_scales

            if Path(task).suffix.lower() in (".yaml", ".yml"):
                task_rows, slots, unit, task_unit = _plan_task(model, calibration, Path(task), plan_configuration)
            else:
                from bcad.calibration.propose import task_jacobian

                task_rows = task_jacobian(model, calibration, Path(task))
                kinds = {
                    "px" if m.camera is not None else "length" if slot < 3 else "angle"
                    for m in model.measurements
                    for slot in m.slots
                }
                if len(kinds) > 1:
                    raise InputError(
                        Path(task),
                        "--for needs readings of one kind (lengths, angles or pixels) to add their variances",
                    )
                slots = {int(slot) for m in model.measurements for slot in m.slots}
                unit = 1.0 if kinds == {"px"} else float(pose_scales(compiled)[min(slots)])
                task_unit = "px" if kinds == {"px"} else parameter_unit(PARAMETERS[min(slots)], compiled.problem.units)
            if len({bool(slot < 3) for slot in slots}) > 1:
                raise InputError(
                    Path(task), "--for needs readings of one kind (lengths or angles) to add their variances"
                )
        proposals = rank_candidates(model, calibration, Path(candidates), propose, task_rows, unit)
    document = calibration_document(compiled, model, calibration, time.perf_counter() - start)
    if proposals is not None:
        document["proposal"] = {
            "candidates": str(candidates),
            "criterion": "D-optimal (greedy)"
            if task is None
            else "the task's predicted variance (greedy A-optimal on the task)",
            "ranked": [
                {
                    "row": p.row,
                    "line": p.line,
                    "joints": p.joints,
                    "entropy_reduction": round(p.entropy_reduction, 6),
                    **({} if p.task_std is None else {"task_std": p.task_std}),
                }
                for p in proposals
            ],
        }
        if task is not None:
            document["proposal"]["task"] = str(task)
            document["proposal"]["task_unit"] = task_unit
        if len(proposals) < propose:
            document["proposal"]["note"] = (
                f"every candidate ranked: the file has {len(proposals)}, fewer than the {propose} asked"
            )
    if predict is not None:
        document["prediction"] = prediction_to_dict(compiled, model, calibration, Path(predict))
    texts: dict[str, str] = {}
    if urdf:
        from bcad.calibration.urdf import calibrated_urdfs

        if not compiled.problem.robots:
            raise InputError(compiled.problem.source.path, "the problem has no robot to write as URDF")
        estimate, _ = calibration.answer()
        nx = len(model.x_columns)
        x = np.array(compiled.parameters.x_nominal, dtype=float)
        x[model.x_columns] = estimate[:nx]
        texts = calibrated_urdfs(compiled, x, estimate[nx : nx + model.l_count])
    from bcad.calibration.result import CalibrationResult
    from bcad.model.results import checked

    return checked(document, CalibrationResult), texts


def prediction_to_dict(compiled: CompiledProblem, model, calibration, path: Path) -> dict:
    """``calibrate --predict C.csv``: the calibrated model's readings at new configurations, in the
    problem's units (:func:`bcad.calibration.propose.predict`)."""
    from bcad.calibration.propose import predict
    from bcad.compiler.units import pose_scales

    scales = pose_scales(compiled)
    slots = {m.name: m.slots for m in model.measurements}
    cameras = {m.name for m in model.measurements if m.camera is not None}
    rows = []
    for entry in predict(model, calibration, path):
        readings = {}
        for name, found in entry["measurements"].items():
            if name in cameras:  # every point of the target: its u and v (px)
                values, std = np.reshape(found["values"], (-1, 2)), np.reshape(found["std"], (-1, 2))
                # a point the camera would not see there (behind its lens, outside its image): no values
                readings[name] = {
                    "noise_std": float(found["noise_std"][0]),
                    "points": [
                        {
                            "point": i,
                            "seen": bool(seen),
                            "u": {
                                "value": float(values[i, 0]) if seen else None,
                                "std": float(std[i, 0]) if seen else None,
                            },
                            "v": {
                                "value": float(values[i, 1]) if seen else None,
                                "std": float(std[i, 1]) if seen else None,
                            },
                        }
                        for i, seen in enumerate(found["seen"])
                    ],
                }
                continue
            scale = scales[slots[name]]
            readings[name] = {
                PARAMETERS[slot]: {"value": float(v * s), "std": float(d * s), "noise_std": float(e * s)}
                for slot, v, d, e, s in zip(slots[name], found["values"], found["std"], found["noise_std"], scale)
            }
        rows.append({"row": entry["row"], "line": entry["line"], "joints": entry["joints"], "measurements": readings})
    return {
        "configurations": str(path),
        "model": "MAP, Laplace covariance propagated to first order (std); "
        "a new reading spreads by sqrt(std^2 + noise_std^2)",
        "rows": rows,
    }


def output_files(compiled: CompiledProblem, urdf: Path | None, camera_info: Path | None) -> dict[str, dict[str, Path]]:
    """The files ``--urdf`` and ``--camera-info`` write: one per robot (``urdf``) and per camera
    (``camera_info``), named after it where the problem has several."""
    from bcad.calibration.urdf import urdf_paths as paths_for

    files: dict[str, dict[str, Path]] = {"urdf": {}, "camera_info": {}}
    if urdf is not None:
        files["urdf"] = paths_for(urdf, [robot.name for robot in compiled.problem.robots])
    if camera_info is not None:
        if not compiled.problem.cameras:
            raise InputError("--camera-info", "the problem has no camera (cameras:) to write")
        files["camera_info"] = paths_for(camera_info, [camera.name for camera in compiled.problem.cameras], ".yaml")
    return files


def write_calibrated(document: dict, texts: dict[str, str], files: dict[str, dict[str, Path]], inputs) -> None:
    """Write the calibrated robots' URDFs and cameras' camera_info YAML to ``files``
    (:func:`output_files`) and record their paths in the document (``urdf``, ``camera_info``)."""
    from bcad.io import write_text_atomic
    from bcad.model.camera_info import CameraInfo, camera_info_text

    for name, path in files["urdf"].items():
        write_text_atomic(texts[name], path, inputs)
    for name, path in files["camera_info"].items():
        camera = document["cameras"][name]
        info = CameraInfo(*camera["image_size"], camera["distortion_model"], camera["values"], name)
        write_text_atomic(camera_info_text(info), path, inputs)
    for key in ("urdf", "camera_info"):
        if files[key]:
            document[key] = {name: str(path) for name, path in files[key].items()}
