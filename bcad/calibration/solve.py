"""Calibration: the identified parameters given the measurements.

In whitened variables z = (theta - mu) / sigma (mu, sigma: the prior's
moments, or a flat X's start and the std of the uniform on its bounds), the
negative log posterior is, to a constant,

    sum_priors z^2 / 2 + sum_rows w_r |(measured - predicted(theta) - noise mean) / noise std|^2 / 2,

a least-squares problem: Levenberg-Marquardt finds its minimum (the MAP, the
estimate of the X), and the Laplace approximation gives the posterior
covariance (J^T J)^-1 at the MAP, J the Jacobian of the stacked whitened
residuals (identity rows for the priors, central differences through the
batched chain for the data). The MAP and that one covariance are the
calibrated model; the importance sampler checks them and is
reported beside them (:mod:`bcad.calibration.check`).

Robust loss (``robust=True``): Huber's loss on each measurement row's
whitened residual norm d_r, by iteratively reweighted least squares with
w_r = min(1, c / d_r), c the 99.9 % quantile of the chi distribution with
the row's k degrees of freedom. Rows with d_r > c at the end are outliers,
and the answer is then the least-squares fit of the other rows (from the
robust answer; flagged again at the fit's answer until the outliers are the
rows beyond c there): Huber's linear tail keeps pulling with a force c from every
outlier, however far, and the Laplace covariance at its minimum counts the
outliers' information as data. With 3 of 30 tracker rows 40-120 noise
standard deviations off, the Huber answer's (estimate - truth) / std spread
1.35 over 10 cells; the inliers' fit is the fit of the rows deleted.

Identifiability: the data's own information in z is F = J_d^T J_d. Where an
eigenvalue of F is below 1, the data say less about that combination than
the prior does: it is reported as not identified by these data, and its
estimate stays near the prior instead of becoming nonsense (the prior rows
hold it). A flat X in such a combination has no prior row to hold it: it is
given a Gaussian prior row about its start with the uniform's std (soft: it
may move where the data inform part of the combination, and its std comes out
below the uniform's), and the solve repeats. A
parameter with a prior is identified when the data shrink its std below
IDENTIFIED of the prior's.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bcad.calibration.model import CalibrationModel
from bcad.calibration.priors import ParameterPriors, parameter_priors
from bcad.compiler import CompiledProblem
from bcad.numerics.least_squares import levenberg_marquardt

#: a parameter is identified when its posterior std is below this fraction of its prior std
IDENTIFIED = 0.5
#: steps of the central differences, as a fraction of each prior std
STEP = 1e-4
#: Levenberg-Marquardt iterations at most, and the relative decrease of the cost that ends them
#: (the cost is a chi-square: 1e-10 of it is far below any statistical meaning)
ITERATIONS = 100
TOLERANCE = 1e-10
#: the first Marquardt damping: calibrations start near their answer, so Gauss-Newton steps first
DAMPING = 1e-6
#: reweighting rounds of the robust loss at most
ROBUST_ROUNDS = 20
#: the quantile of a row's chi distribution beyond which Huber's loss turns linear
ROBUST_QUANTILE = 0.999
#: least-squares fits of the inliers at most, each flagging the outliers again at its answer
REFIT_ROUNDS = 5
#: a combination of parameters whose data information (in prior units) is below this is not observable
OBSERVABLE = 1.0


@dataclass
class Outlier:
    measurement: str
    row: int  # 1-based row of the measurement
    line: int | None  # its CSV line, if it came from a file
    distance: float  # whitened residual norm at the estimate
    weight: float  # the Huber weight it ended with, before the inliers' fit gave it none


@dataclass
class Calibration:
    names: list[str]
    kinds: list[str]  # "X" (estimated: MAP) or "L" (posterior)
    priors: ParameterPriors
    estimate: np.ndarray  # the MAP
    std: np.ndarray  # the Laplace std
    covariance: np.ndarray
    identified: np.ndarray
    held: np.ndarray  # flat X given a prior row about their start (in a combination the data do not observe)
    #: combinations the data barely inform: (information, {name: weight}) with weights of unit norm
    unobservable: list[tuple[float, dict[str, float]]] = field(default_factory=list)
    residuals_before: np.ndarray | None = None
    residuals_after: np.ndarray | None = None
    row_weights: np.ndarray | None = None  # the robust loss's per-row weights (None: plain least squares)
    outliers: list[Outlier] = field(default_factory=list)
    inliers: np.ndarray | None = None  # per stacked residual: not in an outlier row (None: no robust loss)
    check: object | None = None  # the importance-sampling check (bcad.calibration.check.LaplaceCheck)

    @property
    def correlation(self) -> np.ndarray:
        """The covariance over the outer product of the stds; nan where a std is 0 (a noise of
        1e-12 rounds some to it), which the JSON writes as null."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.covariance / np.outer(self.std, self.std)

    def answer(self) -> tuple[np.ndarray, np.ndarray]:
        """The calibrated model: the joint MAP of every parameter, X and L alike, and the
        Laplace std, the diagonal of the one covariance whose correlations are reported too. The
        importance-sampled check is reported beside it, never mixed in: a mean of one parameter
        from samples beside the MAP of another, where the two share an unobservable combination,
        put the sampling error of the first straight into the calibrated poses."""
        return self.estimate, self.std


