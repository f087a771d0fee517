"""bcad's Python API, and the one place that runs a problem: load, compile, solve, write.

The ``bcad`` command is a thin layer over this module, as is ``bcad batch``;
:mod:`bcad.results` and :mod:`bcad.report` only format. In a notebook::

    import bcad

    problem = bcad.load("problems/rx90_face_on_face.yaml")
    result = bcad.solve(problem, seed=0)
    result.table()                      # Table 2 of the 2000 paper (rich; HTML in notebooks)
    result.links["contact"].std         # the posterior std of the closing link's pose, Eq. 2
    result.to_json()

Errors raise :class:`bcad.InputError` (with the file and line); nothing here exits.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from bcad.compiler.units import angle_scale
from bcad.errors import InputError, quoted, shown
from bcad.model.source import SourceDocument
from bcad.numerics.seeding import stream

# The Bayesian family, the graph compiler and the graph language's schemas are loaded by the
# functions that use them: ``bcad maxerror`` and ``bcad validate`` start without them.
if TYPE_CHECKING:
    from bcad.bayes.estimators import ObjectiveEstimate
    from bcad.bayes.model import BayesModel
    from bcad.bayes.posterior import PosteriorSummary
    from bcad.compiler import CompiledProblem
    from bcad.model.problem import Problem

__all__ = ["load", "compile", "solve", "posterior", "maxerror", "calibrate", "Result", "ClosingLink", "InputError"]


# --- orchestration: the documents of the commands --------------------------------------------


#: posterior samples that ``--samples-out`` may keep in memory and write at most
MAX_SAMPLES_OUT = 2_000_000


def write_samples(compiled: CompiledProblem, kept: dict[str, np.ndarray], path: Path, protected) -> None:
    """``--samples-out``: the posterior samples as a numpy .npz, in the problem's units.

    Arrays: ``LINK/poses`` (N, 6) of each closing link (tx ty tz rx ry rz), ``LINK/log_weights``
    (N,) its own weight (its distributions and relation), ``log_weights`` (N,) the sample's whole
    weight (the integrand of Eq. 2: every closing link and tree relation); ``parameters`` and
    ``units``. The weighted posterior is the samples weighted by exp(log_weights).
    """
    import io

    from bcad.compiler.units import pose_scales
    from bcad.io import write_bytes_atomic
    from bcad.model.pose import PARAMETERS

    scales = pose_scales(compiled)
    arrays = {key: (value * scales if key.endswith("/poses") else value) for key, value in kept.items()}
    arrays["parameters"] = np.array(PARAMETERS)
    arrays["units"] = np.array([compiled.problem.units.length, compiled.problem.units.angle])
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    write_bytes_atomic(buffer.getvalue(), path, protected)


def monte_carlo_estimate(posterior: PosteriorSummary, samples: int) -> ObjectiveEstimate:
    """The paper's estimate (Sect. 4.1.2): the prior samples of the posterior pass, weighted by the integrand."""
    from bcad.bayes.estimators import ObjectiveEstimate

    return ObjectiveEstimate(
        "mc", posterior.log_value, posterior.log_value_se, samples, posterior.effective_samples, posterior.pareto_k,
        [link.weighted for link in posterior.links],
    )


def posterior_and_estimate(model: BayesModel, x: np.ndarray, samples: int, estimator: str,
                           posterior_rng: np.random.Generator, importance_rng: np.random.Generator,
                           keep: dict | None = None, progress: Callable | None = None,
                           ) -> tuple[PosteriorSummary, ObjectiveEstimate]:
    """The posterior at X (``samples`` prior samples, ``keep`` and ``progress``: :func:`sample_posteriors`) and
    log p(X) I(X) by the estimator. The ``mc`` estimate is read off that posterior; the others
    are independent of it and run beside it on a second thread: numpy releases the GIL in its
    loops, and each has its own random stream, so the results do not depend on the order
    (on a 2-core machine the RX90 example's pair takes 0.7 s instead of 1.1 s)."""
    from concurrent.futures import ThreadPoolExecutor

    from bcad.bayes.estimators import estimate as estimate_objective
    from bcad.bayes.posterior import sample_posteriors

    if estimator == "mc":
        posterior = sample_posteriors(model, {"x": x}, samples, posterior_rng, keep, progress)["x"]
        return posterior, monte_carlo_estimate(posterior, samples)
    with ThreadPoolExecutor(max_workers=2) as pool:
        posterior_job = pool.submit(sample_posteriors, model, {"x": x}, samples, posterior_rng, keep, progress)
        estimate = estimate_objective(model, x, estimator, samples, importance_rng)
        return posterior_job.result()["x"], estimate


def result_model(kind: str):
    """The typed model of a result document of this kind (the command that wrote it)."""
    if kind in ("solve", "posterior"):
        from bcad.bayes.result import DesignResult

        return DesignResult
    if kind == "maxerror":
        from bcad.worstcase.result import MaxErrorResult

        return MaxErrorResult
    from bcad.calibration.result import CalibrationResult

    return CalibrationResult


def results_json_schema() -> dict:
    """The JSON Schema of every result document (``bcad schema --results``): one of the
    families' models, told apart by ``kind``."""
    from pydantic.json_schema import models_json_schema

    from bcad.bayes.result import DesignResult
    from bcad.calibration.result import CalibrationResult
    from bcad.model.results import SCHEMA_VERSION
    from bcad.model.schema import SCHEMA_DRAFT
    from bcad.worstcase.result import MaxErrorResult

    models = [DesignResult, MaxErrorResult, CalibrationResult]
    references, definitions = models_json_schema([(model, "serialization") for model in models],
                                                 ref_template="#/$defs/{model}")
    return {
        "$schema": SCHEMA_DRAFT,
        "$id": "https://bcad.invalid/schema/results.schema.json",
        "title": f"bcad result (schema_version {SCHEMA_VERSION})",
        "description": "The JSON document that bcad solve, posterior, maxerror or calibrate writes; its 'kind' names "
                       "the command. Keys not listed may be added by later versions: readers ignore them.",
        "anyOf": [references[(model, "serialization")] for model in models],
        "$defs": definitions["$defs"],
    }


