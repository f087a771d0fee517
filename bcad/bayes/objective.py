"""The objective p(X) I(X) of Eq. 2, estimated by Monte Carlo in log space.

For a population of X and a batch of L samples (Sect. 4.1.2, step 2):

    log G^T_N(X) = log p(X) + log (1/N) sum_i prod_cycles p^T_O(F(X, L_i)) p^T(H | F(X, L_i)),

where F(X, L_i) is the pose each cycle's closing link must have for the
cycle to close (Eq. 1), p_O the closing link's distributions (of the
deviation from its nominal pose) and p(H | .) its relation's inequality
constraints; T is the temperature of Sect. 4.2.1 (T = 0: the original
objective). Tree links whose relation involves X contribute their
p(H_k | X, L) too. The sum over samples is a log-sum-exp, so a product of
densities never underflows to 0 where its log is finite.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bcad.compiler import CompiledProblem
from bcad.kinematics.chain import Chain, LinkTransform, Samples
from bcad.kinematics.se3 import wrap_angle
from bcad.model.pose import LENGTH_PARAMETERS, PARAMETERS
from bcad.relations.geometry import RelationConstraint

#: individual-samples evaluated at once (P x N): about 20 MB per working array.
CHUNK = 1 << 18

#: log of the smallest normal double: below it the paper's G would be 0.0.
LOG_ZERO = math.log(np.finfo(float).tiny)


def log_mean_exp(values: np.ndarray, axis: int = -1) -> np.ndarray:
    """log(mean(exp(values))) along ``axis``, exact for -inf entries."""
    peak = np.max(values, axis=axis, keepdims=True)
    safe = np.where(np.isfinite(peak), peak, 0.0)
    with np.errstate(divide="ignore"):
        total = np.log(np.mean(np.exp(values - safe), axis=axis)) + np.squeeze(safe, axis=axis)
    return np.where(np.isneginf(np.squeeze(peak, axis=axis)), -np.inf, total)


@dataclass
class ObservedGroup:
    """A distribution on parameters of a closing link: the p_O of Eq. 2."""

    distribution: object
    slots: tuple[int, ...]
    nominal: np.ndarray
    angular: bool

    def log_density(self, poses: np.ndarray, temperature: float) -> np.ndarray:
        deviation = poses[..., list(self.slots)] - self.nominal
        if self.angular:
            deviation = wrap_angle(deviation)
        if len(self.slots) == 1:
            deviation = deviation[..., 0]
        return self.distribution.tempered_logpdf(deviation, temperature)


@dataclass
class CycleTerm:
    name: str
    chain: Chain
    observed: list[ObservedGroup]
    relation: RelationConstraint | None


def observed_groups(compiled: CompiledProblem, link_index: int) -> list[ObservedGroup]:
    link = compiled.graph.links[link_index]
    groups = []
    for names, distribution in link.distributions.items():
        slots = tuple(PARAMETERS.index(name) for name in names)
        angular = names[0] not in LENGTH_PARAMETERS
        groups.append(ObservedGroup(distribution, slots, link.nominal[list(slots)], angular))
    return groups


def periodic_unknowns(compiled: CompiledProblem) -> np.ndarray:
    """Per X, its period 2 pi where p(X) I(X) repeats every turn of it, else inf.

    An angle enters the poses only through R = Rz Ry Rx, which every whole turn of rx, ry or rz
    leaves unchanged; so an angular X with a uniform prior whose bounds span at least one turn
    (a UR5's +-2 pi joints) is periodic, provided it appears only in angular slots with whole
    coefficients (a mimic joint of factor 0.5 breaks it; a prismatic use of it is not an angle):
    :func:`turning_unknowns`. The search then wraps it instead of stopping at an artificial bound,
    and does not count a maximum a turn away as another basin.
    """
    table = compiled.parameters
    spans = np.array([high - low for low, high in table.x_bounds], dtype=float).reshape(-1)
    whole_turn = spans >= 2.0 * math.pi * (1.0 - 1e-12)
    return np.where(turning_unknowns(compiled) & whole_turn, 2.0 * math.pi, np.inf)


def turning_unknowns(compiled: CompiledProblem) -> np.ndarray:
    """Per X, whether it would be periodic if its bounds spanned a whole turn
    (:func:`periodic_unknowns`): an angle with a uniform prior that enters the poses only in
    angular slots, with whole coefficients."""
    table = compiled.parameters
    turning = np.array([parameter.slot >= 3 for parameter in table.x], dtype=bool)
    for group in table.x_priors:
        turning[list(group.columns)] = False
    for transform in compiled.transforms:
        for slot, parameter in enumerate(transform.parameters):
            for term in parameter.terms:
                whole = abs(term.coefficient - round(term.coefficient)) < 1e-12 and round(term.coefficient) != 0
                if term.source == "x" and (slot < 3 or not whole):
                    turning[term.index] = False
    return turning


class Objective:
    """log G^T_N(X) for populations of X on batches of L samples."""

    def __init__(self, compiled: CompiledProblem):
        self.compiled = compiled
        self.table = compiled.parameters
        self.cycles = [
            CycleTerm(
                compiled.graph.links[cycle.closing_link].name,
                chain,
                observed_groups(compiled, cycle.closing_link),
                compiled.graph.links[cycle.closing_link].relation,
            )
            for cycle, chain in zip(compiled.graph.cycles, compiled.cycle_chains)
        ]
        closing = set(compiled.graph.closing_links)
        # Tree relations that involve X cannot be sampled away: they weigh the integrand.
        self.tree_relations = [
            (link.relation, Chain([(LinkTransform(compiled.transforms[index].parameters), True)]))
            for index, link in enumerate(compiled.graph.links)
            if link.relation is not None and index not in closing and "X" in link.status
        ]
        self.bounds = np.array(self.table.x_bounds, dtype=float).reshape(-1, 2)
        #: per X: 2 pi where the objective is 2 pi-periodic in it (:func:`periodic_unknowns`), else inf
        self.periods = periodic_unknowns(compiled)
        nominal = np.array(self.table.x_nominal, dtype=float)
        periodic = np.isfinite(self.periods)
        #: the canonical period of each periodic X: [start, start + 2 pi), centred on its nominal
        #: value where its bounds allow (a joint reported near its zero, not a turn away)
        self.period_starts = np.where(
            periodic,
            np.clip(nominal - math.pi, self.bounds[:, 0], self.bounds[:, 1] - np.where(periodic, self.periods, 0.0)),
            self.bounds[:, 0],
        )

    @property
    def dimension(self) -> int:
        return len(self.table.x)

    def canonical(self, population: np.ndarray) -> np.ndarray:
        """Each periodic X moved into its canonical period (the same poses, so the same p(X) I(X))."""
        population = np.array(population, dtype=float)
        periodic = np.isfinite(self.periods)
        if periodic.any():
            start, period = self.period_starts[periodic], self.periods[periodic]
            population[..., periodic] = start + np.mod(population[..., periodic] - start, period)
        return population

    def separation(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Max-norm distance between X's, each coordinate relative to its bounds' width, a
        periodic X's the shorter way round its circle (broadcasts over leading axes)."""
        width = self.bounds[:, 1] - self.bounds[:, 0]
        difference = np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float))
        periodic = np.isfinite(self.periods)
        if periodic.any():
            around = np.mod(difference[..., periodic], self.periods[periodic])
            difference[..., periodic] = np.minimum(around, self.periods[periodic] - around)
        return np.max(difference / width, axis=-1)

    def log_prior(self, population: np.ndarray) -> np.ndarray:
        """log p(X): each X's prior (default uniform on its bounds), -inf outside the bounds."""
        population = np.atleast_2d(population)
        inside = np.all((population >= self.bounds[:, 0]) & (population <= self.bounds[:, 1]), axis=1)
        uniform = np.ones(self.dimension, dtype=bool)
        for group in self.table.x_priors:
            uniform[list(group.columns)] = False
        widths = self.bounds[uniform, 1] - self.bounds[uniform, 0]
        total = np.where(inside, -np.sum(np.log(widths)), -np.inf)
        for group in self.table.x_priors:
            values = population[:, list(group.columns)]
            total = total + group.distribution.logpdf(values[:, 0])
        return total

    def _log_integrand(self, evaluate, shape: tuple[int, ...], temperature: float, samples: Samples) -> np.ndarray:
        """Sum of the log terms of the integrand, with ``evaluate(chain)`` giving each chain's
        transforms on ``samples`` (whose L also sets the relations' uncertain dimensions)."""
        total = np.zeros(shape)
        for cycle in self.cycles:
            transform = evaluate(cycle.chain)
            if cycle.observed:
                poses = transform.poses()
                for group in cycle.observed:
                    total += group.log_density(poses, temperature)
            if cycle.relation is not None:
                total += cycle.relation.bind(samples.columns).log_satisfaction(
                    transform.columns, transform.translations, temperature
                )
        for relation, chain in self.tree_relations:
            transform = evaluate(chain)
            total += relation.bind(samples.columns).log_satisfaction(
                transform.columns, transform.translations, temperature
            )
        return total

    def log_integrand(self, population: np.ndarray, samples: Samples, temperature: float) -> np.ndarray:
        """The log integrand of I(X) for every individual and sample, shape (P, N)."""
        population = np.atleast_2d(population)
        return self._log_integrand(
            lambda chain: chain.evaluate_population(population, samples),
            (population.shape[0], samples.count),
            temperature,
            samples,
        )

    def log_value(self, population: np.ndarray, samples: Samples, temperature: float) -> np.ndarray:
        """log p(X) + log Î(X) for each individual, all on the same samples (common random numbers).

        Large populations are evaluated in chunks of about CHUNK individual-samples,
        which keeps the working arrays in cache-friendly sizes.
        """
        population = np.atleast_2d(population)
        rows = max(1, CHUNK // samples.count)
        log_integral = np.concatenate(
            [
                log_mean_exp(self.log_integrand(population[start : start + rows], samples, temperature), axis=1)
                for start in range(0, population.shape[0], rows)
            ]
        )
        return self.log_prior(population) + log_integral

    def log_value_independent(self, population: np.ndarray, samples: Samples, temperature: float) -> np.ndarray:
        """Like :meth:`log_value`, but individual p uses its own rows p*N..(p+1)*N-1 of ``samples``
        (the paper's evaluation: no common random numbers)."""
        population = np.atleast_2d(population)
        count = population.shape[0]
        per_sample = np.repeat(population, samples.count // count, axis=0)
        total = self._log_integrand(
            lambda chain: chain.evaluate(per_sample, samples), (samples.count,), temperature, samples
        )
        return self.log_prior(population) + log_mean_exp(total.reshape(count, -1), axis=1)
