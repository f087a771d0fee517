"""Importance sampling of I(X) with a conditional Laplace proposal.

I(X) = E_p(L)[f(X, L)], f the integrand of Eq. 2 (closing links' scores times
the relations' indicators). Plain Monte Carlo (Sect. 4.1.2) wastes almost
every prior draw where the scores are narrow (the RX90 example: 20 effective
samples per 1e5). A single global Gaussian proposal is not enough either:
second-order effects of the joint errors move the closing pose by more than
the scores' width, and its weights are heavy-tailed. This proposal is
conditional, per sample:

1. Whiten the adapted free parameters, z ~ N(0, I): a ``normal`` L is
   mu + sigma z, a ``uniform`` or ``truncnormal`` one F^-1(Phi(z)) (its
   quantile at the normal's probability: the same distribution, and the
   proposal can follow a posterior far narrower than the prior). L in a tree
   link's local relation and ``disc`` L are drawn from their prior as they
   are. Where a transformed L is adapted, the Jacobian is taken at the
   conditional mode of the central sample (Gauss-Newton with its own
   derivatives), since F^-1(Phi(z)) bends: a narrow score near a uniform's
   edge sees a slope several times smaller than at its centre. From the linearisation
   (:mod:`bcad.bayes.linear`), the whitened scored residual moves along
   A = Sigma_O^-1/2 J_O sigma_G; its r <= k right singular vectors V span the
   few directions that move the scores. Split z = V u + w: u ~ N(0, I_r) and
   w (the rest) are independent, and w is drawn from the prior.
2. Given w, go to the conditional mode of u, the maximiser of
   -|u|^2/2 - |Sigma_O^-1/2 (d(u, w) - mu_O)|^2 / 2, by Gauss-Newton steps
   with the global Jacobian B = A V: the first on the linearised residual,
   then CHORD_STEPS chord steps on the exact one (a batched chain evaluation
   each), which catch the second-order effects that move the closing pose.
   One chord step is enough with the proposal of step 3: on the RX90 example at
   its solution (1e5 samples, 10 seeds) one step and two gave the same 40 %
   effective samples, k̂ 0.01-0.14 and 0.00-0.10; at the nominal of the
   repository's examples and of 14 random cells of bench/random_cells.py's
   kinds (2e4 samples, 4 seeds) the same effective samples and k̂ ranges, for
   a chain evaluation less per sample. Per-sample Jacobians (r + 1 more
   evaluations) cost 1.8 times as much.
3. Draw u from a local Student-t with DOF = 4 degrees of freedom, centre u*
   and scale 1.2^2 H^-1, H = I + B^T B, mixed defensively with the prior
   N(0, I) (weight DEFENSIVE), which bounds the weights where the local
   proposal is too narrow. The t's heavier tail covers a target whose tail is
   not Gaussian, at a small cost where it is: on the RX90 example at another
   point of its ridge of maxima (1e5 samples, 12 seeds) a local Gaussian gave
   k̂ 0.51-0.71 (one run exited 3 on k̂ = 0.702), the t 0.43-0.58 at the same
   effective sample size; at the solution of ``bcad solve`` with its default
   seed (1e5 samples, 10 seeds) the t gives 40 % effective samples and k̂
   0.05-0.14, a local Gaussian 46 % and k̂ -0.20-0.02.
4. Weight exactly: w = N(u; 0, I) f(X, L) / q(u | w) with the exact scores
   and indicators, so the estimate is unbiased whatever the approximations.

The standard error of log Î is the delta method's sd(w) / (mean(w) sqrt(N)),
the effective sample size Kish's, and the Pareto k̂ of the weights (PSIS)
says whether those can be trusted (k̂ > 0.7: no). Samples are processed in
chunks; sums are streamed and only the weights' upper tail is kept for k̂,
so memory does not grow with the sample count.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from itertools import islice

import numpy as np

from bcad.bayes.linear import LinearModel
from bcad.bayes.objective import Objective, log_mean_exp
from bcad.bayes.sampling import FreeParameterSampler, chunk_counts, chunk_rows, chunk_streams
from bcad.compiler import CompiledProblem
from bcad.kinematics.chain import Samples
from bcad.model.distributions import Normal, TruncatedNormal, Uniform
from bcad.model.pose import ANGULAR
from bcad.numerics.streaming import LogWeightSums, WeightedPoseSums

#: weight of the prior in the defensive mixture (Hesterberg 1995)
DEFENSIVE = 0.1
#: chord steps on the exact residual (one chain evaluation each)
CHORD_STEPS = 1
#: the local Gaussian's standard deviations are widened by this factor: a proposal
#: slightly wider than the target keeps the weights' tail light
INFLATION = 1.2
#: degrees of freedom of the local Student-t (step 3)
DOF = 4.0
#: Gauss-Newton steps of the central sample's mode where non-Gaussian L are adapted, and the
#: chord steps added for every sample there
CENTRAL_STEPS = 12
CENTRAL_EXTRA_CHORD_STEPS = 2
#: samples per chunk. Smaller chunks keep each pass's arrays in cache and touch fewer fresh pages:
#: `bcad posterior` on the RX90 example at 1e5 samples took 1.10 s wall with 16384 (this and the
#: posterior's chunk), 1.18 s with 32768 and 1.31 s with 65536 (medians of 5, fresh processes)
CHUNK = 1 << 14
#: chunks submitted ahead to a thread pool (:meth:`ImportanceSampler.estimate`): enough to keep two
#: workers busy while the main thread sums, few enough that memory holds a handful of chunks
AHEAD_CHUNKS = 4
#: integrand values (rows of X times common samples) that one block of the common objective holds
COMMON_VALUES = 1 << 16
LOG_TWO_PI = math.log(2.0 * math.pi)


def student_t_log_density(squared_norm: np.ndarray, dimension: int, dof: float) -> np.ndarray:
    """log density of the standard multivariate Student-t (identity scale) at |z|^2 = squared_norm."""
    return (
        math.lgamma(0.5 * (dof + dimension))
        - math.lgamma(0.5 * dof)
        - 0.5 * dimension * math.log(dof * math.pi)
        - 0.5 * (dof + dimension) * np.log1p(squared_norm / dof)
    )


@dataclass
class ImportanceEstimate:
    """log I(X) and the weighted posterior of each cycle's closing pose at one X."""

    log_integral: float
    log_integral_se: float
    effective_samples: float
    pareto_k: float
    samples: int
    directions: int  # r: the few directions the proposal adapts
    links: list[dict[str, np.ndarray] | None] = field(default_factory=list)