class _Objective:
    """The stacked whitened residuals in z, with the current row weights and held parameters."""

    def __init__(self, model: CalibrationModel, priors: ParameterPriors):
        self.model = model
        self.priors = priors
        self.prior_rows = priors.gaussian.copy()
        self.row_of_residual = model.row_of_residual
        self.sqrt_weights = np.ones(len(self.row_of_residual))

    def theta(self, z: np.ndarray) -> np.ndarray:
        return self.priors.mean + self.priors.std * z

    def residuals(self, z: np.ndarray) -> np.ndarray:
        return np.concatenate([z[self.prior_rows], self.sqrt_weights * self.model.residuals(self.theta(z))])

    def jacobian(self, z: np.ndarray, central: bool = True) -> np.ndarray:
        data = self.model.jacobian(self.theta(z), STEP * self.priors.std, central) * self.priors.std
        return np.vstack([np.eye(len(z))[self.prior_rows], self.sqrt_weights[:, None] * data])

    def solve(self, z: np.ndarray) -> np.ndarray:
        low = (self.priors.low - self.priors.mean) / self.priors.std
        high = (self.priors.high - self.priors.mean) / self.priors.std
        # Forward differences while iterating: the steps only need a good direction.
        found, _ = levenberg_marquardt(
            lambda rows: np.stack([self.residuals(row) for row in rows]),
            z[None],
            low,
            high,
            lambda rows, _: np.stack([self.jacobian(row, central=False) for row in rows]),
            iterations=ITERATIONS,
            tolerance=TOLERANCE,
            damping=DAMPING,
        )
        return found[0]

    def data_information(self, J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Eigenvalues (ascending) and eigenvectors of the data's own information J_d^T J_d in z."""
        data = J[int(self.prior_rows.sum()) :]
        return np.linalg.eigh(data.T @ data)

    def hold_unobservable_flat(self, z: np.ndarray) -> np.ndarray:
        """Flat X in a combination the data do not observe at z (bool mask): they get a prior row
        (the uniform's std about their start) and their start value."""
        information, vectors = self.data_information(self.jacobian(z, central=False))
        weak = vectors[:, information < OBSERVABLE]
        held = ~self.prior_rows & (np.max(np.abs(weak), axis=1, initial=0.0) > 0.1)
        self.prior_rows |= held
        return held


def _huber_threshold(model: CalibrationModel) -> np.ndarray:
    from scipy.stats import chi

    per_row = np.concatenate([np.full(len(m.x_rows), m.measured.shape[1]) for m in model.measurements])
    return chi.ppf(ROBUST_QUANTILE, per_row)


def _row_distances(objective: _Objective, z: np.ndarray) -> np.ndarray:
    r = objective.model.residuals(objective.theta(z))
    return np.sqrt(np.bincount(objective.row_of_residual, weights=r * r))


def _reweighted(objective: _Objective, z: np.ndarray, threshold: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Huber's loss by iteratively reweighted least squares from z (module docstring): the end z and
    its row weights (the residuals' weights are their square roots, row by row)."""
    objective.sqrt_weights = np.ones(len(objective.row_of_residual))
    row_weights = None
    for _ in range(ROBUST_ROUNDS):
        distances = _row_distances(objective, z)
        row_weights = np.minimum(1.0, threshold / np.maximum(distances, 1e-300))
        previous = objective.sqrt_weights
        objective.sqrt_weights = np.sqrt(row_weights[objective.row_of_residual])
        if np.max(np.abs(objective.sqrt_weights - previous)) < 1e-4:
            break
        z = objective.solve(z)
    return z, row_weights


def _huber_cost(objective: _Objective, z: np.ndarray, threshold: np.ndarray) -> float:
    """The robust objective at z: the priors' half squares plus each row's Huber loss of its
    whitened distance d (d^2 / 2 up to the threshold c, c d - c^2 / 2 beyond)."""
    d = _row_distances(objective, z)
    rows = np.where(d <= threshold, 0.5 * d * d, threshold * d - 0.5 * threshold * threshold)
    return float(0.5 * np.sum(z[objective.prior_rows] ** 2) + np.sum(rows))


def calibrate(
    compiled: CompiledProblem,
    model: CalibrationModel | None = None,
    robust: bool = False,
    check_samples: int = 0,
    seed: int = 0,
) -> Calibration:
    model = model or CalibrationModel(compiled)
    priors = parameter_priors(model)
    n = len(priors.mean)
    if n == 0:
        raise compiled.problem.source.error(
            (), "the problem has nothing to calibrate: no free parameter (L) and no X but robot joints"
        )
    objective = _Objective(model, priors)
    # Flat X that the data cannot see are held at their start from the outset (the linearisation
    # at the start tells), and once more at the solution should the solve have moved into one.
    z = np.zeros(n)
    held = objective.hold_unobservable_flat(z)
    z = objective.solve(z)
    row_weights = None
    threshold = _huber_threshold(model) if robust else None
    if robust:
        # Reweighted from the least-squares answer and from the priors' means: one wild row (a
        # tracker reading a metre off) drags the least-squares answer so far that reweighting from there
        # calls nearly every other row an outlier; from the priors it is the wild row that weighs
        # little. The end with the lower Huber cost is kept.
        ends = [_reweighted(objective, start, threshold) for start in (z, np.zeros(n))]
        z, row_weights = min(ends, key=lambda end: _huber_cost(objective, end[0], threshold))
        flagged = _row_distances(objective, z) > threshold
        if flagged.all():  # nothing to trust: the Huber answer stands (the warning all_outliers)
            objective.sqrt_weights = np.sqrt(row_weights[objective.row_of_residual])
        else:
            # The inliers' least-squares fit (module docstring), flagged again at its answer until
            # the outliers are those beyond the threshold there (a row just inside it at the
            # Huber answer can end beyond it), REFIT_ROUNDS at most.
            for _ in range(REFIT_ROUNDS):
                objective.sqrt_weights = (~flagged[objective.row_of_residual]).astype(float)
                z = objective.solve(z)
                again = _row_distances(objective, z) > threshold
                if np.array_equal(again, flagged) or again.all():
                    break
                flagged = again
    newly = objective.hold_unobservable_flat(z)
    if newly.any():
        held |= newly
        z[newly] = 0.0
        z = objective.solve(z)

    # Not observable: eigen-directions of the data's information below OBSERVABLE (in prior units).
    J = objective.jacobian(z)
    information, vectors = objective.data_information(J)
    unobservable = []
    for value, vector in zip(information, vectors.T):
        if value >= OBSERVABLE:
            break
        largest = np.argsort(-np.abs(vector))[:4]
        # (an eigenvalue of J^T J, which is never negative: -2.7e-11 is the eigensolver's rounding)
        unobservable.append(
            (float(max(value, 0.0)), {model.names[k]: float(vector[k]) for k in largest if abs(vector[k]) > 0.1})
        )

    normal = J.T @ J
    try:
        covariance_z = np.linalg.inv(normal)
    except np.linalg.LinAlgError:
        covariance_z = np.linalg.pinv(normal)
    covariance_z = 0.5 * (covariance_z + covariance_z.T)  # the inverse's rounding left it 1e-10 off symmetric
    covariance = covariance_z * np.outer(priors.std, priors.std)
    std = np.sqrt(np.maximum(np.diagonal(covariance), 0.0))
    identified = np.where(priors.gaussian, std < IDENTIFIED * priors.std, ~held)
    estimate = objective.theta(z)

    outliers, inliers = [], None
    if row_weights is not None:
        distances = _row_distances(objective, z)
        inliers = ~flagged[objective.row_of_residual]
        # Rows are numbered across measurements: each flagged one back to its measurement and row.
        firsts = np.cumsum([0] + [len(m.x_rows) for m in model.measurements])
        for row in np.flatnonzero(flagged):
            k = int(np.searchsorted(firsts, row, side="right")) - 1
            m, r = model.measurements[k], int(row - firsts[k])
            line = m.lines[r] if m.lines is not None else None
            outliers.append(Outlier(m.name, r + 1, line, float(distances[row]), float(row_weights[row])))

    calibration = Calibration(
        names=model.names,
        kinds=model.kinds,
        priors=priors,
        estimate=estimate,
        std=std,
        covariance=covariance,
        identified=identified,
        held=held,
        unobservable=unobservable,
        residuals_before=model.residuals(priors.mean),
        residuals_after=model.residuals(estimate),
        row_weights=row_weights,
        outliers=outliers,
        inliers=inliers,
    )
    if check_samples:
        from bcad.calibration.check import check_laplace

        calibration.check = check_laplace(model, objective, calibration, check_samples, seed, J)
    return calibration