def checked(document: dict) -> dict:
    """The document, once its family's model has checked it: the schema bcad publishes holds for
    every result it writes (a mismatch is a bug, reported as one)."""
    result_model(document["kind"]).model_validate(document)
    return document


def posterior_document(compiled: CompiledProblem, x: np.ndarray, *, samples: int | None, seed: int,
                       estimator: str | None = None, kept: dict | None = None, model: BayesModel | None = None,
                       samples_option: str = "--samples", progress: Callable | None = None) -> dict:
    """The result of ``bcad posterior``: Table 2 and the objective's estimate at a given X (on
    the problem's model where the caller has built it); ``samples_option`` names the count's
    source in the message that refuses too many; ``progress(done, samples)`` follows the
    posterior's samples."""
    from bcad.bayes.model import BayesModel, check_posterior_work, check_solvable
    from bcad.bayes.trust import design_findings, result_warnings
    from bcad.results import contributors_to_dict, result_document

    start = time.perf_counter()
    check_solvable(compiled, needs_unknowns=False)
    if samples is None:  # the problem's solver.posterior_samples, as solve's posterior
        samples, samples_option = compiled.problem.solver.posterior_samples, None
    check_posterior_work(compiled, samples, samples_option)
    estimator = estimator or compiled.problem.solver.estimator
    model = model or BayesModel(compiled)
    keep = {"x": kept} if kept is not None else None
    posterior, estimate = posterior_and_estimate(
        model, x, samples, estimator, stream(seed, "posterior"), stream(seed, "importance"), keep, progress)
    return checked(result_document(
        compiled, kind="posterior", seed=seed, backend="posterior", x=x, posterior=posterior, estimate=estimate,
        samples=samples, diagnostics={}, seconds=time.perf_counter() - start,
        contributors=contributors_to_dict(compiled, model.linear, x),
        warnings=result_warnings(posterior, estimate),
        findings=design_findings(compiled, model.linear, x),
    ))


def solve_document(
    compiled: CompiledProblem,
    *,
    backend: str,
    seed: int,
    posterior_samples: int | None = None,
    estimator: str | None = None,
    progress: Callable | None = None,
    kept: dict | None = None,
    samples_option: str = "--samples",
) -> dict:
    """Run a backend, estimate the objective and sample the posterior at its solution, and build
    the result document (with its warnings: :mod:`bcad.bayes.trust`); ``samples_option`` names
    where ``posterior_samples`` came from."""
    from bcad.bayes.estimators import solve as solve_by_search
    from bcad.bayes.genetic_search import solve_bayes
    from bcad.bayes.model import BayesModel, check_posterior_work, check_solvable
    from bcad.bayes.nominal import solve_nominal
    from bcad.bayes.trust import design_findings, result_warnings, search_findings
    from bcad.results import (
        _number,
        arm_reaches,
        contributors_to_dict,
        result_document,
        search_to_dict,
        solution_to_dict,
        std_ratios,
    )

    start = time.perf_counter()
    settings = compiled.problem.solver
    if estimator is not None:
        settings = settings.model_copy(update={"estimator": estimator})
    check_solvable(compiled)
    n = posterior_samples or settings.posterior_samples
    check_posterior_work(compiled, n, samples_option if posterior_samples else None)
    # the posterior's share of the progress: the phase "posterior" with the samples drawn so far
    sampled = (lambda done, total: progress("posterior", float("nan"), done, float("nan"))) if progress else None
    model = BayesModel(compiled)  # built once: every step below receives it
    nominal = solve_nominal(model, stream(seed, "nominal"))
    nominal_summary = {
        "solution": solution_to_dict(compiled, nominal.x),
        "closed": nominal.closed,
        "cost": _number(nominal.cost),
        "starts": nominal.starts,
    }
    timings: dict[str, float] = {"nominal": time.perf_counter() - start}
    comparison = None
    if backend == "nominal":
        x = nominal.x
        diagnostics = {
            "nominal": {key: nominal_summary[key] for key in ("closed", "cost", "starts")},
            "arms": arm_reaches(compiled, nominal=nominal.x),
        }
        started = time.perf_counter()
        posterior, estimate = posterior_and_estimate(
            model, x, n, settings.estimator, stream(seed, "posterior"), stream(seed, "importance"),
            {"x": kept} if kept is not None else None, sampled)
        timings["posterior"] = time.perf_counter() - started
    else:
        diagnostics = {}
        if settings.estimator == "mc":
            solution = solve_bayes(model, settings, seed, progress)
            x = solution.x
            genetic = solution.genetic
            diagnostics["genetic"] = {
                "initial_temperature": genetic.initial_temperature,
                "generations": len(genetic.trace),
                "evaluations": genetic.evaluations,
                "sample_evaluations": genetic.sample_evaluations,
                "best_log_value": _number(genetic.best_log_value),
            }
            diagnostics["refinement"] = None if solution.refinement is None else {
                "start_log_value": _number(solution.refinement.start_log_value),
                "log_value": _number(solution.refinement.log_value),
                "iterations": solution.refinement.iterations,
                "samples": settings.refine_samples,
            }
            diagnostics["selection"] = {key: _number(value) for key, value in solution.selection.items()}
        else:
            if progress:
                progress("search", 0.0, 0, float("nan"))
            solution = solve_by_search(model, settings, seed, nominal.x)
            x = solution.x
            diagnostics["search"] = search_to_dict(compiled, solution)
        timings.update(solution.timings)
        started = time.perf_counter()
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(max_workers=1) as pool:
            # The nominal X is only compared with (its objective, the ratio of its posterior stds):
            # finalist_samples samples of it do, on streams of their own, beside X*'s pair.
            nominal_job = pool.submit(
                posterior_and_estimate, model, nominal.x, min(n, settings.finalist_samples), settings.estimator,
                stream(seed, "posterior-nominal"), stream(seed, "importance-nominal"))
            posterior, estimate = posterior_and_estimate(
                model, x, n, settings.estimator, stream(seed, "posterior"), stream(seed, "importance"),
                {"x": kept} if kept is not None else None, sampled)
            nominal_posterior, nominal_estimate = nominal_job.result()
        timings["posterior"] = time.perf_counter() - started
        comparison = nominal_estimate
        diagnostics["nominal_comparison"] = {
            **nominal_summary,
            "log_objective": _number(nominal_estimate.log_value),
            "log_objective_se": _number(nominal_estimate.log_value_se),
            "posterior_std_ratio": std_ratios(nominal_posterior.links, posterior.links),
        }
        diagnostics["arms"] = arm_reaches(compiled, bayes=x, nominal=nominal.x)
    diagnostics["timings"] = {key: round(value, 3) for key, value in timings.items()}
    warnings = result_warnings(posterior, estimate, comparison)
    findings = design_findings(compiled, model.linear, x)
    if backend != "nominal" and settings.estimator != "mc":
        findings += search_findings(solution.search.get("verdict"))
    return checked(result_document(
        compiled, kind="solve", seed=seed, backend=backend, x=x, posterior=posterior, estimate=estimate, samples=n,
        diagnostics=diagnostics, seconds=time.perf_counter() - start,
        contributors=contributors_to_dict(compiled, model.linear, x), warnings=warnings,
        findings=findings,
    ))


