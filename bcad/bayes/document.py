"""From a solved problem to the result document (JSON) and its tables.

The result of ``bcad solve``:

    {"problem", "bcad_version", "seed", "backend", "units",
     "stats": Table 1 + "seconds",
     "solution": {X name: value},
     "objective": {"log_value", "samples"},
     "posterior": {"samples", "links": {NAME: {"parent", "child", "params",
                   "mean", "std", "constrained", "weighted": {...},
                   "effective_samples", "satisfied", "satisfied_se"}}},
     "diagnostics": {...}}

Values are in the problem's units. Everything but the timings ("seconds"
and "diagnostics.timings") is the same, byte for byte, for the same seed.
"""

from __future__ import annotations

import math

import numpy as np

from bcad.bayes.estimators import ObjectiveEstimate
from bcad.bayes.posterior import LinkPosterior, PosteriorSummary
from bcad.compiler import CompiledProblem
from bcad.compiler.calibration import nominal_samples
from bcad.compiler.units import parameter_scales, pose_scales
from bcad.errors import counted
from bcad.model.pose import PARAMETERS
from bcad.model.results import SCHEMA_VERSION
from bcad.version import __version__


def _number(value: float) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


def solution_to_dict(compiled: CompiledProblem, x: np.ndarray) -> dict[str, float]:
    names = compiled.parameters.x_names
    return {name: float(value) for name, value in zip(names, np.asarray(x) * parameter_scales(compiled, names))}


def solution_from_dict(compiled: CompiledProblem, values: dict[str, float]) -> np.ndarray:
    names = compiled.parameters.x_names
    return np.array([values[name] for name in names], dtype=float) / parameter_scales(compiled, names)


def posterior_to_dict(
    compiled: CompiledProblem, links: list[LinkPosterior], samples: int, estimate: ObjectiveEstimate | None = None
) -> dict:
    """Table 2 per closing link, with standard errors. The weighted posterior and its effective
    sample size are the plain Monte Carlo pass's, or ``estimate``'s where another estimator
    (importance or linear) made it."""
    better = estimate is not None and estimate.estimator != "mc"
    scale = pose_scales(compiled)

    def vector(values):
        return None if values is None else [_number(v) for v in np.asarray(values) * scale]

    def moments(summary: dict | None) -> dict:
        summary = summary or {}
        return {key: vector(summary.get(key)) for key in ("mean", "std", "mean_se", "std_se")}

    return {
        "samples": samples,
        "links": {
            link.name: {
                "parent": link.parent,
                "child": link.child,
                "params": list(PARAMETERS),
                **moments(link.plain),
                "constrained": link.constrained,
                "weighted": moments(estimate.links[k] if better else link.weighted),
                "effective_samples": (
                    None if estimate.effective_samples is None else _number(estimate.effective_samples)
                )
                if better
                else _number(link.effective_samples),
                "satisfied": link.satisfied,
                "satisfied_se": link.satisfied_se,
            }
            for k, link in enumerate(links)
        },
    }


def arm_reaches(compiled: CompiledProblem, **solutions: np.ndarray) -> dict[str, dict[str, float | str]]:
    """Distance from each robot's base frame to its wrist frame at each named solution
    (``bayes=x, nominal=x``), every L at nominal (a calibrated L at its MAP)."""
    at_nominal = nominal_samples(compiled)
    reaches: dict[str, dict[str, float | str]] = {
        robot.name: {"base_frame": robot.base_frame, "wrist_frame": robot.wrist_frame} for robot in compiled.robots
    }
    frames = [frame for robot in compiled.robots for frame in (robot.base_frame, robot.wrist_frame)]
    for label, x in solutions.items():
        transforms = compiled.frame_transforms(x, at_nominal, frames)
        for robot in compiled.robots:
            base = transforms[robot.base_frame].translations[:, 0]
            wrist = transforms[robot.wrist_frame].translations[:, 0]
            reaches[robot.name][label] = float(np.linalg.norm(wrist - base))
    return reaches


