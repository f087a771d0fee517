"""The result of ``bcad calibrate``: JSON and its table, in the problem's units."""

from __future__ import annotations

import math

import numpy as np
from rich.table import Table
from rich.text import Text

from bcad.calibration.check import MAX_PARETO_K as CHECK_MAX_PARETO_K
from bcad.calibration.check import MIN_ESS as CHECK_MIN_ESS
from bcad.calibration.model import CalibrationModel
from bcad.calibration.solve import Calibration
from bcad.compiler import CompiledProblem
from bcad.compiler.robots import dh_error_slots
from bcad.compiler.units import pose_scales
from bcad.errors import printable
from bcad.kinematics.camera import camera_parameters
from bcad.model.pose import LENGTH_NAMES
from bcad.model.results import SCHEMA_VERSION
from bcad.tables import WholeTable
from bcad.version import __version__

#: whitened RMS residual after calibration above which the model does not explain the data
MISFIT = 3.0
#: ... or whose chi-square (the whitened residuals' sum of squares) a model that explains the data
#: at their stated noise exceeds with a probability below this (on as many degrees of freedom as
#: residuals, more than the fit leaves: the test errs towards silence). On 90 tracker values whose
#: noise was understated 2.5 times the RMS was 1.9-2.4, below MISFIT, and the stds 2.4 times too small
MISFIT_PROBABILITY = 1e-3
#: the standard normal's upper MISFIT_PROBABILITY quantile
MISFIT_QUANTILE = 3.090232306167813
#: ... where the RMS is above this too: on thousands of values the test alone would call a noise
#: stated 5 % too small a misfit (the bound's RMS is 1.04 on 3000 values), where the stds are 5 %
#: too small; from 1.1 on they are off by more than a tenth
MISFIT_RMS_FLOOR = 1.1


def chi_square_bound(degrees: int) -> float:
    """The chi-square's upper MISFIT_PROBABILITY quantile on ``degrees`` degrees of freedom (at least
    one: with no residual the RMS, not a number, is the misfit already), by
    Wilson and Hilferty's cube-root normal approximation (k (1 - 2/(9k) + z sqrt(2/(9k)))^3), which
    errs high by at most 3 % (at k = 1: 11.2 for 10.8) and by under 1 % from k = 10 on."""
    k = max(int(degrees), 1)
    return k * (1.0 - 2.0 / (9.0 * k) + MISFIT_QUANTILE * np.sqrt(2.0 / (9.0 * k))) ** 3


def _residual_summary(model: CalibrationModel, compiled: CompiledProblem, whitened: np.ndarray) -> dict:
    units = pose_scales(compiled)
    summary = {}
    for m, block in zip(model.measurements, model.residual_blocks(whitened)):
        entry = {}
        for k, (slot, label) in enumerate(zip(m.slots, m.labels)):
            values = block[:, k] * (units[slot] if m.camera is None else 1.0)  # pixels as they are
            entry[label] = {
                "mean": float(values.mean()),
                "rms": float(np.sqrt(np.mean(values**2))),
                "max": float(np.abs(values).max()),
            }
        summary[m.name] = entry
    return summary


def _dh_meaning(compiled: CompiledProblem) -> dict[str, str]:
    """Parameter names of DH robots' errors -> the DH parameter they perturb (``ur5/joint_2 a``)."""
    meaning = {}
    for robot in compiled.problem.robots:
        if robot.dh is None:
            continue
        for i, row in enumerate(robot.dh):
            joint = f"{robot.name}/{row.name or f'joint_{i + 1}'}"
            for link, slots in dh_error_slots(row.type == "revolute", robot.convention).items():
                meaning.update({f"{joint}/{link}.{parameter}": source for parameter, source in slots.items()})
    return meaning


def _camera_parameters_not_identified(compiled: CompiledProblem, cal: Calibration) -> list[str]:
    """The cameras' own parameters and their mount links' that the data leave unidentified (a
    degenerate set of views): a camera calibration is asked for exactly those."""
    prefixes = []
    for camera in compiled.problem.cameras:
        prefixes.append(f"{camera.name}.")
        prefixes += [f"{link.name}." for link in compiled.graph.links if camera.frame in (link.parent, link.child)]
    return [name for k, name in enumerate(cal.names) if not cal.identified[k] and name.startswith(tuple(prefixes))]