#: the exact bound's allowance for the rounding of the exact error's evaluation, in units of
#: (joints + 2) machine epsilons, relative
EXACT_ROUNDING = 64
#: clearance samples times joints that ``maxerror --samples`` draws at most (7 joints: 2.9e6 samples)
MAX_CLEARANCE_SAMPLE_WORK = 20_000_000


def maxerror_document(problem, *, tol: float, model: str, samples: int | None = None, seed: int = 0,
                      spec: dict[str, float] | None = None, allocate: dict[str, float] | None = None,
                      weights: list[float] | None = None) -> dict:
    """The result of ``bcad maxerror``: certified first-order maxima, optionally the exact
    model's local maximum and the statistics of uniformly distributed clearances."""
    from bcad.worstcase.branch_and_bound import certified_maximum
    from bcad.worstcase.error_map import build_error_map

    error_map = build_error_map(problem)
    if samples and samples * error_map.joints > MAX_CLEARANCE_SAMPLE_WORK:
        # each sample is a chain of exact screws, kept for the percentiles: bounded in time and memory
        raise InputError("--samples", f"{samples:,} samples of a {error_map.joints}-joint chain; at most "
                                      f"{MAX_CLEARANCE_SAMPLE_WORK // error_map.joints:,} (samples x joints <= "
                                      f"{MAX_CLEARANCE_SAMPLE_WORK:.0e}: time and memory grow with both)")
    per_angle = 1.0 / angle_scale(problem.units)
    # Screw units: dr in the problem's angle unit, dt in its length unit.
    screw_scale = np.array([per_angle] * 3 + [1.0] * 3)
    from bcad.model.results import SCHEMA_VERSION
    from bcad.version import __version__

    document = {"kind": "maxerror", "schema_version": SCHEMA_VERSION, "problem": problem.name,
                "bcad_version": __version__, "model": "first-order", "units": problem.units.model_dump()}
    warnings: list[dict] = []
    for kind in ("rotation", "translation"):
        found = certified_maximum(error_map, kind, tol)
        scale = per_angle if kind == "rotation" else 1.0
        # A change of unit rounds: step the bounds outward so they stay bounds.
        entry = {
            "max": float(max(np.nextafter(found.max * scale, -np.inf), 0.0)) if scale != 1.0 else found.max,
            "upper_bound": float(np.nextafter(found.upper_bound * scale, np.inf)) if scale != 1.0 and found.upper_bound > 0 else found.upper_bound,
            "argmax": (found.argmax * screw_scale).tolist(),
            "seconds": round(found.seconds, 4),
            "gap": (found.upper_bound - found.max) / found.upper_bound if found.upper_bound > 0 else 0.0,
            "converged": found.converged,
        }
        if not found.converged:
            warnings.append({
                "code": "gap_not_reached",
                "message": f"the {kind} search stopped at a relative gap of {entry['gap']:.3g}, above --tol {tol:g}: "
                           "the bound is certified but looser than asked (the tolerance may be below what doubles resolve)",
            })
        entry["model"] = "first-order"  # the linearised model's figures (Eq. 11): not a bound of the exact error
        if model == "exact":
            from bcad.worstcase.exact import EXACT_STARTS, exact_maximum, exact_upper_bounds
            from bcad.worstcase.exact_bound import exact_bound

            search = exact_maximum(error_map, found.argmax, kind, rng=stream(seed, f"exact-{kind}"))
            # Both bounds from the one first-order bound of this kind; only this kind's is kept.
            bound = exact_upper_bounds(error_map, found.upper_bound, found.upper_bound)[0 if kind == "rotation" else 1]
            # The sharp bound (bcad/worstcase/exact_bound.py), where its branch and bound applies.
            sharp = exact_bound(error_map, kind, search.max, search.argmax, tol, bound)
            if sharp is not None and sharp.bound < bound:
                bound = sharp.bound
            # The exact error is evaluated in doubles, to about (n + 2) eps relative
            # (bcad.worstcase.exact.error_transforms): the bound covers that rounding too.
            bound *= 1.0 + EXACT_ROUNDING * (error_map.joints + 2) * np.finfo(float).eps
            if search.max > bound:  # never seen: a certificate that does not hold is said, not shown as one
                warnings.append({"code": "exact_bound_below_max",
                                 "message": f"the exact {kind} bound {bound:.17g} is below the error {search.max:.17g} "
                                            "a feasible point reaches: the bound is not certified here"})
            if (bound - search.max) > tol * bound:
                warnings.append({
                    "code": "exact_gap_not_reached",
                    "message": f"the exact {kind} bound is {(bound - search.max) / bound:.3g} above the largest exact error "
                               f"found, more than --tol {tol:g}: both are certified (the error is between them), the bound is looser than asked",
                })
            entry["exact"] = {
                "max": search.max * scale,
                "bound": float(np.nextafter(bound * scale, np.inf)) if scale != 1.0 else bound,
                "gap": (bound - search.max) / bound if bound > 0 else 0.0,
                "argmax": (search.argmax * screw_scale).tolist(),
                "at_first_order_argmax": search.start_value * scale,
                "relative_to_first_order": search.max / found.max - 1.0 if found.max > 0 else 0.0,
                "starts": 2 + EXACT_STARTS,
                "bound_cells": None if sharp is None else sharp.cells,
            }
        document[kind] = entry
    if model == "exact":
        document["model"] = "exact"
    if samples:
        from bcad.worstcase.statistics import error_statistics

        internal = None if spec is None else {kind: value / per_angle if kind == "rotation" else value for kind, value in spec.items()}
        statistics = error_statistics(error_map, problem.name, problem.units.length, samples, stream(seed, "clearance"), internal)
        for value in statistics["rotation"]:
            statistics["rotation"][value] *= per_angle
        if spec is not None:
            statistics["yield"]["spec"] = dict(spec)  # as given, in the problem's units
            # The exact model's certified bounds within the spec: no clearance can miss it.
            bounds = {kind: document.get(kind, {}).get("exact", {}).get("bound") for kind in spec}
            if all(bound is not None and bound <= spec[kind] for kind, bound in bounds.items()):
                statistics["yield"]["certain"] = True
        document["statistics"] = statistics
    if allocate is not None:
        allocation = document["allocation"] = allocation_to_dict(error_map, allocate, weights, per_angle)
        width = allocation["relative_width"]
        if width is None or width > ALLOCATION_WIDTH:
            side = ("no clearance was found beyond the spec (no unsafe side)" if allocation["lambda_high"] is None
                    else f"its relative width is {width:.3g}")
            warnings.append({
                "code": "allocation_width_not_reached",
                "message": f"the tolerance bracket is wider than {ALLOCATION_WIDTH:g}: {side}; lambda_low "
                           f"{allocation['lambda_low']:.9g} is still proven safe (a limit the tool hardly reaches, "
                           "or one below what the bounds resolve)",
            })
    document["warnings"] = warnings
    return checked(document)


