"""The posterior of each closing link at a solution X* (Table 2 of the 2000 paper).

Table 2 reports, for the link to close, the mean and standard deviation of
its 6 pose parameters "obtained empirically using a Monte Carlo simulation
with 1e5 sampled points": the distribution of the pose F(X*, L) that the
rest of the cycle gives the closing link, with L drawn from its prior
(subject to the tree links' local relations). That is ``mean`` and ``std``.
Its standard deviations exceed those of the link's own Gaussians (1.95 mm
against 0.5 mm on tz), so the table is not weighted by them.

bcad also reports the posterior in the strict sense, p(Q | X*, H, K): the
same samples weighted by the closing link's distributions and relation
(``weighted``), with the effective sample size of those weights, and the
fraction of samples that satisfy the relation's inequalities. The same pass
gives log p(X*) Î(X*) on these samples.

Samples are drawn and summarised in chunks (streaming sums), so memory does
not grow with the sample count. Means and variances are accumulated about a
centre taken from the first chunk (its mean; the circular mean for angles),
which keeps the sums free of cancellation and angles free of wrap-around.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from bcad.bayes.model import BayesModel
from bcad.bayes.objective import Objective
from bcad.bayes.sampling import chunk_counts, chunk_rows, chunk_streams
from bcad.compiler import CompiledProblem
from bcad.kinematics.chain import Samples
from bcad.model.pose import ANGULAR, PARAMETERS
from bcad.numerics.angles import wrap_angle
from bcad.numerics.streaming import LogWeightSums, WeightedPoseSums

if TYPE_CHECKING:
    from bcad.bayes.importance import ImportanceEstimate

#: posterior samples drawn at once, at most (fewer with many L: see chunk_rows), as the importance
#: sampler's (:data:`bcad.bayes.importance.CHUNK`: smaller chunks are faster)
CHUNK = 1 << 14


@dataclass
class LinkPosterior:
    """``plain``: Table 2 (F(X*, L), L from its prior); ``weighted``: the posterior in the
    strict sense. Each is {mean, std, mean_se, std_se} (None when every weight is 0)."""

    name: str
    parent: str
    child: str
    constrained: list[str]
    plain: dict[str, np.ndarray]
    weighted: dict[str, np.ndarray] | None
    effective_samples: float
    satisfied: float | None
    #: its standard error over the N prior samples, sqrt(p (1 - p) / N) (a binomial share)
    satisfied_se: float | None = None

    @property
    def mean(self) -> np.ndarray:
        return self.plain["mean"]

    @property
    def std(self) -> np.ndarray:
        return self.plain["std"]


@dataclass
class PosteriorSummary:
    links: list[LinkPosterior]
    log_value: float  # log p(X) Î(X) on the posterior samples
    log_value_se: float  # its standard error (delta method)
    effective_samples: float  # of that estimate
    pareto_k: float  # PSIS k̂ of its weights
    samples: int = 0  # the prior samples behind Table 2's unweighted figures


class _LinkSums:
    """Table 2's unweighted sums and the weighted posterior's, for one closing link."""

    def __init__(self, expected: int):
        self.plain = WeightedPoseSums(expected, ANGULAR)
        self.weighted = WeightedPoseSums(expected, ANGULAR)
        self.satisfied = 0

    def add(self, poses: np.ndarray, log_weights: np.ndarray, satisfied: np.ndarray | None) -> None:
        self.plain.add_values(np.zeros(len(poses)), poses)
        self.weighted.add_values(log_weights, poses)
        if satisfied is not None:
            self.satisfied += int(np.count_nonzero(satisfied))


class PosteriorAccumulator:
    """Closing-link posteriors and log p(X) Î(X) for one X, summed chunk by chunk."""

    def __init__(
        self, compiled: CompiledProblem, objective: Objective, x: np.ndarray, expected: int, keep: bool = False
    ):
        self.compiled = compiled
        self.objective = objective
        self.x = np.asarray(x, dtype=float)
        self.links = [_LinkSums(expected) for _ in objective.cycles]
        self.integral = LogWeightSums(expected)
        #: with ``keep``: every chunk's closing poses and log-weights per link, and the joint log-weights
        self.kept: dict[str, list[np.ndarray]] | None = {} if keep else None

    def add(self, samples: Samples) -> None:
        self.add_evaluated(self.evaluate(samples))

    def evaluate(self, samples: Samples) -> tuple[list[tuple], np.ndarray]:
        """A chunk's figures, which :meth:`add_evaluated` sums: per cycle its closing poses, their
        log-weights and which samples meet the relation's inequalities (None: it has none), and
        the whole integrand's log."""
        integrand = np.zeros(samples.count)
        cycles = []
        for cycle, term in zip(self.compiled.graph.cycles, self.objective.cycles):
            link = self.compiled.graph.links[cycle.closing_link]
            transform = term.chain.evaluate(self.x, samples)
            poses = transform.poses()
            log_weights = np.zeros(samples.count)
            for group in term.observed:
                log_weights += group.log_density(poses, 0.0)
            satisfied = None
            if link.relation is not None:
                log_relation = link.relation.bind(samples.columns).log_satisfaction(
                    transform.columns, transform.translations, 0.0
                )
                log_weights += log_relation
                if link.relation.inequality_count:
                    satisfied = np.isfinite(log_relation)
            cycles.append((poses, log_weights, satisfied))
            integrand += log_weights
        for relation, chain in self.objective.tree_relations:
            transform = chain.evaluate(self.x, samples)
            integrand += relation.bind(samples.columns).log_satisfaction(transform.columns, transform.translations, 0.0)
        return cycles, integrand

    def add_evaluated(self, evaluated: tuple[list[tuple], np.ndarray]) -> None:
        """Sum a chunk's figures (:meth:`evaluate`)."""
        cycles, integrand = evaluated
        for cycle, sums, (poses, log_weights, satisfied) in zip(self.compiled.graph.cycles, self.links, cycles):
            sums.add(poses, log_weights, satisfied)
            if self.kept is not None:
                link = self.compiled.graph.links[cycle.closing_link]
                # angles as the centre's turn plus their wrapped offsets: a plain mean of the kept
                # samples is the table's (a link about rz = pi reads -pi + 0.01 and pi - 0.01 alike)
                centre = sums.plain.centre[ANGULAR]
                unwrapped = poses.copy()
                unwrapped[:, ANGULAR] = centre + wrap_angle(poses[:, ANGULAR] - centre)
                self.kept.setdefault(f"{link.name}/poses", []).append(unwrapped)
                self.kept.setdefault(f"{link.name}/log_weights", []).append(log_weights)
        self.integral.add(integrand)
        if self.kept is not None:
            self.kept.setdefault("log_weights", []).append(integrand)

    def summary(self) -> PosteriorSummary:
        results = []
        for cycle, term, sums in zip(self.compiled.graph.cycles, self.objective.cycles, self.links):
            link = self.compiled.graph.links[cycle.closing_link]
            constrained = (
                list(link.relation.constrained)
                if link.relation is not None
                else [PARAMETERS[slot] for group in term.observed for slot in group.slots]
            )
            has_inequalities = link.relation is not None and link.relation.inequality_count
            share = sums.satisfied / sums.plain.count if has_inequalities else None
            results.append(
                LinkPosterior(
                    link.name,
                    link.parent,
                    link.child,
                    constrained,
                    sums.plain.moments(),
                    sums.weighted.moments(),
                    sums.weighted.effective_samples,
                    share,
                    None if share is None else math.sqrt(share * (1.0 - share) / sums.plain.count),
                )
            )
        log_prior = float(self.objective.log_prior(self.x[None])[0])
        integral = self.integral
        return PosteriorSummary(
            results,
            log_prior + integral.log_mean,
            integral.log_mean_se,
            integral.effective_samples,
            integral.pareto_k,
            integral.count,
        )


