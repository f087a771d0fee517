"""From a solved problem to the result document (JSON) and its tables.

The result of ``bcad solve``:

    {"problem", "bcad_version", "seed", "backend", "units",
     "stats": Table 1 + "seconds",
     "solution": {X name: value},
     "objective": {"log_value", "samples"},
     "posterior": {"samples", "links": {NAME: {"parent", "child", "params",
                   "mean", "std", "constrained", "weighted": {...},
                   "effective_samples", "satisfied"}}},
     "diagnostics": {...}}

Values are in the problem's units. Everything but the timings ("seconds"
and "diagnostics.timings") is the same, byte for byte, for the same seed.
"""

from __future__ import annotations

import math
import time
from typing import Callable

import numpy as np

from bcad import __version__
from bcad.bayes.estimators import Estimators, ObjectiveEstimate
from bcad.compile import CompiledProblem
from bcad.compile.units import angle_scale
from bcad.kinematics.chain import Samples
from bcad.model.pose import LENGTH_PARAMETERS, PARAMETERS
from bcad.solvers.objective import Objective
from bcad.solvers.posterior import LinkPosterior, PosteriorSummary, sample_posteriors
from bcad.solvers.seeding import stream


def _number(value: float) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


def _parameter_scales(compiled: CompiledProblem, names: list[str]) -> np.ndarray:
    """Factors from internal units (rad) to the problem's units, per parameter name."""
    per_angle = 1.0 / angle_scale(compiled.problem.units)
    return np.array([1.0 if name.rsplit(".", 1)[1] in LENGTH_PARAMETERS else per_angle for name in names])


def solution_to_dict(compiled: CompiledProblem, x: np.ndarray) -> dict[str, float]:
    names = compiled.parameters.x_names
    return {name: float(value) for name, value in zip(names, np.asarray(x) * _parameter_scales(compiled, names))}


def solution_from_dict(compiled: CompiledProblem, values: dict[str, float]) -> np.ndarray:
    names = compiled.parameters.x_names
    return np.array([values[name] for name in names], dtype=float) / _parameter_scales(compiled, names)


def _pose_scales(compiled: CompiledProblem) -> np.ndarray:
    per_angle = 1.0 / angle_scale(compiled.problem.units)
    return np.array([1.0 if name in LENGTH_PARAMETERS else per_angle for name in PARAMETERS])


def posterior_to_dict(compiled: CompiledProblem, links: list[LinkPosterior], samples: int,
                      estimate: ObjectiveEstimate | None = None) -> dict:
    """Table 2 per closing link, with standard errors. The weighted posterior and its effective
    sample size are the plain Monte Carlo pass's, or ``estimate``'s where another estimator
    (importance or linear) made it."""
    better = estimate is not None and estimate.estimator != "mc"
    scale = _pose_scales(compiled)

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
                ) if better else _number(link.effective_samples),
                "satisfied": link.satisfied,
            }
            for k, link in enumerate(links)
        },
    }


def arm_reaches(compiled: CompiledProblem, **solutions: np.ndarray) -> dict[str, dict[str, float | str]]:
    """Distance from each robot's base frame to its wrist frame at each named solution
    (``bayes=x, nominal=x``), every L at nominal."""
    nominal_samples = Samples(np.zeros((1, len(compiled.parameters.l))))
    reaches: dict[str, dict[str, float | str]] = {
        robot.name: {"base_frame": robot.base_frame, "wrist_frame": robot.wrist_frame} for robot in compiled.robots
    }
    frames = [frame for robot in compiled.robots for frame in (robot.base_frame, robot.wrist_frame)]
    for label, x in solutions.items():
        transforms = compiled.frame_transforms(x, nominal_samples, frames)
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