#: the relative width of a tolerance bracket above which ``bcad maxerror --allocate`` warns
ALLOCATION_WIDTH = 1e-6


def allocation_to_dict(error_map, spec: dict[str, float], weights: list[float] | None, per_angle: float) -> dict:
    """Tolerance synthesis (:mod:`bcad.worstcase.allocate`) in the problem's units."""
    from bcad.worstcase.allocate import allocate as allocate_clearances

    if weights is not None and len(weights) != error_map.joints:
        raise InputError("--weights", f"gives {len(weights)} weights for a chain of {error_map.joints} joints")
    internal = {kind: value / per_angle if kind == "rotation" else value for kind, value in spec.items()}
    found = allocate_clearances(error_map, internal, None if weights is None else np.array(weights, float))
    factors = np.ones(error_map.joints) if weights is None else np.array(weights, float)
    unit = np.array([per_angle, per_angle, 1.0, 1.0])
    clearances = error_map.clearance * (found.lambda_low * factors)[:, None] * unit[None, :]

    def in_units(values: dict[str, float]) -> dict[str, float]:
        return {kind: value * per_angle if kind == "rotation" else value for kind, value in values.items()}

    return {
        "spec": dict(spec),
        "weights": None if weights is None else list(weights),
        "lambda_low": found.lambda_low,
        "lambda_high": found.lambda_high if np.isfinite(found.lambda_high) else None,
        "relative_width": found.relative_width if np.isfinite(found.relative_width) else None,
        "exact_bound_at_lambda_low": in_units(found.bound_at_low),
        "witness_errors_at_lambda_high": in_units(found.witness_errors),
        "clearances_at_lambda_low": [dict(zip(("rot_xy", "rot_z", "trans_xy", "trans_z"), map(float, row))) for row in clearances],
        "note": "lambda_low is proven safe (the exact model's certified bound is within the spec there); lambda_high is "
                "shown unsafe (a feasible clearance there exceeds the spec by more than 1e-9 relative)",
    }


#: the importance-sampling check's default size, and its budget: samples x measured values
#: (each sample predicts every measurement; 3e7 values take about 10 s on a 2-core machine)
DEFAULT_CHECK_SAMPLES, CHECK_VALUES = 1000, 30_000_000


