"""The importance-sampling check of the Laplace answer.

The Laplace approximation N(MAP, Sigma) is exact for a linear model with
Gaussian priors and noise; a calibration is neither (the kinematics bend,
a prior may be uniform). The check draws N samples from a proposal built on
the Laplace Gaussian and weighs each by the exact posterior over the
proposal:

    log w = -1/2 sum_rows w_r |r(theta)|^2 + log p(theta) - log q(theta),

p the exact priors (not their Gaussian surrogates), r the whitened residuals,
w_r the robust loss's row weights. The self-normalised weighted mean and std
are the posterior's, with the standard error of the mean, the effective
sample size and PSIS's Pareto k̂ (:mod:`bcad.numerics.weights`): k̂ > 0.7 means
the check itself cannot be trusted. The two answers disagree when a mean
moves by more than SHIFT Laplace std (beyond 3 standard errors) or a std
changes by a ratio outside STD_RATIO.

The proposal follows the posterior's curvature (:class:`CurvedLaplace`).
In the Laplace-whitened coordinates w (z = z* + L w, L L^T the covariance
of z), the directions the data barely see (their data information below
WEAK: the prior holds them) keep their prior's width however many rows
there are, and the kinematics bend along them: a full-DH chain's last zero
offset turns the reflector's offset about the last axis, so the posterior
is a curved ridge (a banana) whose straight Gaussian falls off it as the
fourth power of the distance (500 measurements: 9.4 in log density at 2
std). The proposal draws the weak coordinates a from the Gaussian and
shifts the others by the Gauss-Newton step to their conditional mode given
a, to second order (the INLA idea, in closed form):

    w_S = c + g(a),  g(a) = -A_S^T (R* + 1/2 Q[a, a]),

A = J L the whitened Jacobian (A^T A = I, so A_S^T A_W = 0), R* the stacked
residuals at the MAP and Q[a, a] their second derivative along a (central
differences at one std), followed by RIDGE_STEPS Gauss-Newton steps at each
draw's a (:meth:`CurvedLaplace.ridge`). The map (a, c) -> w is a shear (unit
Jacobian), so the proposal's density is that of (a, c): exact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bcad.numerics.streaming import WeightedPoseSums

#: the proposal's std over the Laplace std is 1 + SPREAD / sqrt(n)
SPREAD = 0.5
#: samples x parameters drawn at a time (the residuals are evaluated in the model's own chunks)
CHUNK = 1 << 18
#: samples of the first pass at most (held in memory for their moments)
FIRST_PASS_SAMPLES = 4096
#: the check fails (cannot be trusted) above this k̂, or below MIN_ESS effective samples
MAX_PARETO_K = 0.7
MIN_ESS = 100.0
#: the first pass's proposal is kept (and its draws counted) at this fraction of effective samples or
#: more; below it the proposal adapts to the pass's weighted moments, if it has MIN_ADAPT_ESS of them
KEEP_FRACTION = 0.5
MIN_ADAPT_ESS = 20.0
#: whitened directions whose data information is below this follow the curvature (the prior holds them),
#: at most CURVED of them (the weakest): their second derivatives cost CURVED (CURVED + 1) evaluations
WEAK = 0.5
CURVED = 12
#: Gauss-Newton steps that bring each draw of the weak coordinates back onto the posterior's ridge
RIDGE_STEPS = 2
#: ... taken where the second-order step misses the ridge by RIDGE_OFF (whitened) at RIDGE_PROBE std
RIDGE_OFF, RIDGE_PROBE = 0.05, 2.0
#: the Laplace answer is off when a mean moves by more than SHIFT of its std, or a std by a ratio outside STD_RATIO
SHIFT = 0.3
STD_RATIO = (0.8, 1.25)


@dataclass
class LaplaceCheck:
    samples: int
    mean: np.ndarray
    std: np.ndarray
    mean_se: np.ndarray
    effective_samples: float
    pareto_k: float

    @property
    def trusted(self) -> bool:
        return bool(self.effective_samples >= MIN_ESS and not self.pareto_k > MAX_PARETO_K)

    def disagreement(self, estimate: np.ndarray, std: np.ndarray) -> list[int]:
        """Positions where the Laplace answer (estimate, std) and the sampled posterior differ."""
        shift = np.abs(self.mean - estimate) - 3.0 * self.mean_se
        ratio = self.std / np.maximum(std, 1e-300)
        off = (shift > SHIFT * std) | (ratio < STD_RATIO[0]) | (ratio > STD_RATIO[1])
        return [int(k) for k in np.flatnonzero(off)]


def _proposal_factor(covariance: np.ndarray) -> tuple[np.ndarray, float]:
    """S with S S^T = the proposal's covariance, and log |det S|: Cholesky's, or, where rounding
    has left the covariance not quite positive definite (noise of 1e-12, 100,000 rows), the
    eigen-decomposition's with the eigenvalues floored at 1e-14 of the largest: a proposal a
    little wider in the directions the data pin down, whose density stays exact."""
    symmetric = 0.5 * (covariance + covariance.T)
    try:
        scale = np.linalg.cholesky(symmetric + 1e-300 * np.eye(len(symmetric)))
        return scale, float(np.sum(np.log(np.diagonal(scale))))
    except np.linalg.LinAlgError:
        values, vectors = np.linalg.eigh(symmetric)
        values = np.maximum(values, max(float(values.max(initial=0.0)), 1e-300) * 1e-14)
        return vectors * np.sqrt(values), float(0.5 * np.sum(np.log(values)))


class CurvedLaplace:
    """The Laplace Gaussian bent along the posterior's weak directions (module docstring): base
    coordinates y = (a, c) ~ N(mean, covariance), w = y with g(a) added to the strong part, and
    z = z* + basis w. ``draw`` returns the parameter vectors, their y and log q up to a constant."""

    def __init__(self, objective, z_map: np.ndarray, covariance_z: np.ndarray, jacobian: np.ndarray):
        self.objective = objective
        n = len(z_map)
        self.z_map = z_map
        factor, _ = _proposal_factor(covariance_z)
        whitened = jacobian @ factor
        data = whitened[int(objective.prior_rows.sum()) :]
        information, rotation = np.linalg.eigh(data.T @ data)
        self.basis = factor @ rotation  # z = z* + basis w; eigenvalues ascending: the weakest first
        self.weak = np.zeros(n, dtype=bool)
        self.weak[: min(CURVED, int(np.sum(information < WEAK)), n - 1)] = True
        strong = whitened @ rotation[:, ~self.weak]  # A_S
        self.strong = strong
        centre = self._projected(z_map[None], strong)[0]  # A_S^T R*
        self.shift = -centre  # g(0): the MAP's own Gauss-Newton step, ~0
        self.curvature = self._curvature(strong, centre)
        self.ridge_steps = self._ridge_steps()
        self.mean, self.covariance = np.zeros(n), np.eye(n)

    def _stacked_residuals(self, z: np.ndarray) -> np.ndarray:
        """R(z): the prior rows and the weighted data rows of the least-squares objective, (S, rows)."""
        objective = self.objective
        data = objective.model.residuals_batch(objective.theta(z)) * objective.sqrt_weights
        return np.concatenate([z[:, objective.prior_rows], data], axis=1)

    def _projected(self, z: np.ndarray, strong: np.ndarray) -> np.ndarray:
        """R(z) A_S, CHUNK residuals at a time (the residuals of every z are never held at once)."""
        step = max(1, CHUNK // max(1, strong.shape[0]))
        return np.concatenate(
            [self._stacked_residuals(z[start : start + step]) @ strong for start in range(0, len(z), step)]
        )

    def _curvature(self, strong: np.ndarray, centre: np.ndarray) -> np.ndarray:
        """A_S^T Q[e_i, e_j] for the weak directions i, j: (k, k, n - k), from central second
        differences at one std (e_i + e_j by polarisation)."""
        weak = self.basis[:, self.weak].T
        k = len(weak)
        if k == 0:
            return np.zeros((0, 0, strong.shape[1]))
        pairs = [(i, j) for i in range(k) for j in range(i + 1, k)]
        steps = np.concatenate([weak, [weak[i] + weak[j] for i, j in pairs]]) if pairs else weak
        plus = self._projected(self.z_map + steps, strong)
        minus = self._projected(self.z_map - steps, strong)
        second = plus + minus - 2.0 * centre  # Q[step, step] projected on A_S
        curvature = np.zeros((k, k, strong.shape[1]))
        curvature[range(k), range(k)] = second[:k]
        for p, (i, j) in enumerate(pairs):
            curvature[i, j] = curvature[j, i] = 0.5 * (second[k + p] - second[i] - second[j])
        return curvature

    def adapt(self, moments) -> None:
        """Move the base Gaussian to a pass's weighted moments of y (:func:`_weighted_moments`),
        blended with the current covariance so that it cannot collapse (unchanged without
        MIN_ADAPT_ESS effective samples)."""
        if moments is not None and moments[2] >= MIN_ADAPT_ESS:
            self.mean, self.covariance = moments[0], 0.5 * (moments[1] + self.covariance)

    def draw(self, rng, count: int, widen: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        scale, log_determinant = _proposal_factor(self.covariance * widen)
        normal = rng.standard_normal((count, len(self.mean)))
        y = self.mean + normal @ scale.T
        log_proposal = -0.5 * np.sum(normal * normal, axis=1) - log_determinant
        return self.parameters(y), y, log_proposal

    def parameters(self, y: np.ndarray) -> np.ndarray:
        """The parameter vectors (S, n) of base coordinates y (S, n): the shear, then the basis."""
        w = y.copy()
        w[:, ~self.weak] += self.ridge(y[:, self.weak])
        return self.objective.theta(self.z_map + w @ self.basis.T)

    def _ridge_steps(self) -> int:
        """RIDGE_STEPS where the second-order step leaves a draw RIDGE_OFF or more (whitened) off
        the ridge at RIDGE_PROBE std along some weak direction, else 0 (each step costs a
        residual evaluation per draw: a full-DH cell of 5000 readings would take twice as long
        for nothing)."""
        k = int(self.weak.sum())
        if k == 0 or RIDGE_STEPS == 0:
            return 0
        probes = RIDGE_PROBE * np.concatenate([np.eye(k), -np.eye(k)])
        second = self.ridge(probes, steps=0)
        w = np.zeros((len(probes), len(self.weak)))
        w[:, self.weak], w[:, ~self.weak] = probes, second
        off = self._projected(self.z_map + w @ self.basis.T, self.strong)
        self.ridge_off = float(np.max(np.abs(off)))
        return RIDGE_STEPS if self.ridge_off >= RIDGE_OFF else 0

    def ridge(self, a: np.ndarray, steps: int | None = None) -> np.ndarray:
        """g(a), the strong coordinates' conditional mode given the weak ones a (S, k): the
        second-order step of the module docstring, then RIDGE_STEPS Gauss-Newton steps
        w_S <- w_S - A_S^T R(z) at (a, w_S). A ridge that turns (a base rotated about a far axis)
        leaves the second-order step a third-order distance off it, which the data's rows, far
        narrower than the prior along the ridge, turn into weights that fall with |a|: the check
        would read the ridge as narrower than it is. g depends on a alone, so the map stays a
        shear of unit Jacobian and the proposal's density exact. ``steps``: the Gauss-Newton
        steps (default: those the constructor chose)."""
        strong = self.shift - 0.5 * np.einsum("si,sj,ijk->sk", a, a, self.curvature, optimize=True)
        if not self.weak.any():
            return strong
        w = np.zeros((len(a), len(self.weak)))
        w[:, self.weak] = a
        for _ in range(steps if steps is not None else self.ridge_steps):
            w[:, ~self.weak] = strong
            strong = strong - self._projected(self.z_map + w @ self.basis.T, self.strong)
        return strong


def _log_weights(model, objective, thetas: np.ndarray, log_proposal: np.ndarray) -> np.ndarray:
    priors = objective.priors
    held = objective.prior_rows & ~priors.gaussian  # flat X held by a row: that row is their prior here
    r = model.residuals_batch(thetas) * objective.sqrt_weights
    log_likelihood = -0.5 * np.sum(r * r, axis=1)
    if np.all(objective.sqrt_weights == 1.0):  # (the robust loss's reweighted rows stay Gaussian)
        # A noise that is not normal: its own density in place of the moment-matched Gaussian's
        # (their constants cancel in the normalised weights), so the check weighs the data by the
        # noise the problem gives, and data it makes impossible (a reading off by more than a
        # uniform's half width) leave no weight.
        for columns, density, scale, mean in model.noise_densities():
            part = r[:, columns]
            log_likelihood += 0.5 * np.sum(part * part, axis=1)
            log_likelihood += np.sum(density.logpdf(part * scale + mean), axis=1)
    z_held = (thetas[:, held] - priors.mean[held]) / priors.std[held]
    log_prior = priors.log_density(thetas) - 0.5 * np.sum(z_held * z_held, axis=1)
    with np.errstate(invalid="ignore"):
        log_weights = log_likelihood + log_prior - log_proposal
    log_weights[~np.isfinite(log_weights)] = -np.inf
    return log_weights


def _importance_pass(model, objective, proposal: CurvedLaplace, rng, samples: int, widen: float, sink) -> None:
    """``samples`` draws of the proposal, CHUNK values at a time, each chunk's parameter vectors,
    base coordinates and log-weights against the exact posterior handed to ``sink``."""
    n = len(proposal.mean)
    # draws per chunk: CHUNK values of theta, and as many of the residuals (100,000 rows: 3 draws)
    step = max(1, CHUNK // max(1, n, len(objective.sqrt_weights)))
    for start in range(0, samples, step):
        thetas, y, log_proposal = proposal.draw(rng, min(step, samples - start), widen)
        sink(thetas, y, _log_weights(model, objective, thetas, log_proposal))


def _weighted_moments(values: np.ndarray, log_weights: np.ndarray):
    """Self-normalised mean, covariance and ESS; None without a finite weight."""
    peak = np.max(log_weights)
    if not math.isfinite(peak):
        return None
    w = np.exp(log_weights - peak)
    w /= w.sum()
    mean = w @ values
    centred = values - mean
    return mean, (w[:, None] * centred).T @ centred, float(1.0 / np.sum(w * w))


def check_laplace(model, objective, calibration, samples: int, seed: int, jacobian: np.ndarray) -> LaplaceCheck:
    """Importance sampling of the posterior from the curved Laplace proposal, widened by
    1 + SPREAD / sqrt(n) (so that its tails cover the posterior's). A first pass of a quarter of
    the samples (at most FIRST_PASS_SAMPLES) tells whether it fits: with KEEP_FRACTION effective
    samples or more its draws count and the rest follow; otherwise (a prior truncating the
    posterior, say) the proposal moves to the pass's weighted moments and all the samples come
    from it, streamed (the memory does not grow with their number). ``jacobian``: the stacked
    residuals' at the MAP, as the solve has it."""
    n = len(calibration.estimate)
    priors = objective.priors
    rng = np.random.default_rng(seed)
    widen = (1.0 + SPREAD / math.sqrt(n)) ** 2
    z_map = (calibration.estimate - priors.mean) / priors.std
    proposal = CurvedLaplace(objective, z_map, calibration.covariance / np.outer(priors.std, priors.std), jacobian)
    first = min(FIRST_PASS_SAMPLES, samples, max(100, samples // 4))
    chunks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    _importance_pass(model, objective, proposal, rng, first, widen, lambda *chunk: chunks.append(chunk))
    thetas, y, log_weights = (np.concatenate(part) for part in zip(*chunks))
    found = _weighted_moments(y, log_weights)
    sums = WeightedPoseSums(samples, np.zeros(n, dtype=bool))
    if found is not None and found[2] >= KEEP_FRACTION * first:
        sums.add_values(log_weights, thetas)
        rest = samples - first
    else:
        proposal.adapt(found)
        rest = samples
    _importance_pass(
        model,
        objective,
        proposal,
        rng,
        rest,
        widen,
        lambda thetas, y, log_weights: sums.add_values(log_weights, thetas),
    )
    moments = sums.moments()
    if moments is None:
        nan = np.full(n, np.nan)
        return LaplaceCheck(samples, nan, nan, nan, 0.0, math.inf)
    return LaplaceCheck(
        samples, moments["mean"], moments["std"], moments["mean_se"], sums.effective_samples, sums.pareto_k
    )