def posterior_at(compiled: CompiledProblem, solutions: dict[str, np.ndarray], samples: int, seed: int) -> dict[str, PosteriorSummary]:
    """The posterior at each named X on one set of samples from the seed's "posterior" stream,
    so ``bcad posterior --seed S`` reproduces what ``bcad solve --seed S`` reported."""
    return sample_posteriors(compiled, solutions, samples, stream(seed, "posterior"), compiled.problem.solver.qmc)


def objective_to_dict(estimate: ObjectiveEstimate) -> dict:
    return {
        "estimator": estimate.estimator,
        "log_value": _number(estimate.log_value),
        "log_value_se": _number(estimate.log_value_se),
        "samples": estimate.samples,
        "effective_samples": None if estimate.effective_samples is None else _number(estimate.effective_samples),
        "pareto_k": None if estimate.pareto_k is None else _number(estimate.pareto_k),
    }


def monte_carlo_estimate(posterior: PosteriorSummary, samples: int) -> ObjectiveEstimate:
    """The paper's estimate (Sect. 4.1.2): the prior samples of the posterior pass, weighted by the integrand."""
    return ObjectiveEstimate(
        "mc", posterior.log_value, posterior.log_value_se, samples, posterior.effective_samples, posterior.pareto_k,
        [link.weighted for link in posterior.links],
    )


def estimate_at(estimators, x: np.ndarray, posterior: PosteriorSummary, samples: int, estimator: str,
                rng: np.random.Generator) -> ObjectiveEstimate:
    """log p(X) I(X) and the weighted posteriors at X by the chosen estimator."""
    if estimator == "mc":
        return monte_carlo_estimate(posterior, samples)
    return estimators.estimate(x, estimator, samples, rng)


def contributors_to_dict(compiled: CompiledProblem, linear, x: np.ndarray) -> dict:
    """Per scored parameter of each closing link: the share of its linearised variance
    J Sigma_L J^T that each L parameter contributes, summed per link and per robot."""
    from bcad.bayes.contributors import variance_shares

    return variance_shares(compiled, linear, x, _parameter_scales)