def std_ratios(reference: list[LinkPosterior], candidate: list[LinkPosterior]) -> dict[str, dict[str, float | None]]:
    """reference std / candidate std on each closing link's constrained parameters."""
    ratios = {}
    for ref, cand in zip(reference, candidate):
        per_parameter = {}
        for name in ref.constrained:
            k = PARAMETERS.index(name)
            per_parameter[name] = _number(ref.std[k] / cand.std[k]) if cand.std[k] > 0 else None
        known = [value for value in per_parameter.values() if value is not None]
        # One figure per link: the geometric mean of the ratios, i.e. the ratio of the
        # k-th roots of the two generalised spreads (products of standard deviations).
        per_parameter["geometric_mean"] = _number(np.exp(np.mean(np.log(known)))) if known else None
        ratios[ref.name] = per_parameter
    return ratios


def search_to_dict(compiled: CompiledProblem, solution) -> dict:
    """The global search's record (:func:`bcad.bayes.estimators.solve`): its basins, best first,
    with the climbs that reached each and, for the finalists, the importance-sampled value; its
    coverage and its verdict (:func:`bcad.bayes.trust.search_findings`)."""
    report = solution.search
    scored = {tuple(np.round(f["basin_x"], 12)): f for f in solution.finalists}
    basins = []
    for basin in report["basins"]:
        entry = {
            "linear_log_value": _number(basin.log_value),
            "climbs": basin.climbs,
            "starts": basin.starts,
            "converged": basin.converged,
            "solution": solution_to_dict(compiled, basin.x),
        }
        finalist = scored.get(tuple(np.round(basin.x, 12)))
        if finalist is not None:
            entry["log_value"] = _number(finalist["log_value"])
            entry["log_value_se"] = _number(finalist["log_value_se"])
            if not np.array_equal(finalist["x"], basin.x):
                entry["polished"] = solution_to_dict(compiled, finalist["x"])
        basins.append(entry)
    climbs = report["climbs"]
    best = report["basins"][0].starts if report["basins"] else 0
    screened = sum(basin.starts for basin in report["basins"])
    document = {
        "starts": report["starts"],
        "climbs": climbs,
        "maxima": [_number(m.log_value) for m in solution.maxima],
        "iterations": [m.iterations for m in solution.maxima],
        "basins": basins,
        "coverage": {
            "best_basin_starts": best,
            "starts_in_basins": screened,
            "unseen_mass": _number(report["unseen_mass"]),
            "converged_climbs": sum(m.converged for m in solution.maxima),
        },
        "finalists": [
            {
                "linear_log_value": _number(f["linear_log_value"]),
                "log_value": _number(f["log_value"]),
                "log_value_se": _number(f["log_value_se"]),
                **(
                    {
                        "exact_climb": {
                            key: _number(value) if isinstance(value, float) else value
                            for key, value in f["exact_climb"].items()
                        }
                    }
                    if "exact_climb" in f
                    else {}
                ),
            }
            for f in solution.finalists
        ],
    }
    if "choice" in report:
        document["choice"] = {
            key: _number(value) if isinstance(value, float) else value for key, value in report["choice"].items()
        }
    if "verdict" in report:
        document["verdict"] = {
            key: (
                _number(value)
                if isinstance(value, float)
                else [_number(v) for v in value]
                if isinstance(value, list)
                else value
            )
            for key, value in report["verdict"].items()
        }
    return document


def search_line(search: dict | None, trusted: bool = True) -> str | None:
    """One line on the global search: basins, climbs, starts, and its verdict (None where the
    result has no search: the nominal backend, the genetic algorithm); where the result is not
    ``trusted`` (it has warnings), the line says that its estimates are the ones they doubt."""
    if not search or "basins" not in search:
        return None
    line = (
        f"search: {counted(search['climbs'], 'climb')} from {counted(search['starts'], 'screened start')} ended at "
        f"{counted(len(search['basins']), 'distinct maximum', 'distinct maxima')}"
    )
    verdict = search.get("verdict")
    if verdict:
        runs = "branch-search lineages" if verdict["method"] == "lineages" else "climbs"
        within = f" within {verdict['agree']:g}" if "agree" in verdict else ""
        line += (
            f"; {verdict['reached_best']} of {counted(verdict['runs'], runs[:-1], runs)} reached the best value{within}"
        )
        if verdict["reached_best"] < 2 and verdict.get("screened_starts_reaching_best", 0) >= 2:
            line += f", standing for {counted(verdict['screened_starts_reaching_best'], 'screened start')}"
        if verdict.get("finalists_scored", 0) >= 2 and verdict["reached_best"] < 2:
            # the stand-in's values alone did not settle it: say what the finalists' estimates did
            line += (
                f", and {verdict['finalists_reached_best']} of {verdict['finalists_scored']} finalists (the answer's "
                f"own included) came within {verdict.get('agree', 0.02):g} of its estimate"
            )
            if verdict.get("runs_reached_best", verdict["finalists_reached_best"]) < verdict["finalists_reached_best"]:
                line += f", from {counted(verdict['runs_reached_best'], 'run')} of the search"
        line += ": settled" if verdict["settled"] else ": not settled"
    choice = search.get("choice")
    if choice and choice.get("mirror_images"):
        count = choice["mirror_images"]
        line += f"; {counted(count, 'mirror image')} of the finalists set aside (as robust by symmetry)"
    if choice and choice.get("margin") is not None:
        margin = f"{choice['margin']:.3f} ± {choice['margin_se']:.3f}"
        line += (
            f"; X* ahead of the next finalist by {margin}"
            if choice["margin"] > 2.0 * choice["margin_se"]
            else f"; X* and the next finalist equal within noise ({margin}): either is as robust (the JSON's "
            "diagnostics.search.basins lists both)"
        )
    if not trusted:
        line += " (the finalists' estimates behind this are of the kind the warnings below doubt)"
    return line


