"""The Bayesian family's run: search X* (or take it), estimate log p(X) I(X) there, sample the
closing links' posterior and build the result document (:class:`bcad.bayes.result.DesignResult`),
checked against its model before it leaves."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from bcad.arguments import Spelling
from bcad.bayes.arguments import MAX_SAMPLES_OUT, RunOptions, samples_kept
from bcad.numerics.seeding import stream

if TYPE_CHECKING:
    from bcad.bayes.estimators import ObjectiveEstimate
    from bcad.bayes.model import BayesModel
    from bcad.bayes.posterior import PosteriorSummary
    from bcad.compiler import CompiledProblem


def write_samples(compiled: CompiledProblem, kept: dict[str, np.ndarray], path: Path, protected) -> None:
    """``--samples-out``: the posterior samples as a numpy .npz, in the problem's units.

    Arrays: ``LINK/poses`` (N, 6) of each closing link (tx ty tz rx ry rz), ``LINK/log_weights``
    (N,) its own weight (its distributions and relation), ``log_weights`` (N,) the sample's whole
    weight (the integrand of Eq. 2: every closing link and tree relation); ``parameters`` and
    ``units``. The weighted posterior is the samples weighted by exp(log_weights). Angles are
    unwrapped about their circular mean (they may leave (-pi, pi]), so that the plain mean and
    std of the file are the document's.
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
        "mc",
        posterior.log_value,
        posterior.log_value_se,
        samples,
        posterior.effective_samples,
        posterior.pareto_k,
        [link.weighted for link in posterior.links],
    )


def posterior_and_estimate(
    model: BayesModel,
    x: np.ndarray,
    samples: int,
    estimator: str,
    posterior_rng: np.random.Generator,
    importance_rng: np.random.Generator,
    keep: dict | None = None,
    progress: Callable | None = None,
) -> tuple[PosteriorSummary, ObjectiveEstimate]:
    """The posterior at X (``samples`` prior samples, ``keep`` and ``progress``: :func:`sample_posteriors`) and
    log p(X) I(X) by the estimator. The ``mc`` estimate is read off that posterior. The
    ``importance`` one starts its proposal from the posterior's own prior draws, chunk by chunk
    (:func:`bcad.bayes.posterior.posterior_and_importance`), the chunks on two threads (numpy
    releases the GIL in its loops; each chunk has its own random streams and the sums are taken
    in order, so the results do not depend on the threads); with a ``qmc`` prior, whose Sobol
    sequence runs through the chunks in order, and for the ``linear`` estimator the estimate runs
    beside the posterior: one thread samples the posterior, the other the estimate's chunks, and
    the first takes the chunks left when it is done."""
    from concurrent.futures import ThreadPoolExecutor

    from bcad.bayes.estimators import estimate as estimate_objective
    from bcad.bayes.estimators import importance_estimate
    from bcad.bayes.posterior import posterior_and_importance, sample_posteriors

    if estimator == "mc":
        posterior = sample_posteriors(model, {"x": x}, samples, posterior_rng, keep, progress)["x"]
        return posterior, monte_carlo_estimate(posterior, samples)
    if estimator == "importance" and not model.sampler.qmc:
        # one pass over shared prior draws (posterior_and_importance), its chunks on two threads
        with ThreadPoolExecutor(max_workers=2) as pool:
            posterior, found = posterior_and_importance(
                model, x, samples, posterior_rng, importance_rng, (keep or {}).get("x"), progress, pool
            )
        return posterior, importance_estimate(model, x, found)
    with ThreadPoolExecutor(max_workers=2) as pool:
        posterior_job = pool.submit(sample_posteriors, model, {"x": x}, samples, posterior_rng, keep, progress)
        estimate = estimate_objective(model, x, estimator, samples, importance_rng, pool)
        return posterior_job.result()["x"], estimate


