"""The ``solver:`` section of a problem file: settings of the Bayesian solver.

Names follow Sect. 4.2.3 of the 2000 paper where it has one (nc1, nc2, alpha,
beta, N0, Nmax, T_epsilon, Delta T). Defaults are tuned so that the RX90
example solves in a few seconds on two cores. Every setting is bounded, so
that no file can make a loop endless or exhaust memory: sample counts of one
batch (N0, Nmax, the selection and refinement batches) at most 1e6 (a batch
holds N x nL doubles several times), alpha <= 0.95 and beta >= 1.1 so that
the temperature and sample-count phases end within a few hundred steps.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from bcad.model.base import StrictModel

ESTIMATORS = ("importance", "linear", "mc")


class SolverSettings(StrictModel):
    # How I(X) is estimated (bcad.bayes): the search, the score and the weighted posterior.
    estimator: Literal["importance", "linear", "mc"] = Field(
        "importance",
        description="importance: Newton search on the linearised objective, finalists and posterior by importance "
        "sampling; linear: the linearised objective alone; mc: the paper's GA on plain Monte Carlo",
    )
    search_starts: int | None = Field(
        None,
        ge=1,
        le=10_000,
        description="points of the space-filling design of X's box, moved towards closing the cycles and "
        "screened by the linearised objective (default: max(64, 5 x climbs))",
    )
    search_climbs: int | None = Field(
        None,
        ge=1,
        le=1000,
        description="Newton climbs: the nominal solution, then the best distinct screened points (default: "
        "by the cost of a Newton step, 84672 / (n^2 (nL + 1)) within 24..192 for n X and nL L: 24 on the "
        "RX90 example, 147 and 192 on the UR5's; 32 where configurations or cycles have X of their own; "
        "fewer where 1e5 / n^2 caps them)",
    )
    search_iterations: int = Field(
        50,
        ge=1,
        le=10000,
        description=(
            "Newton steps per climb, at most: the best climb goes on to this many (it stops sooner where it "
            "gains no more); the others stop earlier, in rounds of successive halving (4, 8, 12 and 16 steps)"
        ),
    )
    search_effort: float = Field(
        1.0,
        ge=0.1,
        le=50.0,
        description="multiplies the search's default budgets: its starts and climbs (within 1e4 and 1e3), and "
        "where configurations or cycles have X of their own each one's branch search (redraws, climbs, "
        "combinations climbed) and its lineages at most; the search's time grows about in proportion "
        "(search_starts and search_climbs given stand)",
    )
    finalists: int = Field(3, ge=1, le=100, description="best distinct local maxima scored by importance sampling")
    finalist_samples: int = Field(8192, ge=16, le=10_000_000, description="importance samples per finalist")
    # The genetic algorithm (Sect. 4.2).
    population: int = Field(40, ge=4, le=10_000, description="individuals in the GA's population")
    elite: int = Field(2, ge=0, le=10_000, description="best individuals copied unchanged into the next generation")
    tournament: int = Field(3, ge=2, le=1000, description="tournament size of parent selection")
    crossover_rate: float = Field(0.9, ge=0.0, le=1.0, description="probability that two parents are blended")
    mutation_rate: float = Field(0.25, ge=0.0, le=1.0, description="probability that a gene is mutated")
    mutation_scale: float = Field(
        0.15, gt=0.0, le=10.0, description="initial std of a mutation, as a fraction of the bounds' width"
    )
    mutation_scale_min: float = Field(
        0.003, gt=0.0, le=1.0, description="floor of the mutation std (it shrinks with T)"
    )
    # Phase 1 and 2: temperature (Sect. 4.2.1 and 4.2.3).
    temperature_step: float = Field(1.0, gt=0.0, le=1e6, description="Delta T of the automatic initial temperature")
    temperature_min: float = Field(0.01, ge=1e-9, le=1e6, description="T_epsilon: below it T is set to 0")
    alpha: float = Field(0.8, ge=0.01, le=0.95, description="temperature factor after each nc1 generations")
    generations_per_temperature: int = Field(2, ge=1, le=100, description="nc1")
    max_initial_draws: int = Field(
        20000,
        ge=1,
        le=1_000_000,
        description="random draws allowed to initialise the population (at least population: one per individual)",
    )
    # Phase 3: sample counts (Sect. 4.2.2 and 4.2.3).
    initial_samples: int = Field(64, ge=1, le=1_000_000, description="N0")
    max_samples: int = Field(4096, ge=1, le=1_000_000, description="Nmax")
    beta: float = Field(2.0, ge=1.1, le=10.0, description="sample-count factor after each nc2 generations")
    generations_per_sample_size: int = Field(3, ge=1, le=100, description="nc2")
    # Beyond the paper (its Sect. 6).
    common_random_numbers: bool = Field(
        True, description="compare every individual of a generation on the same samples"
    )
    qmc: bool = Field(False, description="scrambled Sobol points instead of pseudo-random samples")
    reranked: int = Field(
        12,
        ge=1,
        le=1000,
        description="best distinct individuals of the final population re-ranked on the selection batch",
    )
    selection_samples: int = Field(
        32768,
        ge=1,
        le=1_000_000,
        description="samples of the independent batch that re-ranks the GA's best and validates the refinement",
    )
    refine: bool = Field(True, description="local derivative-based refinement after the GA")
    refine_samples: int = Field(2048, ge=1, le=1_000_000, description="samples held fixed during refinement")
    refine_iterations: int = Field(6, ge=1, le=1000, description="L-BFGS-B iterations of the refinement")
    # The posterior (Table 2).
    posterior_samples: int = Field(
        100000, ge=1, le=1_000_000_000, description="samples of the posterior at the solution"
    )

    @model_validator(mode="after")
    def _consistent(self) -> SolverSettings:
        if self.elite >= self.population:
            raise ValueError(f"elite ({self.elite}) must be smaller than population ({self.population})")
        if self.max_initial_draws < self.population:
            # the GA's initialisation draws each individual once at least (more where it scores 0)
            raise ValueError(
                f"max_initial_draws ({self.max_initial_draws}) must be at least population ({self.population}): "
                "each individual of the first population is one draw at least"
            )
        if self.max_samples < self.initial_samples:
            raise ValueError(
                f"max_samples ({self.max_samples}) must be at least initial_samples ({self.initial_samples})"
            )
        return self

    @classmethod
    def paper(cls) -> SolverSettings:
        """The paper-faithful configuration: no common random numbers, no refinement."""
        return cls(common_random_numbers=False, refine=False)
