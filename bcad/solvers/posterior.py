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

from dataclasses import dataclass

import numpy as np

from bcad.compile import CompiledProblem
from bcad.kinematics.chain import Samples
from bcad.model.pose import LENGTH_PARAMETERS, PARAMETERS
from bcad.solvers.objective import Objective, wrap_angle
from bcad.solvers.sampling import FreeParameterSampler

ANGULAR = np.array([name not in LENGTH_PARAMETERS for name in PARAMETERS])
CHUNK = 1 << 16


@dataclass
class LinkPosterior:
    name: str
    parent: str
    child: str
    constrained: list[str]
    mean: np.ndarray
    std: np.ndarray
    weighted_mean: np.ndarray | None
    weighted_std: np.ndarray | None
    effective_samples: float
    satisfied: float | None


@dataclass
class PosteriorSummary:
    links: list[LinkPosterior]
    log_value: float  # log p(X) Î(X) on the posterior samples
    effective_samples: float  # of that estimate


class WeightedSums:
    """Streaming sums of w, w^2 (w = exp(log weight), rescaled as the running maximum grows)."""

    def __init__(self, width: int):
        self.log_scale = -np.inf
        self.total = 0.0
        self.squares = 0.0
        self.first = np.zeros(width)
        self.second = np.zeros(width)

    def add(self, log_weights: np.ndarray, values: np.ndarray | None = None) -> None:
        peak = np.max(log_weights) if log_weights.size else -np.inf
        if not np.isfinite(peak):
            return
        if peak > self.log_scale:
            shrink = np.exp(self.log_scale - peak) if np.isfinite(self.log_scale) else 0.0
            self.total *= shrink
            self.squares *= shrink * shrink
            self.first *= shrink
            self.second *= shrink
            self.log_scale = peak
        weights = np.exp(log_weights - self.log_scale)
        self.total += weights.sum()
        self.squares += weights @ weights
        if values is not None:
            self.first += weights @ values
            self.second += weights @ (values * values)

    @property
    def effective_samples(self) -> float:
        return float(self.total**2 / self.squares) if self.squares > 0 else 0.0


def _centre(poses: np.ndarray) -> np.ndarray:
    centre = poses.mean(axis=0)
    angles = poses[:, ANGULAR]
    centre[ANGULAR] = np.arctan2(np.sin(angles).mean(axis=0), np.cos(angles).mean(axis=0))
    return centre


class _LinkSums:
    def __init__(self):
        self.centre: np.ndarray | None = None
        self.count = 0
        self.first = np.zeros(6)
        self.second = np.zeros(6)
        self.weighted = WeightedSums(6)
        self.satisfied = 0

    def add(self, poses: np.ndarray, log_weights: np.ndarray, satisfied: np.ndarray | None) -> None:
        if self.centre is None:
            self.centre = _centre(poses)
        deviation = poses - self.centre
        deviation[:, ANGULAR] = wrap_angle(deviation[:, ANGULAR])
        self.count += len(poses)
        self.first += deviation.sum(axis=0)
        self.second += np.einsum("ij,ij->j", deviation, deviation)
        self.weighted.add(log_weights, deviation)
        if satisfied is not None:
            self.satisfied += int(np.count_nonzero(satisfied))

    def moments(self, total: float, first: np.ndarray, second: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        mean = first / total
        std = np.sqrt(np.maximum(second / total - mean * mean, 0.0))
        mean = mean + self.centre
        mean[ANGULAR] = wrap_angle(mean[ANGULAR])
        return mean, std


class PosteriorAccumulator:
    """Closing-link posteriors and log p(X) Î(X) for one X, summed chunk by chunk."""

    def __init__(self, compiled: CompiledProblem, objective: Objective, x: np.ndarray):
        self.compiled = compiled
        self.objective = objective
        self.x = np.asarray(x, dtype=float)
        self.links = [_LinkSums() for _ in objective.cycles]
        self.integral = WeightedSums(0)
        self.count = 0

    def add(self, samples: Samples) -> None:
        integrand = np.zeros(samples.count)
        for cycle, term, sums in zip(self.compiled.graph.cycles, self.objective.cycles, self.links):
            link = self.compiled.graph.links[cycle.closing_link]
            transform = term.chain.evaluate(self.x, samples)
            poses = transform.poses()
            log_weights = np.zeros(samples.count)
            for group in term.observed:
                log_weights += group.log_density(poses, 0.0)
            satisfied = None
            if link.relation is not None:
                log_relation = link.relation.log_satisfaction(transform.columns, transform.translations, 0.0)
                log_weights += log_relation
                if link.relation.inequality_count:
                    satisfied = np.isfinite(log_relation)
            sums.add(poses, log_weights, satisfied)
            integrand += log_weights
        for relation, chain in self.objective.tree_relations:
            transform = chain.evaluate(self.x, samples)
            integrand += relation.log_satisfaction(transform.columns, transform.translations, 0.0)
        self.integral.add(integrand)
        self.count += samples.count

    def summary(self) -> PosteriorSummary:
        results = []
        for cycle, term, sums in zip(self.compiled.graph.cycles, self.objective.cycles, self.links):
            link = self.compiled.graph.links[cycle.closing_link]
            mean, std = sums.moments(sums.count, sums.first, sums.second)
            weighted_mean = weighted_std = None
            if sums.weighted.total > 0:
                weighted_mean, weighted_std = sums.moments(sums.weighted.total, sums.weighted.first, sums.weighted.second)
            constrained = list(link.relation.constrained) if link.relation is not None else [
                PARAMETERS[slot] for group in term.observed for slot in group.slots
            ]
            satisfied = sums.satisfied / sums.count if link.relation is not None and link.relation.inequality_count else None
            results.append(
                LinkPosterior(
                    link.name, link.parent, link.child, constrained, mean, std,
                    weighted_mean, weighted_std, sums.weighted.effective_samples, satisfied,
                )
            )
        log_prior = float(self.objective.log_prior(self.x[None])[0])
        if self.integral.total > 0:
            log_value = log_prior + self.integral.log_scale + float(np.log(self.integral.total / self.count))
        else:
            log_value = -np.inf
        return PosteriorSummary(results, log_value, self.integral.effective_samples)


def sample_posteriors(
    compiled: CompiledProblem, solutions: dict[str, np.ndarray], samples: int, rng: np.random.Generator, qmc: bool = False
) -> dict[str, PosteriorSummary]:
    """The posterior at each named X, all on the same L samples (drawn in chunks)."""
    objective = Objective(compiled)
    accumulators = {name: PosteriorAccumulator(compiled, objective, x) for name, x in solutions.items()}
    for chunk in FreeParameterSampler(compiled, qmc=qmc).draw_chunks(rng, samples, CHUNK):
        batch = Samples(chunk)
        for accumulator in accumulators.values():
            accumulator.add(batch)
    return {name: accumulator.summary() for name, accumulator in accumulators.items()}