def configurations_to_dict(compiled: CompiledProblem, x: np.ndarray) -> dict:
    """Each configuration's joint values at X (problem units) and the links and relations that
    belong to it (its closing links' posteriors are Table 2's rows of those names)."""
    from bcad.compiler.configurations import configuration_joint_values

    values = configuration_joint_values(
        compiled.configurations, compiled.graph.links, compiled.transforms, np.asarray(x, float)
    )
    closing = {compiled.graph.links[k].name for k in compiled.graph.closing_links}
    return {
        configuration.name: {
            "joints": values[configuration.name],
            "links": list(configuration.links),
            "closing_links": [name for name in configuration.links if name in closing],
        }
        for configuration in compiled.configurations
    }


def objective_to_dict(estimate: ObjectiveEstimate) -> dict:
    return {
        "estimator": estimate.estimator,
        "log_value": _number(estimate.log_value),
        "log_value_se": _number(estimate.log_value_se),
        "samples": estimate.samples,
        "effective_samples": None if estimate.effective_samples is None else _number(estimate.effective_samples),
        "pareto_k": None if estimate.pareto_k is None else _number(estimate.pareto_k),
    }


def contributors_to_dict(compiled: CompiledProblem, linear, x: np.ndarray) -> dict:
    """Per scored parameter of each closing link: the share of its linearised variance
    J Sigma_L J^T that each L parameter contributes, summed per link and per robot."""
    from bcad.bayes.contributors import variance_shares

    return variance_shares(compiled, linear, x, parameter_scales)


def result_document(
    compiled: CompiledProblem,
    *,
    kind: str,
    seed: int,
    backend: str,
    x: np.ndarray,
    posterior: PosteriorSummary,
    estimate: ObjectiveEstimate,
    samples: int,
    diagnostics: dict,
    seconds: float,
    contributors: dict | None = None,
    warnings: list[dict] | None = None,
    findings: list[dict] | None = None,
) -> dict:
    document = {
        "kind": kind,  # the command that wrote it (bcad.bayes.result.DesignResult)
        "schema_version": SCHEMA_VERSION,
        "problem": compiled.problem.name,
        "bcad_version": __version__,
        "seed": seed,
        "backend": backend,
        "units": compiled.problem.units.model_dump(),
        "stats": {**compiled.stats.as_dict(), "seconds": round(seconds, 3)},
        "solution": solution_to_dict(compiled, x),
        "objective": objective_to_dict(estimate),
        "posterior": posterior_to_dict(compiled, posterior.links, samples, estimate),
    }
    if contributors is not None:
        document["contributors"] = contributors
    document["warnings"] = warnings or []
    document["findings"] = findings or []
    document["diagnostics"] = diagnostics
    if compiled.configurations:  # one cell at several poses
        document["configurations"] = configurations_to_dict(compiled, x)
    if compiled.calibration.files:  # measure, then plan: what the results replaced
        prior = compiled.calibration
        document["calibration"] = [
            {"file": name, "applied": prior.applied[name], "not_applied": prior.not_applied[name]}
            for name in prior.files
        ]
    return document
