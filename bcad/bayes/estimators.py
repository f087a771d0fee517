"""X* and log p(X*) I(X*) with the linearised and importance estimators.

``solver.estimator`` chooses how I(X) is estimated:

* ``mc``: the paper's plain Monte Carlo (Sect. 4.1.2), searched by its GA
  (:mod:`bcad.bayes.genetic_search`);
* ``linear``: the linearised I_lin (:mod:`bcad.bayes.linear`), searched by
  Newton's method from several starts (:mod:`bcad.bayes.search`), and
  reported as it is;
* ``importance`` (the default): the same search, then the best distinct
  local maxima (the finalists) scored by importance sampling of the exact
  integrand (:mod:`bcad.bayes.importance`); the best of them is X*, and its
  value and weighted posterior come from a larger importance sample.

Every estimate is an :class:`ObjectiveEstimate`: log p(X) I(X) with its
standard error, effective sample size and Pareto k̂ where it is a Monte
Carlo figure, and each closing link's weighted posterior.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from bcad.bayes.model import BayesModel
from bcad.bayes.search import LocalMaximum, distinct_maxima, maximise_linear
from bcad.model.solver import SolverSettings
from bcad.numerics.seeding import stream


@dataclass
class ObjectiveEstimate:
    """log p(X) I(X) at one X and what it rests on."""

    estimator: str
    log_value: float
    log_value_se: float
    samples: int | None
    effective_samples: float | None
    pareto_k: float | None
    #: per cycle: the closing link's weighted posterior {mean, std, mean_se, std_se}, or None
    links: list[dict[str, np.ndarray] | None]


@dataclass
class EstimatedSolution:
    x: np.ndarray
    maxima: list[LocalMaximum]
    finalists: list[dict[str, float]] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)


def estimate(model: BayesModel, x: np.ndarray, estimator: str, samples: int, rng: np.random.Generator) -> ObjectiveEstimate:
    """log p(X) I(X) by the ``linear`` or ``importance`` estimator."""
    x = np.asarray(x, dtype=float)
    log_prior = float(model.objective.log_prior(x[None])[0])
    if estimator == "linear":
        value, se = model.linear.log_integral(x[None])
        return ObjectiveEstimate("linear", log_prior + float(value[0]), float(se[0]), None, None, None,
                                 model.linear.conditional_links(x))
    found = model.importance.estimate(x, samples, rng)
    return ObjectiveEstimate(
        "importance", log_prior + found.log_integral, found.log_integral_se, samples,
        found.effective_samples, found.pareto_k, found.links,
    )


def search_starts(model: BayesModel, nominal_x: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """The nominal backend's solution, then uniform draws in the bounds, each moved by
    Levenberg-Marquardt to where it closes the cycles nominally (the nominal backend's
    method): the optimum lies near the closure manifold, and random points far
    from it are poor starts for a local search."""
    from bcad.bayes.nominal import CycleClosure

    bounds = model.objective.bounds
    closure = CycleClosure(model.compiled, model.objective)
    starts = [np.asarray(nominal_x, dtype=float)]
    for start in rng.uniform(bounds[:, 0], bounds[:, 1], size=(count - 1, len(bounds))):
        starts.append(closure.close(start, fallback=False)[0])
    return np.vstack(starts)


def solve(model: BayesModel, settings: SolverSettings, seed: int, nominal_x: np.ndarray) -> EstimatedSolution:
    """X*: Newton search on I_lin, then (importance) the finalists scored by importance sampling."""
    timings: dict[str, float] = {}
    start = time.perf_counter()
    starts = search_starts(model, nominal_x, settings.search_starts, stream(seed, "starts"))
    maxima = maximise_linear(model.search_linear, starts, settings.search_iterations)
    timings["search"] = time.perf_counter() - start
    if settings.estimator == "linear":
        return EstimatedSolution(maxima[0].x, maxima, timings=timings)
    start = time.perf_counter()
    rng = stream(seed, "finalists")
    finalists = []
    for maximum in distinct_maxima(maxima, settings.finalists):
        scored = estimate(model, maximum.x, "importance", settings.finalist_samples, rng)
        finalists.append(
            {"x": maximum.x, "linear_log_value": maximum.log_value, "log_value": scored.log_value,
             "log_value_se": scored.log_value_se}
        )
    best = max(finalists, key=lambda f: f["log_value"] if np.isfinite(f["log_value"]) else -np.inf)
    timings["finalists"] = time.perf_counter() - start
    return EstimatedSolution(best["x"], maxima, finalists, timings)