def check_sample_count(model, requested: int | None, where) -> int:
    """The check's samples: ``requested``, or DEFAULT_CHECK_SAMPLES where it is None, at most
    CHECK_VALUES / (measured values) (a default check of a large file is made smaller, and
    said in the result's check.samples; an explicit one over the budget is refused)."""
    values = max(1, model.residual_count)
    most = max(1, CHECK_VALUES // values)
    if requested is None:
        return min(DEFAULT_CHECK_SAMPLES, most)
    if requested > most:
        raise InputError(where, f"--check-samples {requested}: the check predicts all {values:,} measured values per "
                                f"sample, at most {CHECK_VALUES:.0e} values in all, so at most {most:,} samples here "
                                "(or 0: no check)")
    return requested


def _plan_task(model, calibration, path: Path) -> tuple[np.ndarray, list[int], float]:
    """``--for PLAN.yaml``: the task Jacobian of a planning problem's closing links (what its
    relation or closing link scores: the error at the drilling point) at the plan's configuration,
    the cycles closed with L at nominal (the nominal backend, seed 0: a deterministic X); its
    rows' slots, and the factor to the plan's units."""
    from bcad.bayes.model import BayesModel
    from bcad.bayes.nominal import solve_nominal
    from bcad.calibration.propose import plan_task_jacobian
    from bcad.compiler import compile_problem
    from bcad.compiler.units import pose_scales
    from bcad.model import load_problem

    plan = compile_problem(load_problem(path))
    if not plan.graph.cycles:
        raise InputError(path, "the plan has no cycle, so no closing link to direct --propose at")
    x = solve_nominal(BayesModel(plan), np.random.default_rng(0)).x if plan.parameters.x else np.zeros(0)
    rows, slots = plan_task_jacobian(model, calibration, plan, x)
    return rows, slots, float(pose_scales(plan)[min(slots)])


def calibration_run(
    compiled: CompiledProblem, *, robust: bool = False, check_samples: int | None = None, seed: int = 0,
    propose: int = 0, candidates: Path | None = None, urdf: bool = False, predict: Path | None = None,
    task: Path | None = None,
) -> tuple[dict, dict[str, str]]:
    """The result of ``bcad calibrate`` and, with ``urdf``, the calibrated robots' URDF texts."""
    from bcad.calibration.model import CalibrationModel
    from bcad.calibration.report import calibration_document
    from bcad.calibration.solve import calibrate as run_calibration

    start = time.perf_counter()
    model = CalibrationModel(compiled)
    check_samples = check_sample_count(model, check_samples, compiled.problem.source.path)
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
                task_rows, slots, unit = _plan_task(model, calibration, Path(task))
            else:
                from bcad.calibration.propose import task_jacobian

                task_rows = task_jacobian(model, calibration, Path(task))
                kinds = {"px" if m.camera is not None else "length" if slot < 3 else "angle"
                         for m in model.measurements for slot in m.slots}
                if len(kinds) > 1:
                    raise InputError(Path(task), "--for needs readings of one kind (lengths, angles or pixels) to add "
                                                 "their variances")
                slots = {int(slot) for m in model.measurements for slot in m.slots}
                unit = 1.0 if kinds == {"px"} else float(pose_scales(compiled)[min(slots)])
            if len({bool(slot < 3) for slot in slots}) > 1:
                raise InputError(Path(task), "--for needs readings of one kind (lengths or angles) to add their variances")
        proposals = rank_candidates(model, calibration, Path(candidates), propose, task_rows, unit)
    document = calibration_document(compiled, model, calibration, time.perf_counter() - start)
    if proposals is not None:
        document["proposal"] = {
            "candidates": str(candidates),
            "criterion": "D-optimal (greedy)" if task is None else "the task's predicted variance (greedy A-optimal on the task)",
            "ranked": [{"row": p.row, "line": p.line, "joints": p.joints, "entropy_reduction": round(p.entropy_reduction, 6),
                        **({} if p.task_std is None else {"task_std": p.task_std})}
                       for p in proposals],
        }
        if task is not None:
            document["proposal"]["task"] = str(task)
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
    return checked(document), texts


def prediction_to_dict(compiled: CompiledProblem, model, calibration, path: Path) -> dict:
    """``calibrate --predict C.csv``: the calibrated model's readings at new configurations, in the
    problem's units (:func:`bcad.calibration.propose.predict`)."""
    from bcad.calibration.propose import predict
    from bcad.compiler.units import pose_scales
    from bcad.model.pose import PARAMETERS

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
                readings[name] = {"noise_std": float(found["noise_std"][0]), "points": [
                    {"point": i, "seen": bool(seen),
                     "u": {"value": float(values[i, 0]) if seen else None, "std": float(std[i, 0]) if seen else None},
                     "v": {"value": float(values[i, 1]) if seen else None, "std": float(std[i, 1]) if seen else None}}
                    for i, seen in enumerate(found["seen"])]}
                continue
            scale = scales[slots[name]]
            readings[name] = {PARAMETERS[slot]: {"value": float(v * s), "std": float(d * s), "noise_std": float(e * s)}
                              for slot, v, d, e, s in zip(slots[name], found["values"], found["std"], found["noise_std"], scale)}
        rows.append({"row": entry["row"], "line": entry["line"], "joints": entry["joints"], "measurements": readings})
    return {"configurations": str(path), "model": "MAP, Laplace covariance propagated to first order (std); "
            "a new reading spreads by sqrt(std^2 + noise_std^2)", "rows": rows}


def read_result(path: Path) -> tuple[dict[str, float], int]:
    """A result file's ``solution`` (names to finite numbers) and ``seed`` (0 when absent)."""
    import math

    from bcad.model.pose import is_parameter_name
    from bcad.model.source import read_json

    document = read_json(path, "a bcad result (JSON)", "a bcad result")
    try:
        solution = document["solution"]
    except (KeyError, TypeError, IndexError):
        raise InputError(path, "not a bcad result: expected an object with a 'solution' mapping") from None
    if not isinstance(solution, dict):
        raise InputError(path, "not a bcad result: its 'solution' is not a mapping of names to numbers")
    named = [is_parameter_name(name) for name in solution]
    if not all(named):
        raise InputError(path, f"not a bcad result: entry {named.index(False) + 1} of its 'solution' is not named "
                               "LINK.PARAMETER (ur5/base.tx, arm/joint_1.rz)")
    for name, value in solution.items():
        try:  # an integer too large for a float (400 digits) is not finite either
            finite = not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(float(value))
        except OverflowError:
            finite = False
        if not finite:
            raise InputError(path, f"solution value of {quoted(name, 60)} is {json.dumps(value)[:40]}, expected a finite number")
    seed = document.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise InputError(path, f"not a bcad result: its seed is {json.dumps(seed)[:40]}, expected a non-negative integer")
    return {str(name): float(value) for name, value in solution.items()}, seed


# --- the Python API ------------------------------------------------------------------------


#: the most samples an API call may ask for (the schema's bound on posterior_samples)
MAX_API_SAMPLES = 1_000_000_000


def _finite_values(values: dict) -> bool:
    """Whether every entry maps a name to a real number of at most 1e9 in size (a NaN, an
    infinity and a 5000-digit integer are not; the comparison is exact for any integer)."""
    return all(isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool) and abs(v) <= 1e9
               for k, v in values.items())