#: a robust fit that calls more than this share of the rows outliers has broken down
BREAKDOWN = 0.5


def calibration_document(compiled: CompiledProblem, model: CalibrationModel, cal: Calibration, seconds: float) -> dict:
    scale = model.output_scales()
    # With the robust loss, the outliers it reports do not count against the fit.
    kept = cal.residuals_after if cal.inliers is None else cal.residuals_after[cal.inliers]
    warnings = []
    if not kept.size:
        # Every row an outlier: the robust loss has nothing it trusts, and the fit is as
        # good as the measurements' agreement; measured over every row, and said.
        warnings.append(
            {
                "code": "all_outliers",
                "message": "the robust loss finds every measurement row an outlier: no row agrees with the model, "
                "and the calibration cannot be trusted (check the data's units, columns and frames)",
            }
        )
        kept = cal.residuals_after
    elif cal.row_weights is not None and len(cal.outliers) > BREAKDOWN * len(cal.row_weights):
        # A robust fit that calls most rows outliers has followed the few: Huber's loss cannot tell
        # that from an answer the bulk of the data agree on, and the misfit below counts inliers only.
        warnings.append(
            {
                "code": "robust_breakdown",
                "message": f"the robust loss finds {len(cal.outliers)} of {len(cal.row_weights)} measurement rows "
                "outliers: more than half of the data disagree with the answer, which then rests on the few that "
                "agree; the calibration cannot be trusted (check the data, or calibrate without --robust to see "
                "the rows' residuals)",
            }
        )
    rms_after = float(np.sqrt(np.mean(kept**2))) if kept.size else float("nan")
    chi_square, bound = float(np.sum(kept**2)), chi_square_bound(kept.size)
    if not (rms_after <= MISFIT and (chi_square <= bound or rms_after <= MISFIT_RMS_FLOOR)):
        warnings.append(
            {
                "code": "misfit",
                "message": f"after calibration the residuals are {rms_after:.3g} noise standard deviations (RMS; "
                f"chi-square {chi_square:.4g} on {kept.size} values, where a model that explains them at their "
                f"stated noise stays below {bound:.4g} 999 times in 1000): the model does not explain the "
                "measurements, and its stds are too small (a parameter held F, an outlier: try --robust, an "
                "unmodelled joint_noise, or the noise understated)",
            }
        )
    check = cal.check
    disagree = check.disagreement(cal.estimate, cal.std) if check is not None and check.trusted else []
    if check is not None and not check.trusted:
        if check.effective_samples > 0 and not check.pareto_k > CHECK_MAX_PARETO_K:
            # well-behaved weights, too few of them: the check's size, not the posterior, is short
            needed = math.ceil(1.2 * CHECK_MIN_ESS * check.samples / check.effective_samples)
            why = (
                f"its weights are well behaved, but too few for {CHECK_MIN_ESS:g} effective samples: "
                f"--check-samples {needed} or more would judge it"
            )
        elif check.effective_samples > 0 or not model.noise_densities():
            why = "the posterior is far from Gaussian, and the reported std may be wrong"
        else:  # every draw weighs 0 under a noise of bounded support
            why = (
                "no draw explains every reading within its noise's support (a reading off by more than a uniform "
                "noise's half width, say): the measurements are impossible under the noise the problem gives"
            )
        warnings.append(
            {
                "code": "laplace_unchecked",
                "message": "the importance-sampling check of the Laplace answer cannot be trusted "
                f"(Pareto k {check.pareto_k:.2f}, {check.effective_samples:.0f} effective samples of "
                f"{check.samples}): {why}",
            }
        )
    elif check is not None:
        off = [cal.names[k] for k in disagree]
        if off:
            warnings.append(
                {
                    "code": "not_gaussian",
                    "message": f"the posterior of {', '.join(off[:10])}{' ...' if len(off) > 10 else ''} "
                    "is not Gaussian: the importance-sampled mean or std differs from the calibrated model's MAP "
                    "and Laplace std (the sampled moments are in check.parameters)",
                }
            )
    unseen = _camera_parameters_not_identified(compiled, cal)
    if unseen:
        warnings.append(
            {
                "code": "camera_not_identified",
                "message": f"the views do not identify {', '.join(unseen[:10])}{' ...' if len(unseen) > 10 else ''}: "
                "their std stays near their prior's (see unobservable), so the camera's numbers there are the "
                "prior's, not the data's; views that turn the camera about different axes (not all about one "
                "axis, nor all parallel) and at several distances identify them",
            }
        )
    estimate, std = cal.answer()
    meaning = _dh_meaning(compiled)
    priors = cal.priors
    parameters = {}
    for k, name in enumerate(cal.names):
        entry = {
            "kind": cal.kinds[k],
            "reading": "MAP",  # with the Laplace std: one Gaussian, the calibrated model
            "estimate": float(estimate[k] * scale[k]),
            "std": float(std[k] * scale[k]),
            "map": float(cal.estimate[k] * scale[k]),
            "laplace_std": float(cal.std[k] * scale[k]),
            "prior_mean": float(priors.mean[k] * scale[k]),
            "prior_std": float(priors.std[k] * scale[k]),
            "prior": "gaussian" if priors.gaussian[k] else "flat",
            "identified": bool(cal.identified[k]),
            "unit": model.unit_of(k),
        }
        if "@" in name and any(name.split("@", 1)[1].startswith(f"{m}:") for m in model.joint_errors):
            entry["per_view"] = True  # a view's joint error (joint_noise)
        if cal.held[k]:
            entry["held"] = True
        if name in meaning:
            entry["dh"] = meaning[name]
        parameters[name] = entry
    document = {
        "kind": "calibrate",  # bcad.calibration.result.CalibrationResult
        "schema_version": SCHEMA_VERSION,
        "problem": compiled.problem.name,
        "bcad_version": __version__,
        "units": compiled.problem.units.model_dump(),
        "measurements": {m.name: len(m.x_rows) for m in model.measurements},
        "parameters": parameters,
        "correlation": {"names": cal.names, "matrix": cal.correlation.tolist()},
        "unobservable": [{"information": info, "combination": combination} for info, combination in cal.unobservable],
        "residuals": {
            "before": _residual_summary(model, compiled, cal.residuals_before),
            "after": _residual_summary(model, compiled, cal.residuals_after),
            "rms_whitened_after": rms_after,  # of the inliers with --robust
        },
        "warnings": warnings,
        "seconds": round(seconds, 3),
    }
    if model.cameras:
        # every camera at the calibrated model (the identified parameters at their MAP): what
        # `--camera-info` writes as ROS camera_info YAML
        document["cameras"] = {}
        for index, block in enumerate(model.cameras):
            vector = model.camera_vectors(estimate[None], index)[0]
            document["cameras"][block.name] = {
                "image_size": block.image_size,
                "distortion_model": block.model,
                "values": dict(zip(camera_parameters(block.model), map(float, vector))),
            }
    if check is not None:
        document["check"] = {
            "samples": check.samples,
            "effective_samples": round(check.effective_samples, 1),
            "pareto_k": None if not np.isfinite(check.pareto_k) else round(float(check.pareto_k), 3),
            "trusted": check.trusted,
            "disagree": [cal.names[k] for k in disagree],
            # the sampled posterior's moments, beside the calibrated model (MAP and Laplace std), not in it
            "parameters": {
                name: {
                    "mean": float(check.mean[k] * scale[k]),
                    "std": float(check.std[k] * scale[k]),
                    "mean_se": float(check.mean_se[k] * scale[k]),
                }
                for k, name in enumerate(cal.names)
            },
        }
    if cal.row_weights is not None:
        document["robust"] = {
            "loss": "huber",
            "outliers": [
                {
                    "measurement": o.measurement,
                    "row": o.row,
                    "line": o.line,
                    "distance": round(o.distance, 3),
                    "weight": round(o.weight, 4),
                }
                for o in cal.outliers
            ],
        }
    return document


