"""Calibration: the free parameters' posterior given the measurements (issue 10).

In whitened variables z = (L - mu) / sigma (mu, sigma: the prior's moments),
the negative log posterior is, to a constant,

    |z|^2 / 2 + sum_rows |(measured - predicted(L) - noise mean) / noise std|^2 / 2,

a least-squares problem: Levenberg-Marquardt finds its minimum (the MAP), and
the Laplace approximation gives the posterior covariance (J^T J)^-1 at the
MAP, J the Jacobian of the stacked whitened residuals (identity rows for the
prior, central differences through the batched chain for the data).

Identifiability: the data's own information in z is F = J_d^T J_d. Where an
eigenvalue of F is below 1, the data say less about that combination of
parameters than the prior does: it is reported as not identified by these
data, and its estimate stays near the prior instead of becoming nonsense
(the prior rows of the least squares hold it). A parameter is reported as
identified when the data shrink its standard deviation below IDENTIFIED of
the prior's.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bcad.bayes.linear import free_parameter_moments
from bcad.calibrate.model import CalibrationModel
from bcad.compile import CompiledProblem
from bcad.solvers.nominal import bounded_least_squares

#: a parameter is identified when its posterior std is below this fraction of its prior std
IDENTIFIED = 0.5
#: steps of the central differences, as a fraction of each prior std
STEP = 1e-4
#: Levenberg-Marquardt iterations at most
ITERATIONS = 100


@dataclass
class Calibration:
    names: list[str]
    prior_mean: np.ndarray
    prior_std: np.ndarray
    estimate: np.ndarray
    std: np.ndarray
    correlation: np.ndarray
    identified: np.ndarray
    #: combinations the data barely inform: (information, {name: weight}) with weights of unit norm
    unobservable: list[tuple[float, dict[str, float]]] = field(default_factory=list)
    residuals_before: np.ndarray | None = None
    residuals_after: np.ndarray | None = None


def calibrate(compiled: CompiledProblem, model: CalibrationModel | None = None) -> Calibration:
    model = model or CalibrationModel(compiled)
    mean, variance = free_parameter_moments(compiled)
    sd = np.sqrt(variance)
    n = len(mean)
    if n == 0:
        raise compiled.problem.source.error((), "the problem has no free parameter (L) to calibrate")

    def residuals(z: np.ndarray) -> np.ndarray:
        return np.concatenate([z, model.residuals(mean + sd * z)])

    def jacobian(z: np.ndarray) -> np.ndarray:
        return np.vstack([np.eye(n), model.jacobian(mean + sd * z, STEP * sd) * sd])

    infinite = np.full(n, np.inf)
    z, _ = bounded_least_squares(residuals, jacobian, np.zeros(n), -infinite, infinite, ITERATIONS)
    J = jacobian(z)
    covariance_z = np.linalg.inv(J.T @ J)
    covariance = covariance_z * np.outer(sd, sd)
    std = np.sqrt(np.diagonal(covariance))
    correlation = covariance / np.outer(std, std)
    data = J[n:]
    information, vectors = np.linalg.eigh(data.T @ data)
    unobservable = []
    names = model.names
    for value, vector in zip(information, vectors.T):
        if value >= 1.0:
            break
        largest = np.argsort(-np.abs(vector))[:4]
        unobservable.append((float(value), {names[k]: float(vector[k]) for k in largest if abs(vector[k]) > 0.1}))
    return Calibration(
        names=names, prior_mean=mean, prior_std=sd, estimate=mean + sd * z, std=std, correlation=correlation,
        identified=std < IDENTIFIED * sd, unobservable=unobservable,
        residuals_before=model.residuals(mean), residuals_after=model.residuals(mean + sd * z),
    )
