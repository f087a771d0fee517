"""Samples of the free parameters L (step 1 of Sect. 4.1.2 of the 2000 paper).

L is drawn from its prior p(L) such that the local relations of the tree
links (the propositions H_1 ... H_{m-p} of Eq. 2) hold. Parameters of
different links are independent, so the paper updates one link's component
at a time with Metropolis moves and rejects invalid candidates (Fig. 1).
bcad samples every distribution of the language exactly (inverse CDF or a
direct sampler), so it uses **exact rejection sampling** instead: draw every
link's parameters from the prior, then redraw, link by link, the rows that
break that link's relation until all hold. The result is distributed as the
prior restricted to the valid set, like the Metropolis chain's limit, but with
independent samples (no burn-in, no autocorrelation) and fully vectorised.

With ``qmc`` the first draw uses scrambled Sobol points (scipy.stats.qmc)
mapped through each distribution's inverse CDF; rejected rows are redrawn
pseudo-randomly.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from bcad.compiler import CompiledProblem
from bcad.kinematics.chain import Chain, LinkTransform, Samples
from bcad.model.distributions import Normal
from bcad.relations.geometry import RelationConstraint

MAX_REJECTION_ROUNDS = 200


#: L values held by one chunk of samples, at most (32 MB of doubles)
CHUNK_VALUES = 1 << 22


def chunk_rows(free_parameters: int, limit: int) -> int:
    """Samples per chunk: ``limit``, or fewer so that a chunk holds at most CHUNK_VALUES L
    values (a 3000-parameter cell draws 1398 samples at a time: memory does not grow with
    the number of L)."""
    return max(256, min(limit, CHUNK_VALUES // max(free_parameters, 1)))


def chunk_counts(n: int, chunk: int) -> list[int]:
    """The sizes of the chunks of n samples, ``chunk`` at most each."""
    return [min(chunk, n - start) for start in range(0, n, chunk)]


def chunk_streams(rng: np.random.Generator, count: int) -> list[np.random.Generator]:
    """One random stream per chunk: spawned from ``rng``, or ``rng`` itself for a single chunk."""
    return rng.spawn(count) if count > 1 else [rng]


@dataclass
class LocalRelation:
    """A tree link whose relation depends on L only: its valid set is sampled by rejection."""

    name: str
    loc: tuple
    relation: RelationConstraint
    chain: Chain  # T(Q) of the link alone
    groups: list[int]  # indices into the table's l_groups


class FreeParameterSampler:
    def __init__(self, compiled: CompiledProblem, qmc: bool = False):
        self.table = compiled.parameters
        self.source = compiled.problem.source
        self.qmc = qmc
        self.local: list[LocalRelation] = []
        closing = set(compiled.graph.closing_links)
        for index, link in enumerate(compiled.graph.links):
            if link.relation is None or index in closing or "X" in link.status:
                continue
            columns = {p.name: k for k, p in enumerate(self.table.l) if p.link == index}
            # the link's own L and its relation's uncertain dimensions (a face's size): rejection
            # redraws all of them, so the kept draws follow the prior restricted to the valid set
            involved = set(columns.values()) | {column for _, column, _ in link.relation.uncertain}
            groups = [g for g, group in enumerate(self.table.l_groups) if set(group.columns) & involved]
            chain = Chain([(LinkTransform(compiled.transforms[index].parameters), True)])
            self.local.append(LocalRelation(link.name, link.loc, link.relation, chain, groups))

    def _fill(self, values: np.ndarray, rows: np.ndarray, groups, rng: np.random.Generator, uniforms=None) -> None:
        every_row = len(rows) == len(values)
        normal_columns, normal_means, normal_stds = [], [], []
        offset = 0
        for g, group in enumerate(self.table.l_groups):
            dimension = group.distribution.dimension
            if g in groups:
                if uniforms is None and isinstance(group.distribution, Normal):
                    # Gaussian groups are drawn together below: one generator call, not one per group.
                    normal_columns.extend(group.columns)
                    normal_means.append(group.distribution.mean)
                    normal_stds.append(group.distribution.std)
                    offset += dimension
                    continue
                if uniforms is not None:
                    draw = group.distribution.from_uniform(uniforms[:, offset : offset + dimension])
                else:
                    draw = group.distribution.sample(rng, len(rows))
                draw = draw.reshape(len(rows), dimension)
                if every_row:  # plain column assignment
                    values[:, list(group.columns)] = draw
                else:
                    values[np.ix_(rows, group.columns)] = draw
            offset += dimension
        if normal_columns:
            draw = rng.standard_normal((len(rows), len(normal_columns)))
            draw *= np.array(normal_stds)
            draw += np.array(normal_means)
            if every_row and normal_columns == list(range(values.shape[1])):
                values[...] = draw  # every L is Gaussian, in column order
            elif every_row:
                values[:, normal_columns] = draw
            else:
                values[np.ix_(rows, normal_columns)] = draw

    def _sobol(self, rng: np.random.Generator):
        if not (self.qmc and self.table.l_groups):
            return None
        from scipy.stats import qmc

        dimension = sum(group.distribution.dimension for group in self.table.l_groups)
        return qmc.Sobol(dimension, scramble=True, seed=rng)

    def draw(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """N samples of L (deviations from nominal), shape (N, nL)."""
        return self._draw(rng, n, self._sobol(rng))

    def draw_chunks(self, rng: np.random.Generator, n: int, chunk: int):
        """N samples in successive arrays of at most ``chunk`` rows (one Sobol sequence throughout)."""
        sobol = self._sobol(rng)
        for count in chunk_counts(n, chunk):
            yield self._draw(rng, count, sobol)

    def _draw(self, rng: np.random.Generator, n: int, sobol) -> np.ndarray:
        values = np.zeros((n, len(self.table.l)))
        every_row = np.arange(n)
        all_groups = set(range(len(self.table.l_groups)))
        uniforms = None
        if sobol is not None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # n need not be a power of two
                uniforms = sobol.random(n)
        self._fill(values, every_row, all_groups, rng, uniforms)
        for local in self.local:
            for _ in range(MAX_REJECTION_ROUNDS):
                samples = Samples(values)
                transform = local.chain.evaluate(np.zeros(0), samples)
                bound = local.relation.bind(samples.columns)
                bad = np.flatnonzero(np.isinf(bound.log_satisfaction(transform.columns, transform.translations, 0.0)))
                if bad.size == 0:
                    break
                self._fill(values, bad, set(local.groups), rng)
            else:
                raise self.source.error(
                    local.loc,
                    f"the relation of tree link '{local.name}' rejects almost every draw of its prior "
                    f"({bad.size} of {n} still invalid after {MAX_REJECTION_ROUNDS} rounds); "
                    "check its nominal pose and distributions",
                )
        return values
