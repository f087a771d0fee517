"""The priors of the parameters a calibration identifies.

Least squares wants each prior as a residual row (theta - mean) / std: every
L, and every X with a prior other than uniform, gets one from its
distribution's mean and variance (exact for a normal prior, a Gaussian
surrogate otherwise, which the importance-sampling check then corrects with
the exact density). An X with no prior, or a uniform one, is flat on its
bounds: no row, only the bounds; its ``std`` is the uniform's, a scale for
the whitened variables and for "identified".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bcad.calibration.model import CalibrationModel
from bcad.model.distributions import Uniform


@dataclass
class ParameterPriors:
    mean: np.ndarray  # (n,): prior mean (L: of the deviation), or the start of a flat X
    std: np.ndarray  # (n,): prior std, or the std of the uniform on a flat X's bounds
    gaussian: np.ndarray  # (n,) bool: the prior is a least-squares row
    low: np.ndarray  # (n,): bounds (-inf for L)
    high: np.ndarray
    #: (distribution, positions in the identified vector) of every prior that is not flat
    groups: list[tuple[object, tuple[int, ...]]]

    def log_density(self, thetas: np.ndarray) -> np.ndarray:
        """The exact log prior of parameter vectors (S, n), up to a constant; -inf outside the bounds."""
        inside = np.all((thetas >= self.low) & (thetas <= self.high), axis=1)
        total = np.where(inside, 0.0, -np.inf)
        for distribution, positions in self.groups:
            values = thetas[:, list(positions)]
            total = total + distribution.logpdf(values if len(positions) > 1 else values[:, 0])
        return total


def parameter_priors(model: CalibrationModel) -> ParameterPriors:
    table = model.compiled.parameters
    nx, nl = len(model.x_columns), len(table.l)
    n = len(model.names)
    mean, variance = np.zeros(n), np.ones(n)
    gaussian = np.ones(n, dtype=bool)
    low, high = np.full(n, -np.inf), np.full(n, np.inf)
    groups: list[tuple[object, tuple[int, ...]]] = []
    for group in table.l_groups:
        positions = tuple(nx + c for c in group.columns)
        m, v = group.distribution.moments()
        mean[list(positions)], variance[list(positions)] = m, v
        groups.append((group.distribution, positions))
    position_of_x = {column: k for k, column in enumerate(model.x_columns)}
    priors = {group.columns[0]: group.distribution for group in table.x_priors}
    for column, k in position_of_x.items():
        low[k], high[k] = table.x_bounds[column]
        prior = priors.get(column)
        if prior is None or isinstance(prior, Uniform):
            gaussian[k] = False
            mean[k] = min(max(table.x_nominal[column], low[k]), high[k])
            variance[k] = (high[k] - low[k]) ** 2 / 12.0
        else:
            m, v = prior.moments()
            mean[k], variance[k] = float(m[0]), float(v[0])
            groups.append((prior, (k,)))
    k = nx + nl
    for block in model.cameras:  # a camera's identified parameters: their distributions are their priors
        for distribution in block.priors:
            m, v = distribution.moments()
            mean[k], variance[k] = float(m[0]), float(v[0])
            groups.append((distribution, (k,)))
            k += 1
    for start, views, columns, _, distribution in model.joint_errors.values():  # each view's joint errors
        m, v = distribution.moments()
        for position in range(start, start + views * len(columns)):
            mean[position], variance[position] = float(m[0]), float(v[0])
            groups.append((distribution, (position,)))
    if not np.all(np.isfinite(variance)) or np.any(variance <= 0.0):
        raise model.compiled.problem.source.error(
            (), "a parameter to identify has a prior of no finite, positive variance"
        )
    return ParameterPriors(mean, np.sqrt(variance), gaussian, low, high, groups)