class ImportanceSampler:
    """Estimates of I(X) by importance sampling (module docstring)."""

    def __init__(
        self, compiled: CompiledProblem, objective: Objective, linear: LinearModel, prior: FreeParameterSampler
    ):
        """The parts come from the problem's :class:`~bcad.bayes.model.BayesModel`, built once."""
        self.compiled = compiled
        self.objective = objective
        self.linear = linear
        self.prior = prior
        table = compiled.parameters
        local = {
            column for relation in self.prior.local for g in relation.groups for column in table.l_groups[g].columns
        }
        adapted, maps = [], []
        for group in table.l_groups:
            one_dimensional = isinstance(group.distribution, (Normal, Uniform, TruncatedNormal))
            if not one_dimensional or group.columns[0] in local:
                continue
            adapted.append(group.columns[0])
            maps.append(None if isinstance(group.distribution, Normal) else group.distribution)
        #: the adapted L columns: each is L = T(z) with z ~ N(0, 1) (module docstring, step 1)
        self.gaussian = np.array(adapted, dtype=int)
        #: per adapted column, the distribution whose quantile T(z) = F^-1(Phi(z)) maps it (None: Gaussian)
        self.latent_maps = maps
        self.transformed = np.array([m is not None for m in maps], dtype=bool)
        mean = self.linear.mean_l[self.gaussian]
        sd = np.sqrt(self.linear.variance_l[self.gaussian])
        #: dL/dz at z = 0: the Gaussians' std, F^-1(Phi(z))'s slope for the others
        self.latent_scale = sd.copy()
        self.latent_mean, self.latent_sd = mean, sd
        for k in np.flatnonzero(self.transformed):
            step = 1e-4
            ends = self._latent(np.array([-step, step]), k)
            self.latent_scale[k] = max(float(ends[1] - ends[0]) / (2.0 * step), 1e-300)
        self.scale_o = np.sqrt(self.linear.scored_variance)

    def _latent(self, z: np.ndarray, k: int) -> np.ndarray:
        """L of adapted column ``k`` at z: F^-1(Phi(z)) (Gaussian columns: mean + std z)."""
        distribution = self.latent_maps[k]
        if distribution is None:
            return self.latent_mean[k] + self.latent_sd[k] * z
        from scipy.special import ndtr

        return distribution.from_uniform(ndtr(np.asarray(z))[..., None])

    def latent_values(self, z: np.ndarray) -> np.ndarray:
        """L of every adapted column from z (nG, n)."""
        values = self.latent_mean[:, None] + self.latent_sd[:, None] * z
        for k in np.flatnonzero(self.transformed):
            values[k] = self._latent(z[k], k)
        return values

    # -- pieces ---------------------------------------------------------------
    def _directions(self, lin) -> np.ndarray:
        """V (nG, r): the whitened Gaussian directions that move the scored residual."""
        if not len(self.gaussian) or not len(self.scale_o):
            return np.zeros((len(self.gaussian), 0))
        J = lin.jacobians[0][self.linear.scored_rows][:, self.gaussian]
        A = J * self.latent_scale / self.scale_o[:, None]
        _, singular, vt = np.linalg.svd(A, full_matrices=False)
        rank = int(np.sum(singular > 1e-12 * max(singular.max(initial=0.0), 1e-300)))
        return vt[:rank].T

    def _residuals(self, x: np.ndarray, samples: Samples) -> np.ndarray:
        """Whitened scored residuals (d - mu_O) / sigma_O on a batch of L samples: shape (n, k)."""
        poses = np.concatenate([cycle.chain.evaluate(x, samples).poses() for cycle in self.objective.cycles], axis=-1)
        deviation = self.linear.scored_deviation(poses)
        return (deviation - self.linear.scored_mean) / self.scale_o

    def draw(
        self,
        x: np.ndarray,
        n: int,
        rng: np.random.Generator,
        lin,
        directions: np.ndarray,
        values: np.ndarray | None = None,
    ) -> tuple[Samples, np.ndarray]:
        """n samples of L from the proposal and their log (p / q) on the adapted part, given the
        linearisation ``lin`` at X and the adapted ``directions``; the proposal starts from
        ``values``, n draws of the prior (N, nL), where they are given (they are not changed),
        and from n draws of its own otherwise."""
        values = self.prior.draw(rng, n) if values is None else values
        r = directions.shape[1]
        if r == 0:
            return Samples(values), np.zeros(n)
        G = self.gaussian
        columns = np.array(values.T, order="C")  # (nL, n), the layout the chain evaluates: a copy, as it is changed
        transformed = self.transformed
        gaussian, gaussian_rows = ~transformed, G[~transformed]
        # z = (L - mean) / sd on the Gaussian columns; rest = z - V V^T z keeps the part that does
        # not move the scores, and L = (mean + sd rest) + (sd V) u. On the Gaussian rows the part
        # that does not move with u is L - (sd V)(V^T z): formed from the prior draw in place, with
        # one (r, nG) x (nG, n) product for V^T z and one back.
        sd = self.latent_sd[:, None]
        whitened = directions[gaussian] / sd[gaussian]  # V / sd: V^T z = whitened^T (L - mean)
        every_row = len(gaussian_rows) == len(columns) and bool(np.all(gaussian_rows == np.arange(len(columns))))
        gaussian_values = columns if every_row else columns[gaussian_rows]
        projection = whitened.T @ gaussian_values  # (r, n): V^T z
        projection -= whitened.T @ self.latent_mean[gaussian, None]
        transformed_z = np.zeros((0, n))
        if transformed.any():
            # The non-Gaussian columns' z drawn afresh (their prior draws are replaced by T(z): the
            # same distribution), after the others so that a Gaussian problem's stream is unchanged.
            transformed_z = rng.standard_normal((int(transformed.sum()), n))
            projection += directions[transformed].T @ transformed_z
        shift = np.zeros((len(columns), r))
        shift[gaussian_rows] = sd[gaussian] * directions[gaussian]
        base = columns  # this draw's own array: the adapted rows are overwritten
        if every_row:
            base -= shift @ projection
        else:
            base[gaussian_rows] = gaussian_values - shift[gaussian_rows] @ projection
        transformed_directions = directions[transformed]
        transformed_rest = transformed_z - transformed_directions @ projection  # rest's transformed rows
        transformed_columns = list(zip(G[transformed], np.flatnonzero(transformed)))  # (L column, adapted index)

        def with_u(u: np.ndarray) -> Samples:
            moved = shift @ u.T
            moved += base
            if transformed_columns:
                latent = transformed_rest + transformed_directions @ u.T
                for j, (row, k) in enumerate(transformed_columns):
                    moved[row] = self._latent(latent[j], k)
            return Samples.from_columns(moved)

        J_O = lin.jacobians[0][self.linear.scored_rows] / self.scale_o[:, None]  # (k, nL), whitened rows
        B = (J_O[:, G] * self.latent_scale) @ directions  # (k, r): the residual's Jacobian in u
        if transformed.any():
            # F^-1(Phi(z)) bends: the Jacobian at z = 0 can be far from the one where the samples
            # go (a narrow score near a uniform's edge). The mode of the central sample (rest = 0)
            # by Gauss-Newton with its own Jacobian, then every sample's chord steps from it
            # with that Jacobian.
            u, B = self._central_mode(x, directions, B)
            u = np.repeat(u[None, :], n, axis=0)
            precision = np.eye(r) + B.T @ B
            steps = CHORD_STEPS + CENTRAL_EXTRA_CHORD_STEPS
        else:
            # Gauss-Newton step 1 from u = 0, on the linearised residual (no chain evaluation).
            precision = np.eye(r) + B.T @ B
            offset = (self.linear.scored_deviation(lin.poses)[0] - self.linear.scored_mean) / self.scale_o
            residual = J_O @ base  # (k, n): J_O (L - mean_L) + offset, with L at u = 0
            residual += (offset - J_O @ self.linear.mean_l)[:, None]
            residual = residual.T
            u = -np.linalg.solve(precision, (residual @ B).T).T
            steps = CHORD_STEPS
        # Then chord steps on the exact residual, with the same Jacobian: they catch the
        # second-order effects that move the closing pose.
        for _ in range(steps):
            residual = self._residuals(x, with_u(u))
            residual[~np.all(np.isfinite(residual), axis=1)] = 0.0
            u = u - np.linalg.solve(precision, (u + residual @ B).T).T
        mode = u
        chol = np.linalg.cholesky(precision / INFLATION**2)  # H = C C^T: the local scale is C^-T C^-1
        # Student-t with DOF degrees of freedom: z / sqrt(chi2_DOF / DOF)
        scale = np.sqrt(DOF / rng.chisquare(DOF, n))
        local = mode + np.linalg.solve(chol.T, rng.standard_normal((r, n))).T * scale[:, None]
        from_prior = rng.random(n) < DEFENSIVE
        u = np.where(from_prior[:, None], rng.standard_normal((n, r)), local)
        log_prior = -0.5 * np.sum(u * u, axis=1) - 0.5 * r * LOG_TWO_PI
        whitened = (u - mode) @ chol  # rows of C^T (u - mode)
        log_local = student_t_log_density(np.sum(whitened**2, axis=1), r, DOF) + np.sum(np.log(np.diagonal(chol)))
        log_proposal = np.logaddexp(math.log(DEFENSIVE) + log_prior, math.log1p(-DEFENSIVE) + log_local)
        return with_u(u), log_prior - log_proposal

    def _central_mode(self, x, directions, B) -> tuple[np.ndarray, np.ndarray]:
        """The conditional mode u0 of the sample with rest = 0 and the other L at their means, and
        the residual's Jacobian there (Gauss-Newton, forward differences in u: r + 1
        chain evaluations of one sample each step)."""
        r = directions.shape[1]
        G = self.gaussian
        u = np.zeros(r)
        step = 1e-6
        for _ in range(CENTRAL_STEPS):
            points = np.vstack([u, u + step * np.eye(r)])  # (r + 1, r)
            moved = np.repeat(self.linear.mean_l[:, None], r + 1, axis=1)
            moved[G] = self.latent_values(directions @ points.T)
            residual = self._residuals(x, Samples.from_columns(moved))
            if not np.all(np.isfinite(residual)):
                break
            B = ((residual[1:] - residual[0]) / step).T  # (k, r)
            move = -np.linalg.solve(np.eye(r) + B.T @ B, u + B.T @ residual[0])
            u = u + move
            if np.max(np.abs(move)) < 1e-9:
                break
        return u, B

    @property
    def surrogate_is_exact(self) -> bool:
        """Whether I_lin's moment matching is exact in distribution: every L (and every score) a
        ``normal`` (or a calibration's multivariate normal); otherwise the surrogate's optimum is not the integrand's
        (:mod:`bcad.bayes.exact_climb`)."""
        return not self.compiled.parameters.not_normal()

    def common_objective(self, x: np.ndarray, n: int, rng: np.random.Generator):
        """log p(X') I(X') for populations of X' near X (and the samples' log-weights), on n
        samples of the proposal at X drawn once (common random numbers): a deterministic
        function of X' whose differences carry far less noise than independent estimates'. The
        weights p / q stay exact away from X (the defensive mixture bounds them); only their
        spread grows."""
        x = np.asarray(x, dtype=float)
        lin = self.linear.linearise(x[None])
        samples, log_ratio = self.draw(x, n, rng, lin, self._directions(lin))
        rows = max(1, COMMON_VALUES // max(n, 1))

        def values(population: np.ndarray, temperature: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
            """log p(X') I^T(X') for each row, and the log-weights (P, n) of the common samples (T > 0:
            the tempered integrand of Sect. 4.2.1)."""
            population = np.atleast_2d(population)
            parts = []
            for start in range(0, len(population), rows):
                block = population[start : start + rows]
                log_weights = self.objective.log_integrand(block, samples, temperature) + log_ratio[None, :]
                parts.append(np.where(np.isnan(log_weights), -np.inf, log_weights))
            log_weights = np.concatenate(parts)
            return self.objective.log_prior(population) + log_mean_exp(log_weights, axis=1), log_weights

        return values

    def moving_objective(self, n: int, seed: int):
        """log p(X') I(X') for populations of X', each on n samples of the proposal at X' itself
        drawn from the same random numbers (the generator seeded alike for every X'): a
        deterministic function of X' whose proposal follows the posterior as X' moves (where the
        proposal at one X would leave a narrow posterior behind within a step), at two to four
        times the cost of :meth:`common_objective`'s evaluations (the proposal's chord steps)."""

        def values(population: np.ndarray, temperature: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
            population = np.atleast_2d(np.asarray(population, dtype=float))
            rows = []
            for x in population:
                lin = self.linear.linearise(x[None])
                samples, log_ratio = self.draw(x, n, np.random.default_rng(seed), lin, self._directions(lin))
                log_weights = self.objective.log_integrand(x[None], samples, temperature)[0] + log_ratio
                rows.append(np.where(np.isnan(log_weights), -np.inf, log_weights))
            log_weights = np.array(rows)
            return self.objective.log_prior(population) + log_mean_exp(log_weights, axis=1), log_weights

        return values

    # -- the estimate -----------------------------------------------------------
    def prepare(self, x: np.ndarray) -> tuple:
        """What every chunk of an estimate at X shares: the linearisation at X and the adapted
        directions (:meth:`chunk`'s ``lin`` and ``directions``)."""
        lin = self.linear.linearise(np.asarray(x, dtype=float)[None])
        return lin, self._directions(lin)

    def chunk(self, x: np.ndarray, count: int, rng: np.random.Generator, lin, directions, values=None):
        """One chunk of the estimate: ``count`` samples' log-weights (log p / q times the
        integrand) and each cycle's closing poses; the proposal starts from the prior draws
        ``values`` where they are given (:meth:`draw`)."""
        samples, log_weights = self.draw(x, count, rng, lin, directions, values)
        poses = []
        for cycle in self.objective.cycles:
            transform = cycle.chain.evaluate(x, samples)
            pose = transform.poses()
            poses.append(pose)
            for group in cycle.observed:
                log_weights += group.log_density(pose, 0.0)
            if cycle.relation is not None:
                log_weights += cycle.relation.bind(samples.columns).log_satisfaction(
                    transform.columns, transform.translations, 0.0
                )
        for relation, chain in self.objective.tree_relations:
            transform = chain.evaluate(x, samples)
            log_weights += relation.bind(samples.columns).log_satisfaction(
                transform.columns, transform.translations, 0.0
            )
        return np.where(np.isnan(log_weights), -np.inf, log_weights), poses

    def summed(self, chunks, n: int, directions: np.ndarray) -> ImportanceEstimate:
        """The estimate from its ``chunks`` (:meth:`chunk`'s values, in order) of n samples in all."""
        sums = [WeightedPoseSums(n, ANGULAR) for _ in self.objective.cycles]
        total = LogWeightSums(n)
        for log_weights, poses in chunks:
            for pose, link_sums in zip(poses, sums):
                link_sums.add_values(log_weights, pose)
            total.add(log_weights)
        return ImportanceEstimate(
            log_integral=total.log_mean,
            log_integral_se=total.log_mean_se,
            effective_samples=total.effective_samples,
            pareto_k=total.pareto_k,
            samples=n,
            directions=directions.shape[1],
            links=[link_sums.moments() for link_sums in sums],
        )

    def estimate(self, x: np.ndarray, n: int, rng: np.random.Generator, pool=None) -> ImportanceEstimate:
        """log I(X) by importance sampling with n samples, and the closing links' weighted posteriors.

        Samples come in chunks of CHUNK, each from its own stream spawned from ``rng`` (one chunk:
        ``rng`` itself), and are summed in the chunks' order: with a thread ``pool``
        (``concurrent.futures``) the chunks are computed on its workers, with the same result
        bit for bit."""
        x = np.asarray(x, dtype=float)
        lin, directions = self.prepare(x)
        counts = chunk_counts(n, chunk_rows(len(self.linear.mean_l), CHUNK))
        jobs = [(x, count, stream, lin, directions) for count, stream in zip(counts, chunk_streams(rng, len(counts)))]
        return self.summed(in_order(pool, self.chunk, jobs), n, directions)


def in_order(pool, work, jobs: list[tuple]):
    """``work(*job)`` for each job, in the jobs' order. With a thread ``pool`` at most AHEAD_CHUNKS
    are submitted at a time, each the next as one is taken: the pool's workers run them in order,
    and memory holds a few chunks whatever the sample count; those not reached are cancelled if
    the caller stops (an error, an interrupt)."""
    if pool is None or len(jobs) < 2:
        for job in jobs:
            yield work(*job)
        return
    pending: deque = deque()
    upcoming = iter(jobs)
    try:
        for job in islice(upcoming, AHEAD_CHUNKS):
            pending.append(pool.submit(work, *job))
        while pending:
            found = pending.popleft().result()
            for job in islice(upcoming, 1):
                pending.append(pool.submit(work, *job))
            yield found
    finally:
        for future in pending:
            future.cancel()
