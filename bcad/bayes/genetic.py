"""The genetic algorithm of Sect. 4.2.3 of the 2000 paper, in three phases.

1. Initialisation and automatic initial temperature: each individual is drawn
   at random until G^T_{N0} of it is non-zero, raising T by Delta T after every
   zero (INITIALIZATION). "Zero" is the paper's double-precision 0.0: a log
   value below log(DBL_MIN).
2. Temperature reduction: nc1 generations at T, then T <- alpha T, until
   T < T_epsilon; then T = 0 and the population is re-evaluated
   (TEMP-REDUCTION).
3. Sample-count growth: nc2 generations at N, then N <- beta N, up to Nmax
   (N_POINTS_AUGMENTATION); bcad also runs the last nc2 generations at Nmax
   itself, where the paper stops as soon as N reaches it.

A generation is real-coded: X is scaled to the unit box of its bounds;
parents are chosen by tournament, blended (BLX-0.5 crossover), and mutated
by Gaussian steps whose size shrinks with the temperature; the best
``elite`` individuals pass unchanged. Each generation draws a new batch of L
samples; with common random numbers every individual (elites included) is
evaluated on that one batch, otherwise each on its own batch, as in the paper.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from bcad.bayes.objective import LOG_ZERO, Objective
from bcad.bayes.sampling import FreeParameterSampler
from bcad.bayes.work import sample_schedule, temperature_schedule
from bcad.kinematics.chain import Samples
from bcad.model.solver import SolverSettings


class SolverError(Exception):
    """The solver cannot proceed on this problem (reported like bad input)."""


@dataclass
class GenerationRecord:
    phase: str
    temperature: float
    samples: int
    best_log_value: float


@dataclass
class GeneticResult:
    population: np.ndarray
    values: np.ndarray
    best: np.ndarray
    best_log_value: float
    initial_temperature: float
    evaluations: int
    sample_evaluations: int
    trace: list[GenerationRecord] = field(default_factory=list)


Progress = Callable[[str, float, int, float], None]


class GeneticAlgorithm:
    def __init__(
        self,
        objective: Objective,
        sampler: FreeParameterSampler,
        settings: SolverSettings,
        rng: np.random.Generator,
        progress: Progress | None = None,
    ):
        self.objective = objective
        self.sampler = sampler
        self.settings = settings
        self.rng = rng
        self.progress = progress
        self.low = objective.bounds[:, 0]
        self.width = objective.bounds[:, 1] - objective.bounds[:, 0]
        self.evaluations = 0
        self.sample_evaluations = 0

    def to_x(self, unit: np.ndarray) -> np.ndarray:
        return self.low + self.width * unit

    def evaluate(self, unit: np.ndarray, temperature: float, n: int) -> np.ndarray:
        """G^T_N of each individual (rows of ``unit``) on a fresh batch of samples."""
        population = self.to_x(np.atleast_2d(unit))
        count = population.shape[0]
        self.evaluations += count
        self.sample_evaluations += count * n
        if self.settings.common_random_numbers or count == 1:
            samples = Samples(self.sampler.draw(self.rng, n))
            return self.objective.log_value(population, samples, temperature)
        samples = Samples(self.sampler.draw(self.rng, n * count))
        return self.objective.log_value_independent(population, samples, temperature)

    def initialise(self, n: int) -> tuple[np.ndarray, float]:
        """The paper's INITIALIZATION: random individuals, T raised until each is non-zero."""
        settings = self.settings
        temperature = 0.0
        population = np.empty((settings.population, self.objective.dimension))
        draws = 0
        for index in range(settings.population):
            while True:
                candidate = self.rng.uniform(0.0, 1.0, self.objective.dimension)
                draws += 1
                if self.evaluate(candidate, temperature, n)[0] > LOG_ZERO:
                    break
                temperature += settings.temperature_step
                if draws >= settings.max_initial_draws:
                    raise SolverError(
                        f"no random X gave a non-zero objective in {draws} draws, even at T = {temperature:g}; "
                        "check that the problem's cycles can close within the X bounds"
                    )
            population[index] = candidate
        return population, temperature

    def next_generation(self, population: np.ndarray, values: np.ndarray, mutation_scale: float) -> np.ndarray:
        settings, rng = self.settings, self.rng
        size, dimension = population.shape
        order = np.argsort(-values, kind="stable")
        children = [population[i] for i in order[: settings.elite]]
        ranks = np.empty(size, dtype=int)
        ranks[order] = np.arange(size)
        while len(children) < size:
            a, b = (min(rng.integers(0, size, settings.tournament), key=lambda i: ranks[i]) for _ in range(2))
            child = population[a].copy()
            if rng.random() < settings.crossover_rate:
                # BLX-0.5: uniform on the parents' interval widened by half its length.
                low = np.minimum(population[a], population[b])
                span = np.abs(population[a] - population[b])
                child = rng.uniform(low - 0.5 * span, low + 1.5 * span)
            mutate = rng.random(dimension) < settings.mutation_rate
            child = child + mutate * rng.normal(0.0, mutation_scale, dimension)
            # Reflect at the bounds of the unit box.
            child = np.abs(child)
            child = 1.0 - np.abs(1.0 - child)
            children.append(np.clip(child, 0.0, 1.0))
        return np.array(children)

    def run(self) -> GeneticResult:
        settings = self.settings
        n = settings.initial_samples
        population, temperature = self.initialise(n)
        initial_temperature = temperature
        values = self.evaluate(population, temperature, n)
        trace: list[GenerationRecord] = []
        mutation_scale = settings.mutation_scale

        def generations(count: int, phase: str, temperature: float, n: int) -> None:
            nonlocal population, values
            for _ in range(count):
                population = self.next_generation(population, values, max(mutation_scale, settings.mutation_scale_min))
                values = self.evaluate(population, temperature, n)
                best = float(np.max(values))
                trace.append(GenerationRecord(phase, temperature, n, best))
                if self.progress:
                    self.progress(phase, temperature, n, best)

        for step in temperature_schedule(initial_temperature, settings):
            generations(settings.generations_per_temperature, "temperature", step, n)
            mutation_scale *= settings.alpha
        temperature = 0.0
        values = self.evaluate(population, temperature, n)

        for n in sample_schedule(settings):
            generations(settings.generations_per_sample_size, "samples", 0.0, n)
        best = int(np.argmax(values))
        return GeneticResult(
            population=self.to_x(population),
            values=values,
            best=self.to_x(population[best]),
            best_log_value=float(values[best]),
            initial_temperature=initial_temperature,
            evaluations=self.evaluations,
            sample_evaluations=self.sample_evaluations,
            trace=trace,
        )