def sample_posteriors(
    model: BayesModel,
    solutions: dict[str, np.ndarray],
    samples: int,
    rng: np.random.Generator,
    keep: dict[str, dict[str, np.ndarray]] | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, PosteriorSummary]:
    """The posterior at each named X, all on the same L samples (drawn in chunks). For each name
    that is a key of ``keep``, its value is filled with the samples themselves: ``LINK/poses``
    (N, 6) and ``LINK/log_weights`` (N,) per closing link, and ``log_weights`` (N,), the whole
    integrand (internal units). ``progress(done, samples)`` is called after each chunk."""
    keep = keep if keep is not None else {}
    accumulators = {
        name: PosteriorAccumulator(model.compiled, model.objective, x, samples, keep=name in keep)
        for name, x in solutions.items()
    }
    done = 0
    for chunk in model.sampler.draw_chunks(rng, samples, chunk_rows(len(model.compiled.parameters.l), CHUNK)):
        batch = Samples(chunk)
        done += batch.count
        for accumulator in accumulators.values():
            accumulator.add(batch)
        if progress is not None:
            progress(done, samples)
    for name, accumulator in accumulators.items():
        if accumulator.kept is not None:
            keep[name].update({key: np.concatenate(chunks) for key, chunks in accumulator.kept.items()})
    return {name: accumulator.summary() for name, accumulator in accumulators.items()}