def calibration_table(document: dict) -> WholeTable:
    """The calibrated parameters, every figure whole at any width (:class:`bcad.tables.WholeTable`)."""
    units = document["units"]
    table = Table(
        title=Text(printable(f"{document['problem']}: calibrated parameters (MAP ± Laplace std; prior in brackets)"))
    )
    for column in ("parameter", "kind", "estimate", "std", "prior", "identified"):
        table.add_column(column, justify="right" if column != "parameter" else "left", no_wrap=column == "parameter")
    per_view = [name for name, entry in document["parameters"].items() if entry.get("per_view")]
    for name, entry in document["parameters"].items():
        if entry.get("per_view"):
            continue  # a view's joint errors: in the JSON, counted below
        unit = entry.get("unit", units["length"] if name.rsplit(".", 1)[1] in LENGTH_NAMES else units["angle"])
        # the name a plan's L must match, and for a DH robot's error the DH parameter it perturbs
        label = f"{name} ({entry['dh']})" if "dh" in entry else name
        table.add_row(
            Text(printable(label)),
            Text(entry["kind"]),
            Text(f"{entry['estimate']:.5g} {unit}"),
            Text(f"{entry['std']:.3g} {unit}"),
            Text(
                f"[{entry['prior_mean']:.5g} ± {entry['prior_std']:.3g}]" if entry["prior"] == "gaussian" else "[flat]"
            ),
            Text("yes" if entry["identified"] else ("held" if entry.get("held") else "no")),
        )
    if per_view:
        table.title = Text(
            f"{table.title}; the views' {len(per_view)} joint errors are in the JSON"
        )  # title: already printable
    return WholeTable(table)


