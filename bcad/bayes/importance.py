"""Importance sampling of I(X) with a conditional Laplace proposal.

I(X) = E_p(L)[f(X, L)], f the integrand of Eq. 2 (closing links' scores times
the relations' indicators). Plain Monte Carlo (Sect. 4.1.2) wastes almost
every prior draw where the scores are narrow (the RX90 example: 20 effective
samples per 1e5). A single global Gaussian proposal is not enough either:
second-order effects of the joint errors move the closing pose by more than
the scores' width, and its weights are heavy-tailed. This proposal is
conditional, per sample:

1. Whiten the Gaussian free parameters, z = (L_G - mu_G) / sigma_G ~ N(0, I)
   (``normal`` L not involved in a tree link's local relation; the others are
   drawn from their prior as they are). From the linearisation
   (:mod:`bcad.bayes.linear`), the whitened scored residual moves along
   A = Sigma_O^-1/2 J_O sigma_G; its r <= k right singular vectors V span the
   few directions that move the scores. Split z = V u + w: u ~ N(0, I_r) and
   w (the rest) are independent, and w is drawn from the prior.
2. Given w, go to the conditional mode of u, the maximiser of
   -|u|^2/2 - |Sigma_O^-1/2 (d(u, w) - mu_O)|^2 / 2, by two Gauss-Newton steps:
   the first with the global A V, the second with each sample's own Jacobian
   (forward differences, r + 1 batched chain evaluations).
3. Draw u from the local Gaussian N(u*, H^-1), H = I + J^T J, mixed
   defensively with the prior N(0, I) (weight DEFENSIVE), which bounds the
   weights where the local Gaussian is too narrow.
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
from dataclasses import dataclass, field

import numpy as np

from bcad.bayes.linear import LinearModel
from bcad.bayes.weights import pareto_k_of_tail, tail_size
from bcad.compile import CompiledProblem
from bcad.kinematics.chain import Samples
from bcad.model.distributions import Normal
from bcad.model.pose import LENGTH_PARAMETERS, PARAMETERS
from bcad.solvers.objective import Objective, wrap_angle
from bcad.solvers.sampling import FreeParameterSampler

#: weight of the prior in the defensive mixture (Hesterberg 1995)
DEFENSIVE = 0.1
#: samples per chunk
CHUNK = 1 << 15
#: forward-difference step of the per-sample Jacobian, in whitened units
JACOBIAN_STEP = 1e-5
ANGULAR = np.array([name not in LENGTH_PARAMETERS for name in PARAMETERS])
LOG_TWO_PI = math.log(2.0 * math.pi)


class WeightedPoseSums:
    """Streaming sums for self-normalised weighted means and stds with their standard errors.

    With normalised weights v_i = w_i / sum w and deviations e = x - mean:
    se(mean)^2 = sum v_i^2 e_i^2, and for the variance s^2 = sum v_i e_i^2,
    se(s^2)^2 = sum v_i^2 (e_i^2 - s^2)^2, se(s) = se(s^2) / (2 s) (delta
    method). The sums are of powers of x - c about a centre c taken from the
    first chunk, so nothing cancels; weights are rescaled as their running
    maximum grows.
    """

    def __init__(self, width: int, angular: np.ndarray):
        self.angular = angular
        self.centre: np.ndarray | None = None
        self.log_scale = -np.inf
        self.w = 0.0
        self.w2 = 0.0
        self.first = np.zeros(width)  # sum w d
        self.second = np.zeros(width)  # sum w d^2
        self.squared = np.zeros((5, width))  # sum w^2 d^p, p = 0..4

    def add(self, log_weights: np.ndarray, values: np.ndarray) -> None:
        if self.centre is None:
            self.centre = values.mean(axis=0)
            angles = values[:, self.angular]
            self.centre[self.angular] = np.arctan2(np.sin(angles).mean(axis=0), np.cos(angles).mean(axis=0))
        peak = np.max(log_weights) if log_weights.size else -np.inf
        if not np.isfinite(peak):
            return
        if peak > self.log_scale:
            shrink = math.exp(self.log_scale - peak) if np.isfinite(self.log_scale) else 0.0
            self.w *= shrink
            self.first *= shrink
            self.second *= shrink
            self.w2 *= shrink * shrink
            self.squared *= shrink * shrink
            self.log_scale = peak
        weights = np.exp(log_weights - self.log_scale)
        d = values - self.centre
        d[:, self.angular] = wrap_angle(d[:, self.angular])
        self.w += weights.sum()
        self.w2 += weights @ weights
        self.first += weights @ d
        self.second += weights @ (d * d)
        w2 = weights * weights
        power = np.ones_like(d)
        for p in range(5):
            self.squared[p] += w2 @ power
            power = power * d

    def summary(self) -> dict[str, np.ndarray] | None:
        if self.w <= 0.0:
            return None
        a = self.first / self.w  # mean of d
        variance = np.maximum(self.second / self.w - a * a, 0.0)
        S = self.squared / (self.w * self.w)  # S[p] = sum v^2 d^p
        # sum v^2 (d - a)^2 and sum v^2 (d - a)^4, expanded in the powers of d.
        e2 = S[2] - 2 * a * S[1] + a * a * S[0]
        e4 = S[4] - 4 * a * S[3] + 6 * a**2 * S[2] - 4 * a**3 * S[1] + a**4 * S[0]
        spread = np.maximum(e4 - 2 * variance * e2 + variance**2 * S[0], 0.0)
        std = np.sqrt(variance)
        mean = a + self.centre
        mean[self.angular] = wrap_angle(mean[self.angular])
        std_se = np.where(std > 0, np.sqrt(spread) / np.where(std > 0, 2 * std, 1.0), 0.0)
        return {"mean": mean, "std": std, "mean_se": np.sqrt(np.maximum(e2, 0.0)), "std_se": std_se}


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

    def __init__(self, compiled: CompiledProblem, objective: Objective | None = None, linear: LinearModel | None = None):
        self.compiled = compiled
        self.objective = objective or Objective(compiled)
        self.linear = linear or LinearModel(compiled, self.objective)
        self.prior = FreeParameterSampler(compiled)
        table = compiled.parameters
        local = {column for relation in self.prior.local for g in relation.groups for column in table.l_groups[g].columns}
        gaussian = [
            column
            for group in table.l_groups
            if isinstance(group.distribution, Normal)
            for column in group.columns
            if column not in local
        ]
        self.gaussian = np.array(gaussian, dtype=int)
        self.scale_o = np.sqrt(self.linear.scored_variance)

    # -- pieces ---------------------------------------------------------------
    def _directions(self, x: np.ndarray) -> np.ndarray:
        """V (nG, r): the whitened Gaussian directions that move the scored residual."""
        if not len(self.gaussian) or not len(self.scale_o):
            return np.zeros((len(self.gaussian), 0))
        lin = self.linear.linearise(x[None])
        J = lin.jacobians[0][self.linear.scored_rows][:, self.gaussian]
        A = J * np.sqrt(self.linear.variance_l[self.gaussian]) / self.scale_o[:, None]
        _, singular, vt = np.linalg.svd(A, full_matrices=False)
        rank = int(np.sum(singular > 1e-12 * max(singular.max(initial=0.0), 1e-300)))
        return vt[:rank].T

    def _residuals(self, x: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Whitened scored residuals (d - mu_O) / sigma_O for L samples (n, nL): shape (n, k)."""
        samples = Samples(values)
        poses = np.concatenate([cycle.chain.evaluate(x, samples).poses() for cycle in self.objective.cycles], axis=-1)
        deviation = self.linear.scored_deviation(poses)
        return (deviation - self.linear.scored_mean) / self.scale_o

    def draw(self, x: np.ndarray, n: int, rng: np.random.Generator, directions: np.ndarray):
        """n samples of L from the proposal and their log (p / q) on the adapted part, shape (n, nL), (n,)."""
        values = self.prior.draw(rng, n)
        r = directions.shape[1]
        if r == 0:
            return values, np.zeros(n)
        columns = self.gaussian
        mean = self.linear.mean_l[columns]
        sd = np.sqrt(self.linear.variance_l[columns])
        z = (values[:, columns] - mean) / sd
        rest = z - (z @ directions) @ directions.T

        def with_u(u: np.ndarray) -> np.ndarray:
            moved = values.copy()
            moved[:, columns] = mean + sd * (rest + u @ directions.T)
            return moved

        # Gauss-Newton step 1, from u = 0 with the global Jacobian A V.
        lin = self.linear.linearise(x[None])
        J = lin.jacobians[0][self.linear.scored_rows][:, columns] * sd / self.scale_o[:, None]
        B = J @ directions  # (k, r)
        u = np.zeros((n, r))
        residual = self._residuals(x, with_u(u))
        u = -np.linalg.solve(np.eye(r) + B.T @ B, (residual @ B).T).T
        # Step 2, with each sample's own Jacobian (r + 1 evaluations).
        residual = self._residuals(x, with_u(u))
        jacobian = np.empty((n, residual.shape[1], r))
        for i in range(r):
            shifted = u.copy()
            shifted[:, i] += JACOBIAN_STEP
            jacobian[:, :, i] = (self._residuals(x, with_u(shifted)) - residual) / JACOBIAN_STEP
        bad = ~np.all(np.isfinite(jacobian), axis=(1, 2)) | ~np.all(np.isfinite(residual), axis=1)
        jacobian[bad], residual[bad] = 0.0, 0.0
        H = np.eye(r) + np.swapaxes(jacobian, 1, 2) @ jacobian
        gradient = u + np.einsum("nkr,nk->nr", jacobian, residual)
        mode = u - np.linalg.solve(H, gradient[..., None])[..., 0]
        chol = np.linalg.cholesky(H)  # H = C C^T: the local Gaussian is N(mode, C^-T C^-1)
        local = mode + np.linalg.solve(np.swapaxes(chol, 1, 2), rng.standard_normal((n, r, 1)))[..., 0]
        from_prior = rng.random(n) < DEFENSIVE
        u = np.where(from_prior[:, None], rng.standard_normal((n, r)), local)
        log_prior = -0.5 * np.sum(u * u, axis=1) - 0.5 * r * LOG_TWO_PI
        whitened = np.einsum("nrk,nr->nk", chol, u - mode)  # C^T (u - mode)
        log_local = -0.5 * np.sum(whitened**2, axis=1) + np.sum(np.log(np.diagonal(chol, axis1=1, axis2=2)), axis=1)
        log_local -= 0.5 * r * LOG_TWO_PI
        log_proposal = np.logaddexp(math.log(DEFENSIVE) + log_prior, math.log1p(-DEFENSIVE) + log_local)
        return with_u(u), log_prior - log_proposal

    # -- the estimate -----------------------------------------------------------
    def estimate(self, x: np.ndarray, n: int, rng: np.random.Generator) -> ImportanceEstimate:
        """log I(X) by importance sampling with n samples, and the closing links' weighted posteriors."""
        x = np.asarray(x, dtype=float)
        directions = self._directions(x)
        sums = [WeightedPoseSums(6, ANGULAR) for _ in self.objective.cycles]
        total = WeightedPoseSums(0, np.zeros(0, dtype=bool))
        keep = tail_size(n)
        tail = np.empty(0)
        for start in range(0, n, CHUNK):
            count = min(CHUNK, n - start)
            values, log_ratio = self.draw(x, count, rng, directions)
            samples = Samples(values)
            log_weights = log_ratio.copy()
            poses = []
            for cycle in self.objective.cycles:
                transform = cycle.chain.evaluate(x, samples)
                pose = transform.poses()
                poses.append(pose)
                for group in cycle.observed:
                    log_weights += group.log_density(pose, 0.0)
                if cycle.relation is not None:
                    log_weights += cycle.relation.log_satisfaction(transform.columns, transform.translations, 0.0)
            for relation, chain in self.objective.tree_relations:
                transform = chain.evaluate(x, samples)
                log_weights += relation.log_satisfaction(transform.columns, transform.translations, 0.0)
            log_weights = np.where(np.isnan(log_weights), -np.inf, log_weights)
            for pose, link_sums in zip(poses, sums):
                link_sums.add(log_weights, pose)
            total.add(log_weights, np.zeros((count, 0)))
            merged = np.concatenate([tail, log_weights[np.isfinite(log_weights)]])
            tail = merged if len(merged) <= keep else np.partition(merged, len(merged) - keep)[-keep:]
        if total.w > 0:
            mean_weight = total.w / n
            log_integral = total.log_scale + math.log(mean_weight)
            variance = max(total.w2 / n - mean_weight**2, 0.0)
            se = math.sqrt(variance / n) / mean_weight
            ess = total.w**2 / total.w2
        else:
            log_integral, se, ess = -math.inf, math.inf, 0.0
        return ImportanceEstimate(
            log_integral=log_integral,
            log_integral_se=se,
            effective_samples=ess,
            pareto_k=pareto_k_of_tail(tail, n),
            samples=n,
            directions=directions.shape[1],
            links=[link_sums.summary() for link_sums in sums],
        )
