"""The Bayesian backend: X* = argmax p(X) I(X) (Eq. 2 of the 2000 paper).

1. The genetic algorithm of Sect. 4.2.3 (:mod:`bcad.bayes.genetic`).
2. With common random numbers on (the default): the final population's best
   distinct individuals are re-ranked on one larger, independent *selection*
   batch, so that the winner is not merely the luckiest draw of the last
   generation.
3. The winner is refined by L-BFGS-B on a fixed *refinement* batch
   (:mod:`bcad.bayes.refine`). Where the integrand is peaked (few samples
   carry the estimate) a fixed batch can be over-fitted, so the refined X is
   kept only if it beats the winner on the selection batch by more than two
   standard errors of the paired estimate of log I(refined) - log I(winner).

The paper-faithful configuration (``common_random_numbers: false``,
``refine: false``) keeps the GA's best as it is.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from bcad.bayes.genetic import GeneticAlgorithm, GeneticResult, Progress, SolverError
from bcad.bayes.model import BayesModel
from bcad.bayes.objective import Objective
from bcad.bayes.refine import Refinement, refine
from bcad.bayes.sampling import FreeParameterSampler
from bcad.bayes.solvable import check_solvable
from bcad.kinematics.chain import Samples
from bcad.model.solver import SolverSettings
from bcad.numerics.seeding import stream


@dataclass
class BayesSolution:
    x: np.ndarray
    genetic: GeneticResult
    refinement: Refinement | None
    #: log G of the re-ranked winner and of the refined X on the selection batch
    selection: dict[str, float] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)


def solve_bayes(
    model: BayesModel, settings: SolverSettings, seed: int, progress: Progress | None = None
) -> BayesSolution:
    """X* by the paper's GA (module docstring) on the problem's model, built once."""
    check_solvable(model.compiled)
    objective = model.objective
    sampler = (
        model.sampler if model.sampler.qmc == settings.qmc else FreeParameterSampler(model.compiled, qmc=settings.qmc)
    )
    timings: dict[str, float] = {}

    start = time.perf_counter()
    genetic = GeneticAlgorithm(objective, sampler, settings, stream(seed, "genetic"), progress).run()
    timings["genetic"] = time.perf_counter() - start
    x = genetic.best
    refinement = None
    selection: dict[str, float] = {}
    if settings.common_random_numbers:
        start = time.perf_counter()
        held_out = Samples(sampler.draw(stream(seed, "selection"), settings.selection_samples))
        order = np.argsort(-genetic.values, kind="stable")
        candidates = _distinct(genetic.population[order], settings.reranked)
        values = objective.log_value(candidates, held_out, 0.0)
        best = int(np.argmax(values))
        x, selection["winner"] = candidates[best], float(values[best])
        timings["selection"] = time.perf_counter() - start
        if settings.refine:
            start = time.perf_counter()
            samples = Samples(sampler.draw(stream(seed, "refine"), settings.refine_samples))
            refinement = refine(objective, x, samples, settings.refine_iterations)
            gain, error = paired_log_ratio(objective, refinement.x, x, held_out)
            selection["refined_gain"], selection["refined_gain_error"] = gain, error
            if gain > 2.0 * error:
                x = refinement.x
            timings["refine"] = time.perf_counter() - start
    return BayesSolution(x, genetic, refinement, selection, timings)


def paired_log_ratio(
    objective: Objective, x_new: np.ndarray, x_old: np.ndarray, samples: Samples
) -> tuple[float, float]:
    """log G(x_new) - log G(x_old) on common samples, and its standard error (delta method).

    With a_i, b_i the two integrands on sample i, the estimate is
    log(mean a / mean b); its variance is (var a / A^2 + var b / B^2 - 2 cov(a, b) / (A B)) / N.
    """
    population = np.vstack([x_new, x_old])
    log_integrand = objective.log_integrand(population, samples, 0.0)
    log_prior = objective.log_prior(population)
    peak = np.max(log_integrand)
    if not np.isfinite(peak):
        return 0.0, np.inf
    a, b = np.exp(log_integrand - peak)
    A, B = a.mean(), b.mean()
    if A == 0.0 or B == 0.0:
        return (np.inf if B == 0.0 else -np.inf), 0.0
    covariance = np.cov(a, b)
    variance = (covariance[0, 0] / A**2 + covariance[1, 1] / B**2 - 2.0 * covariance[0, 1] / (A * B)) / len(a)
    gain = float(np.log(A) - np.log(B) + log_prior[0] - log_prior[1])
    return gain, float(np.sqrt(max(variance, 0.0)))


def _distinct(population: np.ndarray, count: int) -> np.ndarray:
    """The first ``count`` distinct rows, in order."""
    chosen: list[np.ndarray] = []
    for row in population:
        if not any(np.array_equal(row, other) for other in chosen):
            chosen.append(row)
        if len(chosen) == count:
            break
    return np.array(chosen)


__all__ = ["BayesSolution", "SolverError", "solve_bayes"]
