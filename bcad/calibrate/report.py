"""The result of ``bcad calibrate``: JSON and its table, in the problem's units."""

from __future__ import annotations

import numpy as np
from rich.table import Table
from rich.text import Text

from bcad import __version__
from bcad.calibrate.model import CalibrationModel
from bcad.calibrate.solve import Calibration
from bcad.compile import CompiledProblem
from bcad.compile.units import angle_scale
from bcad.model.pose import LENGTH_PARAMETERS, PARAMETERS

#: whitened RMS residual after calibration above which the model does not explain the data
MISFIT = 3.0


def _scales(compiled: CompiledProblem, names: list[str]) -> np.ndarray:
    per_angle = 1.0 / angle_scale(compiled.problem.units)
    return np.array([1.0 if name.rsplit(".", 1)[1] in LENGTH_PARAMETERS else per_angle for name in names])


def _residual_summary(model: CalibrationModel, compiled: CompiledProblem, whitened: np.ndarray) -> dict:
    per_angle = 1.0 / angle_scale(compiled.problem.units)
    summary, start = {}, 0
    for m in model.measurements:
        block = whitened[start : start + m.measured.size].reshape(m.measured.shape) * m.scale + m.mean
        start += m.measured.size
        entry = {}
        for k, slot in enumerate(m.slots):
            unit = 1.0 if PARAMETERS[slot] in LENGTH_PARAMETERS else per_angle
            values = block[:, k] * unit
            entry[PARAMETERS[slot]] = {
                "mean": float(values.mean()), "rms": float(np.sqrt(np.mean(values**2))), "max": float(np.abs(values).max()),
            }
        summary[m.name] = entry
    return summary


def calibration_document(compiled: CompiledProblem, model: CalibrationModel, cal: Calibration, seconds: float) -> dict:
    scale = _scales(compiled, cal.names)
    rms_after = float(np.sqrt(np.mean(cal.residuals_after**2)))
    warnings = []
    if not rms_after <= MISFIT:
        warnings.append({
            "code": "misfit",
            "message": f"after calibration the residuals are {rms_after:.3g} noise standard deviations (RMS): "
                       "the model does not explain the measurements (a parameter held F, an outlier, or the noise understated)",
        })
    return {
        "problem": compiled.problem.name,
        "bcad_version": __version__,
        "units": compiled.problem.units.model_dump(),
        "measurements": {m.name: len(m.x_rows) for m in model.measurements},
        "parameters": {
            name: {
                "prior_mean": float(cal.prior_mean[k] * scale[k]), "prior_std": float(cal.prior_std[k] * scale[k]),
                "estimate": float(cal.estimate[k] * scale[k]), "std": float(cal.std[k] * scale[k]),
                "identified": bool(cal.identified[k]),
            }
            for k, name in enumerate(cal.names)
        },
        "correlation": {"names": cal.names, "matrix": np.round(cal.correlation, 6).tolist()},
        "unobservable": [{"information": info, "combination": combination} for info, combination in cal.unobservable],
        "residuals": {
            "before": _residual_summary(model, compiled, cal.residuals_before),
            "after": _residual_summary(model, compiled, cal.residuals_after),
            "rms_whitened_after": rms_after,
        },
        "warnings": warnings,
        "seconds": round(seconds, 3),
    }


def calibration_table(document: dict) -> Table:
    units = document["units"]
    table = Table(title=Text(f"{document['problem']}: calibrated parameters (posterior mean ± std; prior in brackets)"))
    for column in ("parameter", "estimate", "std", "prior", "identified"):
        table.add_column(column, justify="right" if column != "parameter" else "left")
    for name, entry in document["parameters"].items():
        unit = units["length"] if name.rsplit(".", 1)[1] in LENGTH_PARAMETERS else units["angle"]
        table.add_row(
            Text(name), f"{entry['estimate']:.5g} {unit}", f"{entry['std']:.3g}",
            f"[{entry['prior_mean']:.3g} ± {entry['prior_std']:.3g}]", "yes" if entry["identified"] else "no",
        )
    return table

