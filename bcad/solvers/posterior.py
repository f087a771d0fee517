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
fraction of samples that satisfy the relation's inequalities.

Angles are summarised around their circular mean, so a parameter near ±pi
gets a meaningful mean and spread.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bcad.compile import CompiledProblem
from bcad.kinematics.chain import Samples
from bcad.model.pose import LENGTH_PARAMETERS, PARAMETERS
from bcad.solvers.objective import Objective, wrap_angle

ANGULAR = np.array([name not in LENGTH_PARAMETERS for name in PARAMETERS])


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


def pose_statistics(poses: np.ndarray, weights: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation of (N, 6) poses; angles about their circular mean."""
    weights = np.full(len(poses), 1.0 / len(poses)) if weights is None else weights
    angles = poses[:, ANGULAR]
    centre = np.arctan2(weights @ np.sin(angles), weights @ np.cos(angles))
    centred = poses.copy()
    centred[:, ANGULAR] = wrap_angle(angles - centre)
    mean = weights @ centred
    std = np.sqrt(np.maximum(weights @ np.square(centred - mean), 0.0))
    mean[ANGULAR] = wrap_angle(mean[ANGULAR] + centre)
    return mean, std


def closing_link_posteriors(
    compiled: CompiledProblem, objective: Objective, x: np.ndarray, samples: Samples
) -> list[LinkPosterior]:
    """The posterior of every closing link at ``x`` on the given L samples."""
    results = []
    for cycle, term in zip(compiled.graph.cycles, objective.cycles):
        link = compiled.graph.links[cycle.closing_link]
        transform = term.chain.evaluate(x, samples)
        poses = transform.poses()
        log_weights = np.zeros(samples.count)
        for group in term.observed:
            log_weights += group.log_density(poses, 0.0)
        satisfied = None
        if link.relation is not None:
            log_relation = link.relation.log_satisfaction(transform.columns, transform.translations, 0.0)
            log_weights += log_relation
            if link.relation.inequality_count:
                satisfied = float(np.mean(np.isfinite(log_relation)))
        mean, std = pose_statistics(poses)
        weighted_mean = weighted_std = None
        effective = 0.0
        if np.any(np.isfinite(log_weights)):
            weights = np.exp(log_weights - np.max(log_weights))
            weights /= weights.sum()
            effective = float(1.0 / np.sum(weights**2))
            weighted_mean, weighted_std = pose_statistics(poses, weights)
        constrained = list(link.relation.constrained) if link.relation is not None else [
            PARAMETERS[slot] for group in term.observed for slot in group.slots
        ]
        results.append(
            LinkPosterior(link.name, link.parent, link.child, constrained, mean, std, weighted_mean, weighted_std, effective, satisfied)
        )
    return results