def proposal_table(proposal: dict) -> WholeTable:
    """``--propose``'s ranking: each chosen candidate configuration, best first, with what it adds
    (the entropy reduction of the parameters, or the task's predicted std after it, ``--for``)."""
    task = any("task_std" in entry for entry in proposal["ranked"])
    table = Table(
        title=Text(
            printable(f"the next configurations to measure, from {proposal['candidates']} ({proposal['criterion']})")
        ),
        caption=Text(printable(proposal["note"])) if "note" in proposal else None,
    )
    heading = f"task std ({proposal['task_unit']})" if proposal.get("task_unit") else "task std"
    for column in ("rank", "CSV line", "entropy reduction") + ((heading,) if task else ()):
        table.add_column(column, justify="right")
    for rank, entry in enumerate(proposal["ranked"], start=1):
        cells = [str(rank), str(entry["line"]), f"{entry['entropy_reduction']:.4g}"]
        if task:
            cells.append(f"{entry['task_std']:.4g}" if entry.get("task_std") is not None else "")
        table.add_row(*(Text(cell) for cell in cells))
    return WholeTable(table)


def prediction_table(prediction: dict) -> WholeTable:
    """``--predict``'s readings: each configuration's predicted value ± std of every length or
    angle a measurement reads (a camera's pixels, one row per point, are in the JSON only)."""
    table = Table(
        title=Text(
            printable(
                f"predicted readings at {prediction['configurations']} (value ± std in the problem's units; "
                "a new reading adds its noise)"
            )
        )
    )
    for column in ("CSV line", "measurement", "reading", "value ± std"):
        table.add_column(column, justify="right" if column != "measurement" else "left")
    for entry in prediction["rows"]:
        for name, readings in entry["measurements"].items():
            if "points" in readings:
                table.add_row(Text(str(entry["line"])), Text(printable(name)), Text("pixels"), Text("in the JSON"))
                continue
            for parameter, found in readings.items():
                table.add_row(
                    Text(str(entry["line"])),
                    Text(printable(name)),
                    Text(parameter),
                    Text(f"{found['value']:.6g} ± {found['std']:.3g}"),
                )
    return WholeTable(table)