def _check_count(value, name: str, low: int, high: int, call: str, optional: bool = False) -> int | None:
    """A whole number in [low, high] (a float with no fraction passes, as 1e5 does), else InputError."""
    if optional and value is None:
        return None
    number = value
    if isinstance(value, float) and value.is_integer():
        number = int(value)
    if isinstance(number, bool) or not isinstance(number, (int, np.integer)) or not low <= number <= high:
        raise InputError(f"bcad.{call}", f"{name} is {shown(value)}; expected a whole number in [{low:g}, {high:g}]")
    return int(number)


def _check_choice(value, name: str, choices: tuple[str, ...], call: str, optional: bool = False) -> str | None:
    if optional and value is None:
        return None
    if not isinstance(value, str) or value not in choices:
        raise InputError(f"bcad.{call}", f"{name} is {shown(value)}; expected one of {', '.join(choices)}")
    return value


def _check_path(value, name: str, call: str) -> Path | None:
    if value is None:
        return None
    if not isinstance(value, (str, Path)) or not str(value).strip():
        raise InputError(f"bcad.{call}", f"{name} is {shown(value)}; expected a file's path (str or pathlib.Path)")
    return Path(value)


def load(source: str | Path | dict) -> Problem:
    """A problem from a YAML file (path) or from a mapping of the same keys (``dict``).

    Paths in a mapping (``urdf``, ``data``) are relative to the current folder. Raises
    :class:`InputError` naming the file and line of anything wrong.
    """
    from bcad.model.problem import load as load_any

    return load_any(source)


def compile(problem: Problem | str | Path | dict) -> CompiledProblem:  # noqa: A001 (bcad.compile)
    """The probabilistic kinematic graph of a problem (Sect. 3.1 of the 2000 paper)."""
    from bcad.compiler.problem import compile_any

    return compile_any(problem)


def compile_with_calibrations(problem, calibration=(), call: str = "bcad") -> CompiledProblem:
    """The compiled problem, with ``calibration`` results (paths) added to its ``calibration:``,
    as ``--calibration`` adds them (the command and the API both come here)."""
    if isinstance(calibration, (str, Path)) or not isinstance(calibration, (list, tuple)):
        raise InputError(f"bcad.{call}", f"calibration is {shown(calibration)}; expected a list of result paths")
    paths = [_check_path(path, "calibration", call) for path in calibration]
    if not paths:
        return compile(problem)
    for path in paths:
        if not path.exists():
            raise InputError(path, "no such file (a bcad calibrate result)")
    loaded = load(problem)
    # model_copy keeps the source document (error positions, relative paths)
    return compile(loaded.model_copy(update={"calibration": [*loaded.calibration, *(str(p.absolute()) for p in paths)]}))


def _inputs_of(problem, compiled: CompiledProblem) -> list[Path]:
    """The files a call read that no output may replace: the problem's and its calibrations'."""
    return ([Path(problem)] if isinstance(problem, (str, Path)) else []) + [Path(p) for p in compiled.calibration.files]


def _samples_kept(samples_out, count: int, call: str) -> tuple[Path | None, dict | None]:
    """``samples_out``'s path and the dict that collects the samples (None, None without it)."""
    if samples_out is None:
        return None, None
    path = _check_path(samples_out, "samples_out", call)
    if count > MAX_SAMPLES_OUT:
        raise InputError(f"bcad.{call}", f"samples_out keeps at most {MAX_SAMPLES_OUT:.0e} samples in memory; lower samples")
    from bcad.io import check_output

    check_output(path)
    return path, {}


@dataclass(frozen=True)
class ClosingLink:
    """The posterior of one closing link's pose Q (Eq. 1), in the problem's units (Table 2)."""

    name: str
    parent: str
    child: str
    parameters: tuple[str, ...]
    mean: np.ndarray  # the prior's propagation: Q under L ~ p(L)
    std: np.ndarray
    weighted_mean: np.ndarray  # the posterior: weighted by the closing link's distributions and relation
    weighted_std: np.ndarray
    effective_samples: float | None
    satisfied: float | None  # fraction of prior samples meeting the relation's inequalities


