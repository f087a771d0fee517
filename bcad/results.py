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


def posterior_to_dict(compiled: CompiledProblem, links: list[LinkPosterior], samples: int) -> dict:
    scale = _pose_scales(compiled)

    def vector(values):
        return None if values is None else [_number(v) for v in np.asarray(values) * scale]

    return {
        "samples": samples,
        "links": {
            link.name: {
                "parent": link.parent,
                "child": link.child,
                "params": list(PARAMETERS),
                "mean": vector(link.mean),
                "std": vector(link.std),
                "constrained": link.constrained,
                "weighted": {"mean": vector(link.weighted_mean), "std": vector(link.weighted_std)},
                "effective_samples": _number(link.effective_samples),
                "satisfied": link.satisfied,
            }
            for link in links
        },
    }


def arm_reaches(compiled: CompiledProblem, **solutions: np.ndarray) -> dict[str, dict[str, float | str]]:
    """Distance from each robot's base frame to its wrist frame at each named solution
    (``bayes=x, nominal=x``), every L at nominal."""
    nominal_samples = Samples(np.zeros((1, len(compiled.parameters.l))))
    reaches: dict[str, dict[str, float | str]] = {
        robot.name: {"base_frame": robot.base_frame, "wrist_frame": robot.wrist_frame} for robot in compiled.robots
    }
    for label, x in solutions.items():
        transforms = compiled.frame_transforms(x, nominal_samples)
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


def result_document(
    compiled: CompiledProblem,
    *,
    seed: int,
    backend: str,
    x: np.ndarray,
    posterior: PosteriorSummary,
    samples: int,
    diagnostics: dict,
    seconds: float,
) -> dict:
    diagnostics = {**diagnostics, "effective_samples": _number(posterior.effective_samples)}
    return {
        "problem": compiled.problem.name,
        "bcad_version": __version__,
        "seed": seed,
        "backend": backend,
        "units": compiled.problem.units.model_dump(),
        "stats": {**compiled.stats.as_dict(), "seconds": round(seconds, 3)},
        "solution": solution_to_dict(compiled, x),
        "objective": {"log_value": _number(posterior.log_value), "samples": samples},
        "posterior": posterior_to_dict(compiled, posterior.links, samples),
        "diagnostics": diagnostics,
    }


def solve(
    compiled: CompiledProblem,
    *,
    backend: str,
    seed: int,
    posterior_samples: int | None = None,
    progress: Callable | None = None,
) -> dict:
    """Run a backend, sample the posterior at its solution and build the result document."""
    from bcad.solvers.bayes import check_solvable, solve_bayes
    from bcad.solvers.nominal import solve_nominal

    start = time.perf_counter()
    settings = compiled.problem.solver
    check_solvable(compiled)
    n = posterior_samples or settings.posterior_samples
    objective = Objective(compiled)
    nominal = solve_nominal(compiled, objective, stream(seed, "nominal"))
    nominal_summary = {
        "solution": solution_to_dict(compiled, nominal.x),
        "closed": nominal.closed,
        "cost": _number(nominal.cost),
        "starts": nominal.starts,
    }
    timings: dict[str, float] = {"nominal": time.perf_counter() - start}
    if backend == "nominal":
        posterior = posterior_at(compiled, {"nominal": nominal.x}, n, seed)["nominal"]
        diagnostics = {
            "nominal": {key: nominal_summary[key] for key in ("closed", "cost", "starts")},
            "arms": arm_reaches(compiled, nominal=nominal.x),
        }
        x = nominal.x
    else:
        solution = solve_bayes(compiled, settings, seed, progress)
        timings.update(solution.timings)
        started = time.perf_counter()
        both = posterior_at(compiled, {"bayes": solution.x, "nominal": nominal.x}, n, seed)
        posterior = both["bayes"]
        timings["posterior"] = time.perf_counter() - started
        genetic = solution.genetic
        diagnostics = {
            "genetic": {
                "initial_temperature": genetic.initial_temperature,
                "generations": len(genetic.trace),
                "evaluations": genetic.evaluations,
                "sample_evaluations": genetic.sample_evaluations,
                "best_log_value": _number(genetic.best_log_value),
            },
            "refinement": None
            if solution.refinement is None
            else {
                "start_log_value": _number(solution.refinement.start_log_value),
                "log_value": _number(solution.refinement.log_value),
                "iterations": solution.refinement.iterations,
                "samples": settings.refine_samples,
            },
            "selection": {key: _number(value) for key, value in solution.selection.items()},
            "nominal_comparison": {
                **nominal_summary,
                "log_objective": _number(both["nominal"].log_value),
                "posterior_std_ratio": std_ratios(both["nominal"].links, posterior.links),
            },
            "arms": arm_reaches(compiled, bayes=solution.x, nominal=nominal.x),
        }
        x = solution.x
    diagnostics["timings"] = {key: round(value, 3) for key, value in timings.items()}
    return result_document(
        compiled, seed=seed, backend=backend, x=x, posterior=posterior, samples=n,
        diagnostics=diagnostics, seconds=time.perf_counter() - start,
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
    document = {"problem": problem.name, "model": "first-order"}
    for kind in ("rotation", "translation"):
        found = certified_maximum(error_map, kind, tol)
        scale = per_angle if kind == "rotation" else 1.0
        # A change of unit rounds: step the bounds outward so they stay bounds.
        entry = {
            "max": float(np.nextafter(found.max * scale, -np.inf)) if scale != 1.0 else found.max,
            "upper_bound": float(np.nextafter(found.upper_bound * scale, np.inf)) if scale != 1.0 else found.upper_bound,
            "argmax": (found.argmax * screw_scale).tolist(),
            "seconds": round(found.seconds, 4),
        }
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
    return document