def posterior_document(
    compiled: CompiledProblem,
    x: np.ndarray,
    *,
    samples: int | None,
    seed: int,
    estimator: str | None = None,
    kept: dict | None = None,
    model: BayesModel | None = None,
    samples_option: str = "--samples",
    progress: Callable | None = None,
) -> dict:
    """The result of ``bcad posterior``: Table 2 and the objective's estimate at a given X (on
    the problem's model where the caller has built it); ``samples_option`` names the count's
    source in the message that refuses too many; ``progress(done, samples)`` follows the
    posterior's samples."""
    from bcad.bayes.document import contributors_to_dict, result_document
    from bcad.bayes.model import BayesModel
    from bcad.bayes.solvable import check_solvable
    from bcad.bayes.trust import design_findings, gimbal_findings, result_warnings
    from bcad.bayes.work import check_posterior_work

    start = time.perf_counter()
    check_solvable(compiled, needs_unknowns=False)
    if samples is None:  # the problem's solver.posterior_samples, as solve's posterior
        samples, samples_option = compiled.problem.solver.posterior_samples, None
    check_posterior_work(compiled, samples, samples_option)
    estimator = estimator or compiled.problem.solver.estimator
    model = model or BayesModel(compiled)
    keep = {"x": kept} if kept is not None else None
    posterior, estimate = posterior_and_estimate(
        model, x, samples, estimator, stream(seed, "posterior"), stream(seed, "importance"), keep, progress
    )
    from bcad.bayes.result import DesignResult
    from bcad.model.results import checked

    return checked(
        result_document(
            compiled,
            kind="posterior",
            seed=seed,
            backend="posterior",
            x=x,
            posterior=posterior,
            estimate=estimate,
            samples=samples,
            diagnostics={},
            seconds=time.perf_counter() - start,
            contributors=contributors_to_dict(compiled, model.linear, x),
            warnings=result_warnings(posterior, estimate),
            findings=design_findings(compiled, model.linear, x) + gimbal_findings(posterior),
        ),
        DesignResult,
    )


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
    from bcad.bayes.document import (
        _number,
        arm_reaches,
        contributors_to_dict,
        result_document,
        search_to_dict,
        solution_to_dict,
        std_ratios,
    )
    from bcad.bayes.estimators import solve as solve_by_search
    from bcad.bayes.genetic_search import solve_bayes
    from bcad.bayes.model import BayesModel
    from bcad.bayes.nominal import solve_nominal
    from bcad.bayes.solvable import check_solvable
    from bcad.bayes.trust import design_findings, gimbal_findings, result_warnings, search_findings
    from bcad.bayes.work import check_posterior_work, check_search_work

    start = time.perf_counter()
    settings = compiled.problem.solver
    if estimator is not None:
        settings = settings.model_copy(update={"estimator": estimator})
    check_solvable(compiled)
    n = posterior_samples or settings.posterior_samples
    check_posterior_work(compiled, n, samples_option if posterior_samples else None)
    check_search_work(compiled, settings)
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
            model,
            x,
            n,
            settings.estimator,
            stream(seed, "posterior"),
            stream(seed, "importance"),
            {"x": kept} if kept is not None else None,
            sampled,
        )
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
            diagnostics["refinement"] = (
                None
                if solution.refinement is None
                else {
                    "start_log_value": _number(solution.refinement.start_log_value),
                    "log_value": _number(solution.refinement.log_value),
                    "iterations": solution.refinement.iterations,
                    "samples": settings.refine_samples,
                }
            )
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
                posterior_and_estimate,
                model,
                nominal.x,
                min(n, settings.finalist_samples),
                settings.estimator,
                stream(seed, "posterior-nominal"),
                stream(seed, "importance-nominal"),
            )
            posterior, estimate = posterior_and_estimate(
                model,
                x,
                n,
                settings.estimator,
                stream(seed, "posterior"),
                stream(seed, "importance"),
                {"x": kept} if kept is not None else None,
                sampled,
            )
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
    findings = design_findings(compiled, model.linear, x) + gimbal_findings(posterior)
    if backend != "nominal" and settings.estimator != "mc":
        findings += search_findings(solution.search.get("verdict"))
    from bcad.bayes.result import DesignResult
    from bcad.model.results import checked

    return checked(
        result_document(
            compiled,
            kind="solve",
            seed=seed,
            backend=backend,
            x=x,
            posterior=posterior,
            estimate=estimate,
            samples=n,
            diagnostics=diagnostics,
            seconds=time.perf_counter() - start,
            contributors=contributors_to_dict(compiled, model.linear, x),
            warnings=warnings,
            findings=findings,
        ),
        DesignResult,
    )


def solve_run(
    compiled: CompiledProblem,
    options: RunOptions,
    spelling: Spelling,
    *,
    progress: Callable | None = None,
    samples_out: Path | None = None,
    inputs: list[Path] = (),
    output: Path | None = None,
    keep: bool = False,
) -> tuple[dict, dict | None]:
    """``bcad solve`` / ``bcad.solve`` on a compiled problem: the result document, and the
    posterior samples kept (for ``samples_out``, written there, or with ``keep`` for pictures:
    at most MAX_SAMPLES_OUT). A cycle that cannot be closed is reported at its closing link."""
    from bcad.bayes.genetic import SolverError

    count = options.samples or compiled.problem.solver.posterior_samples
    kept = samples_kept(samples_out, count, spelling, output, inputs)
    if kept is None and keep and count <= MAX_SAMPLES_OUT:
        kept = {}
    try:
        document = solve_document(
            compiled,
            backend=options.backend,
            seed=options.seed,
            posterior_samples=options.samples,
            estimator=options.estimator,
            progress=progress,
            kept=kept,
            samples_option=spelling.where("samples"),
        )
    except SolverError as exc:
        closing = compiled.graph.closing_links
        loc = compiled.graph.links[closing[0]].loc if closing else ()
        raise compiled.problem.source.error(loc, str(exc)) from None
    if samples_out is not None:
        write_samples(compiled, kept, samples_out, inputs)
    return document, kept


def posterior_run(
    compiled: CompiledProblem,
    x: np.ndarray,
    options: RunOptions,
    spelling: Spelling,
    *,
    progress: Callable | None = None,
    samples_out: Path | None = None,
    inputs: list[Path] = (),
    output: Path | None = None,
) -> dict:
    """``bcad posterior`` / ``bcad.posterior`` at X (:func:`bcad.bayes.arguments.solution_at`): the
    result document; the posterior samples are written to ``samples_out`` where it is given."""
    count = options.samples or compiled.problem.solver.posterior_samples
    kept = samples_kept(samples_out, count, spelling, output, inputs)
    document = posterior_document(
        compiled,
        x,
        samples=options.samples,
        seed=options.seed,
        estimator=options.estimator,
        kept=kept,
        samples_option=spelling.where("samples"),
        progress=progress,
    )
    if samples_out is not None:
        write_samples(compiled, kept, samples_out, inputs)
    return document