@dataclass
class Result:
    """A result of :func:`solve`, :func:`posterior`, :func:`maxerror` or :func:`calibrate`: the JSON
    document of the matching command, with typed views of its parts."""

    kind: str
    document: dict
    #: calibrate: the calibrated robots' URDF texts, by robot name
    urdf: dict[str, str] = field(default_factory=dict)

    @property
    def typed(self):
        """The document as its family's typed model (:class:`bcad.bayes.result.DesignResult`,
        :class:`bcad.worstcase.result.MaxErrorResult`, :class:`bcad.calibration.result.CalibrationResult`):
        ``result.typed.rotation.upper_bound``. Its fields are also the result's own:
        ``worst.rotation.upper_bound``, ``cal.check``."""
        try:
            return self.__dict__["_typed"]
        except KeyError:
            typed = self.__dict__["_typed"] = result_model(self.document["kind"]).model_validate(self.document)
            return typed

    def __getattr__(self, name: str):
        if name.startswith("_") or name in ("kind", "document", "urdf"):
            raise AttributeError(name)
        typed = self.typed
        if name in type(typed).model_fields or name in (typed.model_extra or {}):
            return getattr(typed, name)
        raise AttributeError(f"a {self.kind} result has no {name!r}")

    def to_json(self) -> str:
        """The document as the command writes it (indented JSON, no NaN)."""
        from bcad.io import json_text

        return json_text(self.document)

    @property
    def warnings(self) -> list[dict]:
        return list(self.document.get("warnings", []))

    @property
    def trusted(self) -> bool:
        """No warning: the command would exit 0."""
        return not self.warnings

    @property
    def solution(self) -> dict[str, float]:
        """X by name (solve and posterior)."""
        return dict(self.document.get("solution", {}))

    @property
    def log_objective(self) -> tuple[float | None, float | None]:
        """log p(X) I(X) and its standard error (Eq. 2)."""
        objective = self.document.get("objective", {})
        return objective.get("log_value"), objective.get("log_value_se")

    @property
    def links(self) -> dict[str, ClosingLink]:
        """Each closing link's posterior (solve and posterior)."""
        out = {}
        for name, link in self.document.get("posterior", {}).get("links", {}).items():
            weighted = link.get("weighted") or {}
            out[name] = ClosingLink(
                name, link["parent"], link["child"], tuple(link["params"]), np.array(link["mean"], dtype=float),
                np.array(link["std"], dtype=float), np.array(weighted.get("mean", link["mean"]), dtype=float),
                np.array(weighted.get("std", link["std"]), dtype=float), link.get("effective_samples"), link.get("satisfied"),
            )
        return out

    @property
    def parameters(self) -> dict[str, dict]:
        """Calibrated parameters by name (calibrate)."""
        return dict(self.document.get("parameters", {}))

    def table(self):
        """The command's table (a rich renderable; shown as HTML in notebooks)."""
        from bcad import report

        if self.kind == "maxerror":
            return report.maxerror_table(self.document, self.document["units"])
        if self.kind == "calibrate":
            from bcad.calibration.report import calibration_table

            return calibration_table(self.document)
        return report.posterior_table(self.document)

    def _repr_html_(self) -> str:
        import io

        from rich.console import Console

        console = Console(file=io.StringIO(), record=True, width=120, markup=False, emoji=False)
        console.print(self.table())
        return console.export_html(inline_styles=True)


def solve(problem, *, seed: int = 0, backend: str = "bayes", samples: int | None = None,
          estimator: str | None = None, progress: Callable | None = None, calibration: list[str | Path] = (),
          samples_out: str | Path | None = None) -> Result:
    """X* = argmax p(X) I(X) (Eq. 2) and the closing links' posterior there, as ``bcad solve``.
    ``calibration``: results of ``bcad calibrate`` whose posterior replaces the L they name;
    ``samples_out``: also write the posterior samples there (.npz, as ``--samples-out``);
    ``progress(phase, temperature, samples, best)``: called as the run goes, with ``phase`` one of
    the genetic algorithm's phases, ``"search"``, or ``"posterior"`` (``samples``: drawn so far)."""
    from bcad.model.solver import ESTIMATORS

    _check_choice(backend, "backend", ("bayes", "nominal"), "solve")
    seed = _check_count(seed, "seed", 0, 2**63 - 1, "solve")
    samples = _check_count(samples, "samples", 1, MAX_API_SAMPLES, "solve", optional=True)
    _check_choice(estimator, "estimator", ESTIMATORS, "solve", optional=True)
    if progress is not None and not callable(progress):
        raise InputError("bcad.solve", f"progress is {shown(progress)}; expected a callable or None")
    compiled = compile_with_calibrations(problem, calibration, "solve")
    path, kept = _samples_kept(samples_out, samples or compiled.problem.solver.posterior_samples, "solve")
    result = Result("solve", solve_document(compiled, backend=backend, seed=seed, posterior_samples=samples,
                                            estimator=estimator, progress=progress, kept=kept,
                                            samples_option="bcad.solve: samples"))
    if path is not None:
        write_samples(compiled, kept, path, _inputs_of(problem, compiled))
    return result