def result_document(
    compiled: CompiledProblem,
    *,
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
) -> dict:
    document = {
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
    document["diagnostics"] = diagnostics
    return document


def posterior_document(compiled: CompiledProblem, x: np.ndarray, *, samples: int, seed: int,
                       estimator: str | None = None) -> dict:
    """The result of ``bcad posterior``: Table 2 and the objective's estimate at a given X."""
    from bcad.bayes.trust import result_warnings

    start = time.perf_counter()
    estimator = estimator or compiled.problem.solver.estimator
    objective = Objective(compiled)
    estimators = Estimators(compiled, objective)
    posterior = posterior_at(compiled, {"x": x}, samples, seed)["x"]
    estimate = estimate_at(estimators, x, posterior, samples, estimator, stream(seed, "importance"))
    return result_document(
        compiled, seed=seed, backend="posterior", x=x, posterior=posterior, estimate=estimate, samples=samples,
        diagnostics={}, seconds=time.perf_counter() - start,
        contributors=contributors_to_dict(compiled, estimators.linear, x),
        warnings=result_warnings(compiled, estimators.linear, x, posterior, estimate),
    )


def solve(
    compiled: CompiledProblem,
    *,
    backend: str,
    seed: int,
    posterior_samples: int | None = None,
    estimator: str | None = None,
    progress: Callable | None = None,
) -> dict:
    """Run a backend, estimate the objective and sample the posterior at its solution, and build
    the result document (with its warnings: :mod:`bcad.bayes.trust`)."""
    from bcad.bayes.trust import result_warnings
    from bcad.solvers.bayes import check_solvable, solve_bayes
    from bcad.solvers.nominal import solve_nominal

    start = time.perf_counter()
    settings = compiled.problem.solver
    if estimator is not None:
        settings = settings.model_copy(update={"estimator": estimator})
    check_solvable(compiled)
    n = posterior_samples or settings.posterior_samples
    objective = Objective(compiled)
    estimators = Estimators(compiled, objective)
    nominal = solve_nominal(compiled, objective, stream(seed, "nominal"))
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
        posterior = posterior_at(compiled, {"nominal": x}, n, seed)["nominal"]
        estimate = estimate_at(estimators, x, posterior, n, settings.estimator, stream(seed, "importance"))
        timings["posterior"] = time.perf_counter() - started
    else:
        diagnostics = {}
        if settings.estimator == "mc":
            solution = solve_bayes(compiled, settings, seed, progress)
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
            solution = estimators.solve(settings, seed, nominal.x)
            x = solution.x
            diagnostics["search"] = {
                "starts": len(solution.maxima),
                "maxima": [_number(m.log_value) for m in solution.maxima],
                "iterations": [m.iterations for m in solution.maxima],
                "finalists": [
                    {"linear_log_value": _number(f["linear_log_value"]), "log_value": _number(f["log_value"]),
                     "log_value_se": _number(f["log_value_se"])}
                    for f in solution.finalists
                ],
            }
        timings.update(solution.timings)
        started = time.perf_counter()
        both = posterior_at(compiled, {"bayes": x, "nominal": nominal.x}, n, seed)
        posterior = both["bayes"]
        estimate = estimate_at(estimators, x, posterior, n, settings.estimator, stream(seed, "importance"))
        nominal_estimate = estimate_at(
            estimators, nominal.x, both["nominal"], min(n, settings.finalist_samples),
            settings.estimator, stream(seed, "importance-nominal"),
        )
        timings["posterior"] = time.perf_counter() - started
        comparison = nominal_estimate
        diagnostics["nominal_comparison"] = {
            **nominal_summary,
            "log_objective": _number(nominal_estimate.log_value),
            "log_objective_se": _number(nominal_estimate.log_value_se),
            "posterior_std_ratio": std_ratios(both["nominal"].links, posterior.links),
        }
        diagnostics["arms"] = arm_reaches(compiled, bayes=x, nominal=nominal.x)
    diagnostics["timings"] = {key: round(value, 3) for key, value in timings.items()}
    warnings = result_warnings(compiled, estimators.linear, x, posterior, estimate, comparison)
    return result_document(
        compiled, seed=seed, backend=backend, x=x, posterior=posterior, estimate=estimate, samples=n,
        diagnostics=diagnostics, seconds=time.perf_counter() - start,
        contributors=contributors_to_dict(compiled, estimators.linear, x), warnings=warnings,
    )


def maxerror_document(problem, *, tol: float, model: str, samples: int | None = None, seed: int = 0) -> dict:
    """The result of ``bcad maxerror``: certified first-order maxima, optionally the exact
    model's local maximum and the statistics of uniformly distributed clearances."""
    from bcad.compile.error_map import build_error_map
    from bcad.solvers.maxerror import certified_maximum

    error_map = build_error_map(problem)
    per_angle = 1.0 / angle_scale(problem.units)
    # Screw units: dr in the problem's angle unit, dt in its length unit.
    screw_scale = np.array([per_angle] * 3 + [1.0] * 3)
    document = {"problem": problem.name, "model": "first-order", "units": problem.units.model_dump()}
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
        if model == "exact":
            from bcad.solvers.exact_error import exact_local_maximum

            search = exact_local_maximum(error_map, found.argmax, kind)
            entry["exact"] = {
                "max": search.max * scale,
                "argmax": (search.argmax * screw_scale).tolist(),
                "at_first_order_argmax": search.start_value * scale,
                "relative_to_first_order": search.max / found.max - 1.0 if found.max > 0 else 0.0,
            }
        document[kind] = entry
    if model == "exact":
        document["model"] = "exact"
    if samples:
        from bcad.solvers.clearance_statistics import error_statistics

        statistics = error_statistics(error_map, problem.name, problem.units.length, samples, stream(seed, "clearance"))
        for value in statistics["rotation"]:
            statistics["rotation"][value] *= per_angle
        document["statistics"] = statistics
    document["warnings"] = warnings
    return document
