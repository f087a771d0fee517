"""What a posterior and a search cost, in chain links, and the refusal of one past its budget.

Kept apart from the model (:mod:`bcad.bayes.model`, which builds the estimators) so that
``bcad validate`` checks a problem's own ``solver.posterior_samples`` without importing them.
"""

from __future__ import annotations

from bcad.compiler import CompiledProblem
from bcad.errors import InputError

#: posterior samples times what each costs (:func:`posterior_work`), at most: 4e8 is about 30 s on
#: 2 cores (the RX90 example: 95 per sample, 1e6 samples in 6 s; an edge on a rail: 26, 1e6 in 1.6 s)
MAX_POSTERIOR_WORK = 400_000_000
#: what a sample costs beside its chains' links, in links (drawing, weighting, summing)
SAMPLE_OVERHEAD = 16
#: the GA's (``estimator: mc``) planned sample evaluations times their cost, at most: about five
#: minutes on 2 cores (its defaults on the RX90 example plan at most 3e8)
MAX_SEARCH_WORK = 4_000_000_000
#: the GA settings that set its work, in the order a refusal names the first one the file writes
GENETIC_WORK_SETTINGS = (
    "population",
    "max_samples",
    "initial_samples",
    "generations_per_sample_size",
    "generations_per_temperature",
    "max_initial_draws",
    "temperature_step",
    "temperature_min",
    "alpha",
    "beta",
    "selection_samples",
    "reranked",
    "refine_samples",
    "refine_iterations",
)


def chain_links(compiled: CompiledProblem) -> int:
    """The links of all cycles' chains together: each cycle's tree path and its closing link."""
    return sum(len(cycle.path) + 1 for cycle in compiled.graph.cycles)


def posterior_work(compiled: CompiledProblem) -> int:
    """What one posterior sample costs, in links: every cycle's chain (its tree path and closing
    link), one per L drawn, and :data:`SAMPLE_OVERHEAD`."""
    return chain_links(compiled) + len(compiled.parameters.l) + SAMPLE_OVERHEAD


def check_posterior_work(compiled: CompiledProblem, samples: int, option: str | None) -> None:
    """Refuse (exit 2) a posterior whose samples would take past about half a minute
    (:data:`MAX_POSTERIOR_WORK`), before drawing any. ``option`` names where the count came
    from (``--samples``, ``samples=``); None: the problem's ``solver.posterior_samples``."""
    per_sample = posterior_work(compiled)
    if samples * per_sample <= MAX_POSTERIOR_WORK:
        return
    most = MAX_POSTERIOR_WORK // per_sample
    message = (
        f"{samples:,} posterior samples of this problem (costing {per_sample} chain links each) would take "
        f"more than about half a minute; at most {most:,} are taken (samples x links <= "
        f"{MAX_POSTERIOR_WORK:.0e}); the standard error falls as one over the square root of the samples, "
        "so 4 times fewer only doubles it"
    )
    if option is None:
        raise compiled.problem.source.error(("solver", "posterior_samples"), message)
    raise InputError(option, message)


def temperature_schedule(initial: float, settings) -> list[float]:
    """The GA's temperatures (Sect. 4.2.1): from ``initial`` down by factors ``alpha`` while above
    ``temperature_min``; none where ``initial`` is not above it."""
    temperatures = []
    while initial > settings.temperature_min:
        temperatures.append(initial)
        initial *= settings.alpha
    return temperatures


def sample_schedule(settings) -> list[int]:
    """The GA's sample counts at T = 0 (Sect. 4.2.2): from ``initial_samples`` up by factors
    ``beta`` (one more at least, so that it grows) below ``max_samples``, then ``max_samples``."""
    sizes, n = [], settings.initial_samples
    while n < settings.max_samples:
        sizes.append(n)
        n = max(n + 1, int(round(n * settings.beta)))
    return [*sizes, settings.max_samples]


def genetic_sample_evaluations(settings, dimension: int) -> int:
    """The GA's sample evaluations at most (:class:`bcad.bayes.genetic.GeneticAlgorithm`'s
    schedule): its initial draws; ``generations_per_temperature`` generations at each temperature
    from the highest its initialisation can reach (``max_initial_draws`` times ``temperature_step``)
    down to ``temperature_min`` by factors ``alpha``, at ``initial_samples`` each; one at T = 0;
    ``generations_per_sample_size`` at each sample count from ``initial_samples`` up to
    ``max_samples`` by factors ``beta``; the re-ranking on the selection batch and the
    refinement's iterations (each evaluating the objective and its forward differences)."""
    n0, population = settings.initial_samples, settings.population
    steps = len(temperature_schedule(settings.max_initial_draws * settings.temperature_step, settings))
    sizes = sample_schedule(settings)
    evaluations = settings.max_initial_draws * n0
    evaluations += population * n0 * (steps * settings.generations_per_temperature + 1)
    evaluations += population * settings.generations_per_sample_size * sum(sizes)
    evaluations += settings.reranked * settings.selection_samples
    evaluations += settings.refine_samples * settings.refine_iterations * (dimension + 1)
    return evaluations


def check_search_work(compiled: CompiledProblem, settings) -> None:
    """Refuse (exit 2), before any work, a search whose settings would sample past its budget:
    the importance finalists' samples (``finalists`` times ``finalist_samples``) past the
    posterior's (:data:`MAX_POSTERIOR_WORK`, about half a minute), the GA's planned samples
    (:func:`genetic_sample_evaluations`) past :data:`MAX_SEARCH_WORK` (about five minutes). At the
    line of the setting the file writes (the problem's ``solver``)."""
    per_sample = posterior_work(compiled)
    written = settings.model_fields_set
    if settings.estimator == "importance":
        samples = settings.finalists * settings.finalist_samples
        if samples * per_sample <= MAX_POSTERIOR_WORK:
            return
        field = "finalist_samples" if "finalist_samples" in written or "finalists" not in written else "finalists"
        most = MAX_POSTERIOR_WORK // (per_sample * settings.finalists)
        message = (
            f"{settings.finalists} finalists of {settings.finalist_samples:,} importance samples each (costing "
            f"{per_sample} chain links each) would take more than about half a minute; at most {most:,} samples "
            f"per finalist here (finalists x finalist_samples x links <= {MAX_POSTERIOR_WORK:.0e})"
        )
    elif settings.estimator == "mc":
        samples = genetic_sample_evaluations(settings, len(compiled.parameters.x))
        if samples * per_sample <= MAX_SEARCH_WORK:
            return
        field = next((name for name in GENETIC_WORK_SETTINGS if name in written), "estimator")
        message = (
            f"the genetic algorithm's settings plan up to {samples:.2e} sample evaluations (costing {per_sample} "
            f"chain links each), more than about five minutes of work; expected samples x links <= "
            f"{MAX_SEARCH_WORK:.0e}: a smaller population, max_samples or selection_samples"
        )
    else:
        return
    raise compiled.problem.source.error(("solver", field), message)