def posterior(problem, *, at: Result | dict | str | Path | None = None, values: dict[str, float] | None = None,
              samples: int | None = None, seed: int = 0, estimator: str | None = None,
              calibration: list[str | Path] = (), samples_out: str | Path | None = None) -> Result:
    """The closing links' posterior (Table 2) and the objective's estimate at a given X, as
    ``bcad posterior``: X from ``at`` (a result, its document or its file) and/or ``values``;
    ``samples`` (default: the problem's ``solver.posterior_samples``, as :func:`solve`'s posterior),
    ``calibration`` and ``samples_out`` as :func:`solve`'s."""
    from bcad.model.solver import ESTIMATORS

    samples = _check_count(samples, "samples", 1, MAX_API_SAMPLES, "posterior", optional=True)
    seed = _check_count(seed, "seed", 0, 2**63 - 1, "posterior")
    _check_choice(estimator, "estimator", ESTIMATORS, "posterior", optional=True)
    if at is not None and not isinstance(at, (Result, dict)):
        at = _check_path(at, "at (a result, its document or its file)", "posterior")
    if values is not None and (not isinstance(values, dict) or not _finite_values(values)):
        raise InputError("bcad.posterior", "values must map X names (str) to finite numbers of at most 1e9")
    from bcad.bayes.model import check_solvable
    from bcad.results import solution_from_dict

    compiled = compile_with_calibrations(problem, calibration, "posterior")
    check_solvable(compiled, needs_unknowns=False)
    solution: dict[str, float] = {}
    if isinstance(at, Result):
        solution = at.solution
    elif isinstance(at, dict):
        solution = at.get("solution", at)
        if not isinstance(solution, dict) or not _finite_values(solution):
            raise InputError("bcad.posterior", "at: its solution must map X names (str) to finite numbers of at most 1e9")
        solution = dict(solution)
    elif at is not None:
        solution, _ = read_result(Path(at))
    solution.update(values or {})
    names = compiled.parameters.x_names
    unknown = [name for name in solution if name not in names]
    missing = [name for name in names if name not in solution]
    if unknown or missing:
        problem_text = (f"unknown X parameter(s) {', '.join(quoted(name, 60) for name in unknown[:5])}" if unknown
                        else f"no value for X parameter(s) {', '.join(missing)}")
        raise InputError(compiled.problem.source.path, problem_text)
    x = solution_from_dict(compiled, solution)
    compiled.check_unknowns(x, at if isinstance(at, (str, Path)) else "bcad.posterior")
    path, kept = _samples_kept(samples_out, samples or compiled.problem.solver.posterior_samples, "posterior")
    result = Result("posterior", posterior_document(compiled, x, samples=samples, seed=seed, estimator=estimator, kept=kept,
                                                        samples_option="bcad.posterior: samples"))
    if path is not None:
        write_samples(compiled, kept, path, _inputs_of(problem, compiled))
    return result


def maxerror(problem, *, tol: float = 1e-6, model: str = "first-order", samples: int | None = None, seed: int = 0,
             spec: str | dict[str, float] | None = None, allocate: str | dict[str, float] | None = None,
             weights: str | list[float] | None = None) -> Result:
    """The certified largest end-effector errors that joint clearances can cause, as ``bcad maxerror``
    (``problem``: a clearance problem's path, mapping or loaded model). ``spec``: the yield of a
    spec (``{"translation": 0.0004}`` or ``"rotation=R,dx=D"``, problem units; 1e5 samples unless
    ``samples`` says); ``allocate``: the largest clearance scale whose exact errors meet a spec,
    with per-joint ``weights``."""
    from bcad.model.clearance import (
        ChainProblem,
        chain_problem_from_document,
        clearance_weights,
        load_chain_problem,
        spec_limits,
    )

    if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not 1e-9 <= tol < 1.0:
        raise InputError("bcad.maxerror", f"tol is {shown(tol)}; expected a relative gap in [1e-9, 1)")
    _check_choice(model, "model", ("first-order", "exact"), "maxerror")
    samples = _check_count(samples, "samples", 1, MAX_API_SAMPLES, "maxerror", optional=True)
    seed = _check_count(seed, "seed", 0, 2**63 - 1, "maxerror")
    if isinstance(problem, dict):
        problem = chain_problem_from_document(SourceDocument(path=Path("<dict>"), data=problem))
    elif not isinstance(problem, ChainProblem):
        if problem is None:
            raise InputError("bcad.maxerror", "problem is None; expected a clearance problem's path, mapping or loaded model")
        problem = load_chain_problem(_check_path(problem, "problem", "maxerror"))
    limits = None if spec is None else spec_limits(spec, "bcad.maxerror: spec")
    allocation = None if allocate is None else spec_limits(allocate, "bcad.maxerror: allocate")
    factors = None if weights is None else clearance_weights(weights, "bcad.maxerror: weights")
    if factors is not None and allocation is None:
        raise InputError("bcad.maxerror", "weights scale the clearances of allocate; give allocate too")
    if limits is not None and samples is None:
        samples = 100_000
    return Result("maxerror", maxerror_document(problem, tol=tol, model=model, samples=samples, seed=seed, spec=limits,
                                                allocate=allocation, weights=factors))


def calibrate(problem, *, robust: bool = False, check_samples: int | None = None, seed: int = 0, propose: int = 0,
              candidates: str | Path | None = None, predict: str | Path | None = None,
              task: str | Path | None = None) -> Result:
    """Identify a cell's parameters from its measurements, as ``bcad calibrate``. The
    calibrated robots' URDF texts are in ``result.urdf`` by robot name, the calibrated cameras in
    ``result.document["cameras"]`` (``bcad.model.camera_info.camera_info_text`` writes one as
    ROS camera_info YAML, as ``--camera-info`` does)."""
    if not isinstance(robust, bool):
        raise InputError("bcad.calibrate", f"robust is {shown(robust)}; expected True or False")
    # None: DEFAULT_CHECK_SAMPLES, fewer for a large file (check_sample_count)
    check_samples = _check_count(check_samples, "check_samples", 0, MAX_API_SAMPLES, "calibrate", optional=True)
    seed = _check_count(seed, "seed", 0, 2**63 - 1, "calibrate")
    propose = _check_count(propose, "propose", 0, 100_000, "calibrate")
    candidates, predict, task = (_check_path(v, n, "calibrate") for v, n in ((candidates, "candidates"), (predict, "predict"), (task, "task")))
    if propose and candidates is None:
        raise InputError("bcad.calibrate", "propose needs candidates (a CSV file of configurations)")
    compiled = compile(problem)
    document, texts = calibration_run(compiled, robust=robust, check_samples=check_samples, seed=seed,
                                      propose=propose, candidates=candidates, urdf=bool(compiled.problem.robots),
                                      predict=None if predict is None else Path(predict),
                                      task=None if task is None else Path(task))
    return Result("calibrate", document, texts)