def posterior_and_importance(
    model: BayesModel,
    x: np.ndarray,
    samples: int,
    posterior_rng: np.random.Generator,
    importance_rng: np.random.Generator,
    keep: dict[str, np.ndarray] | None = None,
    progress: Callable[[int, int], None] | None = None,
    pool=None,
) -> tuple[PosteriorSummary, ImportanceEstimate]:
    """The posterior at X (:func:`sample_posteriors`, ``keep`` the samples' dictionary to fill) and
    the importance estimate of I(X) (:meth:`ImportanceSampler.estimate`) on shared prior draws:
    each chunk's L, drawn once from its own stream spawned from ``posterior_rng``, are the
    posterior's samples and the proposal's start (whose own draws come from ``importance_rng``'s
    streams), so a sample's L is drawn once where the two passes drew it twice (the prior draw
    costs about as much as the chain's evaluation). Each estimate is the one its own samples give;
    the chunks run on the thread ``pool``'s workers where one is given and are summed in order,
    with the same result bit for bit. The prior is pseudo-random (a ``qmc`` sampler's Sobol
    sequence runs through the chunks in order: :func:`sample_posteriors`)."""
    from bcad.bayes.importance import in_order

    x = np.asarray(x, dtype=float)
    importance = model.importance
    accumulator = PosteriorAccumulator(model.compiled, model.objective, x, samples, keep=keep is not None)
    lin, directions = importance.prepare(x)
    counts = chunk_counts(samples, chunk_rows(len(model.compiled.parameters.l), CHUNK))
    jobs = list(zip(counts, chunk_streams(posterior_rng, len(counts)), chunk_streams(importance_rng, len(counts))))

    def chunk(count: int, prior_stream, proposal_stream):
        values = model.prior_sampler.draw(prior_stream, count)
        evaluated = accumulator.evaluate(Samples(values))
        return evaluated, importance.chunk(x, count, proposal_stream, lin, directions, values)

    done = 0

    def importance_chunks():
        nonlocal done
        for evaluated, importance_chunk in in_order(pool, chunk, jobs):
            accumulator.add_evaluated(evaluated)
            done += len(evaluated[1])
            if progress is not None:
                progress(done, samples)
            yield importance_chunk

    found = importance.summed(importance_chunks(), samples, directions)
    if accumulator.kept is not None:
        keep.update({key: np.concatenate(chunks) for key, chunks in accumulator.kept.items()})
    return accumulator.summary(), found
