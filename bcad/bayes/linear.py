"""The linearised estimator of I(X): the 2000 paper's future work (Sect. 6).

Every pose that enters the integrand of Eq. 2 (each cycle's closing pose
F_i(X, L), and the pose of each tree relation that involves X) is
linearised in the free parameters about their mean mu = E[L]:

    F(X, L) ~ F(X, mu) + J(X) (L - mu),

with J by central differences through the batched chain: one batched
evaluation of the 1 + 2 nL points mu, mu +- h_j e_j per X
(h_j = STEP x the std of L_j, truncation error ~ h^2, about 1e-9 relative;
the search may use forward differences, 1 + nL points, error ~ h).
L is replaced by the Gaussian of the same mean and covariance (exact for
``normal``; the moments of ``uniform``, ``truncnormal`` and ``disc``), and
each closing link's scores p_O by Gaussians of their moments. Then

    I_lin(X) = N(mu_O - d0(X) - m(X); 0, Sigma_O + J_O Sigma_L J_O^T + V(X)) * P_lin(H | X, O),

the marginal likelihood of a linear-Gaussian model: d0 is the scored
deviation of the closing poses at L = mu, m and V the second-order terms of
curvilinear coordinates (below; zero elsewhere), and P_lin(H | X, O) the probability
that the relations' inequalities hold under the Gaussian of the poses
conditioned on the scores (a Kalman update in pose space). Without
inequalities and with Gaussian L and scores the estimate is exact. With
inequalities P_lin(H | .) is estimated on M fixed standard-normal points
(antithetic pairs, the same for every X and every seed), each inequality's
indicator smoothed to the logistic sigma(-1.702 d / h) (within 0.01 of
Phi(-d / h)) with h^2 = (SMOOTHING w)^2 + (DRAW_SMOOTHING sd)^2, w the
polygon's width along the edge normal and sd the distance's spread (fixed
points are about sd / sqrt(M) apart): the estimate is deterministic and
smooth in X, as a gradient optimiser needs. Each distance is evaluated
exactly at each drawn pose, or to first order about the mean where it is
linear in the pose (a face's polygon, a segment).
Its standard error is that of the mean over the M draws.

A point on a sphere or a cylinder is scored in curvilinear coordinates
(its distance to the surface, arc lengths along it), which are curved in
the point's position p: a lateral error e moves the distance rho - R by
about |e|^2 / (2 rho), and where the other scores pin the errors down,
that bias is comparable with the distance's own spread. So each scored
coordinate c(p) is taken to second order, c ~ c0 + J u + u^T H u / 2 with
H = J_p^T G J_p (G the coordinate's Hessian in p, J_p the position's
Jacobian in L, u = L - mu), and the Gaussian of the scores matched to its
moments under the errors' Gaussian given the scores (covariance
Sigma_c = Sigma_L - Sigma_L J_O^T S^-1 J_O Sigma_L, where the bias is
settled): mean m_i = tr(H_i Sigma_c) / 2 and covariance
V_ij = tr(H_i Sigma_c H_j Sigma_c) / 2. A probe above a sphere's pole with
lateral errors of 0.3 mm, radius 5 mm, scored within 0.05 mm: log I_lin
within 0.02 of a brute-force integral where the first order errs by 0.24
(tests/bayes/test_linear_curvature.py). A UR5 touching a face, a point and a
sphere of radius 9.3 mm at three configurations (the face made large enough
that its edges do not weigh), at the search's 30 best maxima: log I_lin -
log I (importance sampling, 1e5 samples) spread 0.025 (std) to first order,
0.006 with these terms; with the prior's Sigma_L for Sigma_c, log I_lin fell
0.10 below log I where the first order stood 0.05 above it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from bcad.bayes.objective import Objective
from bcad.compiler import CompiledProblem
from bcad.compiler.parameters import free_parameter_moments
from bcad.kinematics.chain import Chain, Samples
from bcad.kinematics.jacobian import pose_jacobian
from bcad.kinematics.se3 import wrap_angle
from bcad.model.pose import ANGULAR, PARAMETERS
from bcad.relations.geometry import RelationConstraint

#: finite-difference step of the Jacobian, as a fraction of each L's standard deviation
STEP = 1e-3
#: smoothing of an inequality's indicator, as a fraction of the polygon's width
SMOOTHING = 0.01
#: smoothing as a fraction of each signed distance's own spread: M points are about
#: sd / sqrt(M) apart, and a narrow kernel leaves I_lin rugged. Measured on the RX90
#: example over 12 choices of the fixed points: 0.3 led the search to maxima whose
#: importance score ranged from -20.41 to -22.04, 0.6 from -20.48 to -20.88.
DRAW_SMOOTHING = 0.6
#: the logistic kernel's slope: sigma(1.702 z) is within 0.01 of Phi(z) (Bowling et al. 2009)
LOGISTIC = 1.702
#: fixed draws of P_lin(H | X, O)
DRAWS = 64
#: the polish's sharper kernels (:func:`bcad.bayes.estimators.polish`): no width term, a
#: narrower spread term, and more fixed points to keep the estimate smooth at that width.
#: On the UR5 face example (importance score of the polished maximum): 0.01 / 0.6 / 64 (the
#: search's) -14.349, 0.002 / 0.3 / 256 -14.338, 0 / 0.2 / 512 -14.337
POLISH_SMOOTHING = 0.0
POLISH_DRAW_SMOOTHING = 0.3
POLISH_DRAWS = 256
#: the scramble of the fixed quadrature points
QUADRATURE_SEED = 20000
LOG_TWO_PI = math.log(2.0 * math.pi)
#: central-difference steps of a linear relation's distances in the pose (length unit, rad). The
#: distances are linear in the translation, so any step is exact there and a long one keeps
#: rounding out; in the rotation, 1e-4 rad errs by about 2e-9 of the gradient, smoothly in X.
#: Measured on the RX90 example, seeds 0-9: with these steps every seed within 0.031 of the
#: best; with 1e-6 and 1e-8 (forward), seeds 4, 7 and 8 ended 0.10-0.24 below. The same line
#: of X shows no more noise in log I_lin with the short steps, so the cause is the search's
#: sensitivity to small changes of its landscape rather than these steps' rounding alone.
POSE_STEPS = np.diag([1.0, 1.0, 1.0, 1e-4, 1e-4, 1e-4])


def free_parameter_covariance(compiled: CompiledProblem) -> np.ndarray | None:
    """Sigma_L (nL, nL) where a distribution covers correlated L (it has a ``covariance``: a
    calibration's joint posterior), else None: the L are independent and their variances do."""
    table = compiled.parameters
    correlated = [group for group in table.l_groups if hasattr(group.distribution, "covariance")]
    if not correlated:
        return None
    _, variance = free_parameter_moments(compiled)
    covariance = np.diag(variance)
    for group in correlated:
        covariance[np.ix_(group.columns, group.columns)] = group.distribution.covariance
    return covariance


@dataclass(frozen=True)
class ScoredRow:
    """One scored parameter of a closing link: row ``row`` of the stacked poses."""

    row: int
    nominal: float
    angular: bool
    mean: float
    variance: float
    name: str


@dataclass(frozen=True)
class RelationTerm:
    """A relation whose inequalities weigh the integrand: its pose is rows 6t..6t+5."""

    term: int
    relation: RelationConstraint


@dataclass
class Linearisation:
    """Stacked poses at L = mu, shape (P, R), and their Jacobians dF/dL, shape (P, R, nL)."""

    poses: np.ndarray
    jacobians: np.ndarray
    #: the chains in curvilinear coordinates (a point on a sphere), for the second-order terms
    curvilinear: list[Curvilinear] = field(default_factory=list)


@dataclass
class Curvilinear:
    """A chain whose translation rows are curvilinear coordinates c(p) of its Cartesian position p:
    its first stacked row, dp/dL (P, 3, nL) and each coordinate's Hessian in p (P, 3, 3, 3)."""

    row: int
    position_jacobians: np.ndarray
    hessians: np.ndarray


class LinearModel:
    """Every integrand pose linearised in L, and I_lin(X) for populations of X."""

    def __init__(
        self,
        compiled: CompiledProblem,
        objective: Objective | None = None,
        draws: int = DRAWS,
        central: bool = True,
        smoothing: float = SMOOTHING,
        draw_smoothing: float = DRAW_SMOOTHING,
    ):
        self.compiled = compiled
        self.central = central
        #: the inequalities' kernel widths (module docstring): SMOOTHING and DRAW_SMOOTHING by default
        self.smoothing, self.draw_smoothing = smoothing, draw_smoothing
        self.objective = objective or Objective(compiled)
        self.mean_l, self.variance_l = free_parameter_moments(compiled)
        #: Sigma_L where some L are correlated (a calibration's joint posterior), else None (diagonal)
        self.covariance_l = free_parameter_covariance(compiled)
        n = len(self.mean_l)
        self.step = STEP * np.sqrt(self.variance_l)
        points = np.repeat(self.mean_l[None], 1 + (2 if central else 1) * n, axis=0)
        points[1 : n + 1] += np.diag(self.step)
        if central:
            points[n + 1 :] -= np.diag(self.step)
        self.points = Samples(points)
        self.chains: list[Chain] = [cycle.chain for cycle in self.objective.cycles]
        self.chains += [chain for _, chain in self.objective.tree_relations]
        self.scored: list[ScoredRow] = []
        self.relations: list[RelationTerm] = []
        for t, cycle in enumerate(self.objective.cycles):
            for group in cycle.observed:
                mean, variance = group.distribution.moments()
                for k, slot in enumerate(group.slots):
                    self.scored.append(
                        ScoredRow(
                            6 * t + slot,
                            float(group.nominal[k]),
                            group.angular,
                            float(mean[k]),
                            float(variance[k]),
                            f"{cycle.name}.{PARAMETERS[slot]}",
                        )
                    )
            if cycle.relation is not None and cycle.relation.inequality_count:
                self.relations.append(RelationTerm(t, cycle.relation))
        for k, (relation, _) in enumerate(self.objective.tree_relations):
            if relation.inequality_count:
                self.relations.append(RelationTerm(len(self.objective.cycles) + k, relation))
        self.scored_rows = np.array([s.row for s in self.scored], dtype=int)
        self.scored_nominal = np.array([s.nominal for s in self.scored])
        self.scored_angular = np.array([s.angular for s in self.scored], dtype=bool)
        self.scored_mean = np.array([s.mean for s in self.scored])
        self.scored_variance = np.array([s.variance for s in self.scored])
        self.relation_rows = np.array([6 * r.term + j for r in self.relations for j in range(6)], dtype=int)
        #: the relations' poses move with nL L at most: where their rows outnumber the L, the
        #: conditional Gaussian is drawn in L's space (rank nL) instead of the rows' (rank r)
        self.in_l_space = len(self.relation_rows) > n
        self.draws = fixed_normal_points(draws, n if self.in_l_space else len(self.relation_rows))

    # -- linearisation ------------------------------------------------------
    def linearise(self, population: np.ndarray) -> Linearisation:
        """Poses at L = mu and their Jacobians, for every X of the population (P, nX)."""
        population = np.atleast_2d(np.asarray(population, dtype=float))
        cached = getattr(self, "_cached_chains", {})
        parts = [
            tuple(np.broadcast_to(a, (len(population),) + a.shape[1:]) for a in cached[k])
            if k in cached
            else self._chain_linearisation(chain, population)
            for k, chain in enumerate(self.chains)
        ]
        return Linearisation(
            np.concatenate([part[0] for part in parts], axis=1),
            np.concatenate([part[1] for part in parts], axis=1),
            [Curvilinear(6 * k, *part[2:]) for k, part in enumerate(parts) if len(part) > 2],
        )

    def _chain_linearisation(self, chain: Chain, population: np.ndarray) -> tuple[np.ndarray, ...]:
        """One chain's poses at L = mu (P, 6) and their Jacobians (P, 6, nL): analytic
        (:func:`bcad.kinematics.jacobian.pose_jacobian`, one pass over the chain, exact; in
        curvilinear coordinates by the chain rule, :meth:`_curvilinear_linearisation`), or at
        gimbal lock by differences (:meth:`_differenced_linearisation`). A chain in curvilinear
        coordinates also gives its position's Jacobian (P, 3, nL) and the coordinates' Hessians
        (P, 3, 3, 3) (:func:`coordinate_hessians`)."""
        if chain.coordinates is None:
            found = pose_jacobian(chain, population, self.mean_l)
        elif hasattr(chain.coordinates, "gradients"):
            found = self._curvilinear_linearisation(chain, population)
        else:  # a map without exact derivatives
            found = None
        if found is not None:
            return found
        return self._differenced_linearisation(chain, population)

    def _curvilinear_linearisation(self, chain: Chain, population: np.ndarray) -> tuple[np.ndarray, ...] | None:
        """A chain in curvilinear coordinates c(p, radius) linearised by the chain rule on its
        Cartesian Jacobian: dc/dL = dc/dp dp/dL + dc/dradius e_column (an uncertain radius), the
        rotation rows as they are; with dp/dL (P, 3, nL) and the coordinates' Hessians in p. None
        at gimbal lock (for differences)."""
        found = pose_jacobian(chain, population, self.mean_l, cartesian=True)
        if found is None:
            return None
        poses, jacobians = found
        coordinates = chain.coordinates.at(self.mean_l)
        translations = poses[:, :3].T.copy()  # (3, P), Cartesian
        position_jacobians = jacobians[:, :3].copy()  # (P, 3, nL)
        poses[:, :3] = coordinates(translations).T
        gradients = coordinates.gradients(translations)  # (3 coordinates, 3 axes, P)
        jacobians[:, :3] = np.einsum("cap,pan->pcn", gradients, position_jacobians)
        if chain.coordinates.column is not None:
            jacobians[:, :3, chain.coordinates.column] += coordinates.radius_rates(translations).T
        return poses, jacobians, position_jacobians, coordinate_hessians(chain.coordinates, translations.T)

    def _differenced_linearisation(self, chain: Chain, population: np.ndarray) -> tuple[np.ndarray, ...]:
        """:meth:`_chain_linearisation` by differences of the chain evaluated at L = mu and at mu
        moved by ``step`` along each L (the poses at gimbal lock)."""
        n = len(self.mean_l)
        transform = chain.evaluate_population(population, self.points)
        spacing = (2.0 if self.central else 1.0) * self.step

        def differences(values: np.ndarray) -> np.ndarray:
            """Values at the points (P, 1 + n or 2n, r) -> their differences along each L (P, n, r)."""
            return values[:, 1 : n + 1] - (values[:, n + 1 :] if self.central else values[:, :1])

        def jacobian(difference: np.ndarray) -> np.ndarray:  # (P, n, r) -> (P, r, n)
            return np.swapaxes(difference / spacing[None, :, None], 1, 2)

        stacked = transform.poses()  # (P, 1 + n or 2n, 6)
        difference = differences(stacked)
        difference[..., 3:] = wrap_angle(difference[..., 3:])
        found = stacked[:, 0], jacobian(difference)
        if chain.coordinates is None:
            return found
        positions = np.moveaxis(transform.translations, 0, -1)  # (P, points, 3)
        return (*found, jacobian(differences(positions)), coordinate_hessians(chain.coordinates, positions[:, 0]))

    def holding(self, anchor: np.ndarray, mask: np.ndarray) -> LinearModel:
        """This model for populations that differ from ``anchor`` only in X[mask] (a configuration's
        own joints): a shallow copy whose chains that do not depend on those X are linearised once,
        at the anchor (a UR5 at three configurations: each block's climbs evaluate one cycle of
        three). A chain is independent of X[mask] where moving them leaves its poses bit for bit."""
        import copy

        anchor = np.asarray(anchor, dtype=float)
        probe = anchor.copy()
        width = np.ptp(self.objective.bounds, axis=1)
        probe[mask] += 0.1234567 * width[mask]
        cached = {}
        for k, chain in enumerate(self.chains):
            at_anchor = chain.evaluate_population(anchor[None], self.points).poses()
            if np.array_equal(at_anchor, chain.evaluate_population(probe[None], self.points).poses()):
                cached[k] = self._chain_linearisation(chain, anchor[None])
        held = copy.copy(self)
        held._cached_chains = cached
        return held

    def scored_deviation(self, poses: np.ndarray) -> np.ndarray:
        """d0: the scored parameters' deviation from their nominal values, shape (P, k)."""
        deviation = poses[:, self.scored_rows] - self.scored_nominal
        deviation[:, self.scored_angular] = wrap_angle(deviation[:, self.scored_angular])
        return deviation

    # -- the estimate -------------------------------------------------------
    def log_integral(self, population: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """log I_lin(X) and its standard error (that of the M-draw estimate of P(H)), shape (P,)."""
        value, se, _ = self.log_integral_parts(population)
        return value, se

    def log_integral_parts(self, population: np.ndarray):
        """log I_lin(X), its standard error, and the whitened residual w = (S + V)^-1/2 (mu_O - d0 - m),
        (P, k).

        log I_lin = -|w|^2 / 2 + (terms that vary slowly with X): the search uses w's
        Jacobian for the stiff part of the Hessian (Gauss-Newton)."""
        population = np.asarray(population, dtype=float)
        if not population.size:  # (no points: a block with no branch beyond its anchor's)
            return np.empty(0), np.empty(0), np.empty((0, len(self.scored_rows)))
        lin = self.linearise(population)
        covariance, S, residual = self._scored_system(lin, full=not self.in_l_space)
        O = self.scored_rows
        # (the relations' inequalities below stay with the first-order Gaussian of the poses)
        S_second, residual_second = self._second_order(lin, S, residual)
        chol = np.linalg.cholesky(S_second)
        whitened = np.linalg.solve(chol, residual_second[..., None])[..., 0]
        log_det = 2.0 * np.sum(np.log(np.diagonal(chol, axis1=1, axis2=2)), axis=1)
        log_gaussian = -0.5 * np.sum(whitened**2, axis=1) - 0.5 * log_det - 0.5 * len(O) * LOG_TWO_PI
        if not self.relations:
            return log_gaussian, np.zeros_like(log_gaussian), whitened
        log_h, se = self._log_inequalities(lin, covariance, S, residual)
        return log_gaussian + log_h, se, whitened

    def _scored_system(self, lin: Linearisation, full: bool = True):
        """J Sigma_L J^T (P, R, R) (None unless ``full``), S = Sigma_O + J_O Sigma_L J_O^T (P, k, k)
        and the residual mu_O - d0 (P, k)."""
        J = lin.jacobians
        if not full:
            J_O = J[:, self.scored_rows]
            S = self._l_times(J_O) @ np.swapaxes(J_O, 1, 2) + np.diag(self.scored_variance)
            return None, S, self.scored_mean - self.scored_deviation(lin.poses)
        if self.covariance_l is None:
            covariance = (J * self.variance_l) @ np.swapaxes(J, 1, 2)
        else:
            covariance = J @ self.covariance_l @ np.swapaxes(J, 1, 2)
        O = self.scored_rows
        S = covariance[:, O[:, None], O[None, :]] + np.diag(self.scored_variance)
        return covariance, S, self.scored_mean - self.scored_deviation(lin.poses)

    def scored_gaussian(self, lin: Linearisation) -> tuple[np.ndarray, np.ndarray]:
        """The scores' Gaussian given a linearisation, second-order terms included: its covariance
        S + V (P, k, k) and the residual mu_O - d0 - m (P, k)."""
        _, S, residual = self._scored_system(lin, full=False)
        return self._second_order(lin, S, residual)

    def _second_order(self, lin: Linearisation, S: np.ndarray, residual: np.ndarray):
        """S + V and mu_O - d0 - m: the scores' covariance and residual with the second-order terms
        of curvilinear coordinates (module docstring); S and the residual themselves elsewhere."""
        where = {int(row): k for k, row in enumerate(self.scored_rows)}
        terms = []  # (scored column, the chain, its coordinate)
        for chain in lin.curvilinear:
            terms += [(where[chain.row + c], chain, c) for c in range(3) if chain.row + c in where]
        if not terms:
            return S, residual
        # tr(H_a Sigma_c) = tr(G_a C_aa) and tr(H_a Sigma_c H_b Sigma_c) = tr(G_a C_ab G_b C_ba), with
        # H = J_p^T G J_p: C_ab = J_pa Sigma_c J_pb^T, the positions' covariance given the scores
        # (3 x 3 blocks, the Kalman update in the positions' space)
        chains = list({id(chain): chain for _, chain, _ in terms}.values())
        block = {id(chain): slice(3 * k, 3 * k + 3) for k, chain in enumerate(chains)}
        positions = np.concatenate([chain.position_jacobians for chain in chains], axis=1)  # (P, 3c, nL)
        J_O = lin.jacobians[:, self.scored_rows]
        positions_sigma = self._l_times(positions)
        cross = positions_sigma @ np.swapaxes(J_O, 1, 2)  # (P, 3c, k)
        C = positions_sigma @ np.swapaxes(positions, 1, 2) - cross @ np.linalg.solve(S, np.swapaxes(cross, 1, 2))
        S, residual = S.copy(), residual.copy()
        for column, chain, c in terms:
            own = block[id(chain)]
            residual[:, column] -= 0.5 * np.einsum("pij,pji->p", chain.hessians[:, c], C[:, own, own])
            for other, other_chain, d in terms:
                theirs = block[id(other_chain)]
                left = chain.hessians[:, c] @ C[:, own, theirs]  # G_a C_ab
                right = other_chain.hessians[:, d] @ C[:, theirs, own]  # G_b C_ba
                S[:, column, other] += 0.5 * np.einsum("pij,pji->p", left, right)
        return S, residual

    def conditional_poses(
        self,
        lin: Linearisation,
        covariance: np.ndarray,
        S: np.ndarray,
        residual: np.ndarray,
        rows: np.ndarray | None = None,
    ):
        """Mean (P, r) and covariance (P, r, r) of pose rows (default: the relations') given the scores.

        The Kalman update of the linear-Gaussian model: mean F0 + C_rO S^-1 (mu_O - d0),
        covariance C_rr - C_rO S^-1 C_Or.
        """
        rows = self.relation_rows if rows is None else rows
        cross = covariance[:, rows[:, None], self.scored_rows[None, :]]  # (P, r, k)
        gain = np.swapaxes(np.linalg.solve(S, np.swapaxes(cross, 1, 2)), 1, 2)  # cross S^-1
        mean = lin.poses[:, rows] + np.einsum("prk,pk->pr", gain, residual)
        conditional = covariance[:, rows[:, None], rows[None, :]] - gain @ np.swapaxes(cross, 1, 2)
        return mean, 0.5 * (conditional + np.swapaxes(conditional, 1, 2))

    def _l_times(self, A: np.ndarray) -> np.ndarray:
        """A Sigma_L for a stack of matrices A (..., m, nL)."""
        return A * self.variance_l if self.covariance_l is None else A @ self.covariance_l

    def conditional_in_l_space(self, lin: Linearisation, S: np.ndarray, residual: np.ndarray):
        """Mean (P, r) of the relations' pose rows given the scores, and a root R (P, r, nL) of their
        covariance, R R^T = J_r Sigma_c J_r^T: the Kalman update in L's space, where there are
        fewer L than rows, Sigma_c = Sigma_L - K J_O Sigma_L, K = Sigma_L J_O^T S^-1."""
        J = lin.jacobians
        J_O, J_r = J[:, self.scored_rows], J[:, self.relation_rows]
        n = J.shape[2]
        if n == 0:
            return lin.poses[:, self.relation_rows], np.zeros((len(J), len(self.relation_rows), 0))
        O_sigma = self._l_times(J_O)  # (P, k, nL): J_O Sigma_L
        gain = np.swapaxes(np.linalg.solve(S, O_sigma), 1, 2)  # (P, nL, k): Sigma_L J_O^T S^-1
        mean = lin.poses[:, self.relation_rows] + np.einsum("prn,pn->pr", J_r, np.einsum("pnk,pk->pn", gain, residual))
        sigma_l = np.diag(self.variance_l) if self.covariance_l is None else self.covariance_l
        conditional = sigma_l[None] - gain @ O_sigma
        return mean, J_r @ _scaled_cholesky(0.5 * (conditional + np.swapaxes(conditional, 1, 2)))

    def conditional_links(self, x: np.ndarray) -> list[dict[str, np.ndarray]]:
        """Each closing link's linear-Gaussian posterior given its scores (inequalities ignored)."""
        lin = self.linearise(np.asarray(x, dtype=float)[None])
        links = []
        for t in range(len(self.objective.cycles)):
            rows = np.arange(6 * t, 6 * t + 6)
            mean, covariance = self.conditional_poses(lin, *self._scored_system(lin), rows=rows)
            mean = mean[0]
            mean[ANGULAR] = wrap_angle(mean[ANGULAR])
            zeros = np.zeros(6)
            links.append(
                {
                    "mean": mean,
                    "std": np.sqrt(np.maximum(np.diagonal(covariance[0]), 0.0)),
                    "mean_se": zeros,
                    "std_se": zeros,
                }
            )
        return links

    def contributors(self, x: np.ndarray) -> list[tuple[ScoredRow, np.ndarray]]:
        """For each scored parameter c, its linearised variance J_c Sigma_L J_c^T split over the L
        parameters: J_cj (Sigma_L J_c^T)_j, each parameter's covariance contribution (Euler's
        allocation), which is J_cj^2 Var(L_j) where the L are independent. Where a calibration's
        posterior correlates them, the contributions still sum to the variance, and those of
        parameters that offset each other (an unobservable combination) are of either sign."""
        lin = self.linearise(np.asarray(x, dtype=float)[None])
        J = lin.jacobians[0]
        if self.covariance_l is None:
            return [(row, J[row.row] ** 2 * self.variance_l) for row in self.scored]
        return [(row, J[row.row] * (self.covariance_l @ J[row.row])) for row in self.scored]

    def _log_inequalities(self, lin, covariance, S, residual) -> tuple[np.ndarray, np.ndarray]:
        """log P_lin(H | X, O) on the fixed draws, and its standard error.

        The poses are the linear-Gaussian model's (conditional mean plus the fixed draws
        through its Cholesky root); the signed distances are evaluated exactly at each, or, for a
        relation whose distances are linear in the pose (a face), to first order about the mean
        (one small matrix product, no rotation matrices per draw).
        """
        if self.in_l_space:  # fewer L than rows (many relations): rank-nL draws (module docstring)
            mean, root = self.conditional_in_l_space(lin, S, residual)
            conditional = None
        else:
            mean, conditional = self.conditional_poses(lin, covariance, S, residual)
            root = _scaled_cholesky(conditional)
        P, M = mean.shape[0], self.draws.shape[0]
        # log of each draw's smoothed indicator, draws first: (M, P)
        log_smooth = np.zeros((M, P))
        for k, term in enumerate(self.relations):
            relation = term.relation
            block = slice(6 * k, 6 * k + 6)
            centre = mean[:, block]
            block_root = np.swapaxes(root[:, block], 1, 2)  # (P, q, 6): the block's rows of the root (q columns)
            if relation.linear_in_pose:
                # Distances linear in the pose (a face's polygon): first order about the mean is
                # exact but for the rotation's second order, and one small matrix product.
                # (a point's distances do not move with the rotation: their rotation rows are 0)
                moved = POSE_STEPS if relation.depends_on_rotation else POSE_STEPS[:3]
                m = len(moved)
                steps = np.concatenate([centre[:, None], centre[:, None] + moved, centre[:, None] - moved], axis=1)
                at_steps = relation.inequalities(steps.reshape(-1, 6)).reshape(P, 1 + 2 * m, -1)
                gradient = np.zeros((P, 6, at_steps.shape[2]))  # (P, 6, c)
                gradient[:, :m] = (at_steps[:, 1 : m + 1] - at_steps[:, m + 1 :]) / (
                    2.0 * moved.diagonal()[None, :, None]
                )
                at_centre, distances = at_steps[:, 0], None  # (P, c); the draws' distances below, scaled
                # g^T R: each distance's change per unit of the draws (P, q, c), so that the draws'
                # distances are one product with the draws, never the drawn poses themselves
                projected = block_root @ gradient
                if conditional is None:  # g^T R R^T g
                    spread = np.sum(projected**2, axis=1)
                else:
                    spread = np.sum(gradient * (conditional[:, block, block] @ gradient), axis=1)  # g^T C g
            else:
                # The signed distances at each drawn pose, not linearised about the mean: a peg's
                # radial distance |r| - c has no gradient where the peg is centred, which is where
                # the search takes it, and a first-order distance there ignores the lateral error.
                poses = centre[:, None] + self.draws @ block_root  # (P, M, 6): the drawn poses
                distances = relation.inequalities(poses.reshape(-1, 6)).reshape(P, M, -1)
                spread = distances.var(axis=1)  # (P, c): each distance's spread under the draws
            # uncertain dimensions (a face's size, a cylinder's length) are independent of the pose:
            # P(d + e <= 0) for a normal e of variance v is Phi(-d / sqrt(v)), so v widens each
            # inequality's probit kernel (to first order in the dimensions)
            dimensions = relation.dimension_variance(centre, self.variance_l) if relation.uncertain else 0.0
            bandwidth = np.sqrt((self.smoothing * relation.widths) ** 2 + self.draw_smoothing**2 * spread + dimensions)
            # The logistic kernel log sigma(-LOGISTIC d / h) = -softplus(LOGISTIC d / h), close to log Phi(-d / h).
            scale = LOGISTIC / np.maximum(bandwidth, 1e-300)  # (P, c)
            if distances is None:  # d / h at the draws: z^T (R^T g) scaled, one product over every X
                arguments = np.tensordot(self.draws, projected * scale[:, None, :], axes=([1], [1]))  # (M, P, c)
                arguments += at_centre * scale
                log_smooth -= softplus_sum(arguments)
            else:
                log_smooth -= softplus_sum(np.multiply(distances, scale[:, None, :], out=distances)).T
        log_smooth = log_smooth.T  # (P, M)
        peak = log_smooth.max(axis=1, keepdims=True)
        weights = np.exp(log_smooth - peak)
        mean_weight = weights.mean(axis=1)
        se = weights.std(axis=1) / (mean_weight * math.sqrt(M))
        return np.log(mean_weight) + peak[:, 0], se


#: -|a| below this leaves 1 + exp(-|a|) equal to 1 in double precision (exp(-40) < 2^-53), and keeps
#: exp out of its subnormal range, where it is 5-30 times slower
SOFTPLUS_FLOOR = 40.0
#: factors 1 + exp(-|a|) (each at most 2) multiplied before one logarithm: 2^1000 is finite
SOFTPLUS_PRODUCT = 1000
#: rows shorter than this (a face's few edges) are summed column by column: numpy reduces such a
#: short last axis with one loop per row (the same additions in the same order, 1.5-2.5 times
#: slower); from 8 on it adds in pairs, and its reduce is the order kept
SOFTPLUS_COLUMNS = 8


def softplus_sum(a: np.ndarray) -> np.ndarray:
    """The sum over the last axis of log(1 + exp(a)), overflow-free, overwriting ``a``.

    log(1 + e^a) = max(a, 0) + log(1 + e^-|a|), and the second terms' sum is the logarithm of
    their factors' product: one logarithm per row instead of a log1p per entry, which costs
    about twice an exp (the search's hottest line). Equal to numpy's logaddexp(0, a) summed
    within a few ulp of the sum per entry (each factor's rounding), and to within 4.3e-18 per
    entry where |a| > 40."""
    factors = np.abs(a)
    np.minimum(factors, SOFTPLUS_FLOOR, out=factors)
    np.negative(factors, out=factors)
    np.exp(factors, out=factors)
    factors += 1.0
    np.maximum(a, 0.0, out=a)
    columns = a.shape[-1]
    if 0 < columns < SOFTPLUS_COLUMNS:
        total, product = a[..., 0].copy(), factors[..., 0].copy()
        for column in range(1, columns):
            total += a[..., column]
            product *= factors[..., column]
        total += np.log(product)
        return total[()]  # a scalar for one row, as the reduction gives
    total = np.add.reduce(a, axis=-1)
    for start in range(0, columns, SOFTPLUS_PRODUCT):
        total += np.log(np.multiply.reduce(factors[..., start : start + SOFTPLUS_PRODUCT], axis=-1))
    return total


#: step of the coordinates' second differences, relative to the point's distance from the sphere's
#: centre or the cylinder's axis: truncation error ~ this squared
COORDINATE_STEP = 1e-3


def coordinate_hessians(coordinates, positions: np.ndarray) -> np.ndarray:
    """The Hessians in the Cartesian position of a chain's curvilinear coordinates
    (:attr:`bcad.kinematics.chain.BatchTransform.coordinates`: three per point), by central second
    differences: (P, 3, 3, 3), [point, coordinate, a, b].

    Args:
        coordinates: the map (3, *batch) -> (3, *batch) of Cartesian positions to coordinates.
        positions: the points (P, 3), in the surface's frame (length unit).
    """
    P = len(positions)
    centre = positions.T
    radius = getattr(coordinates, "radius", None)
    # the distance to the sphere's centre or the cylinder's axis (rho = the distance coordinate + R)
    distance = np.abs(coordinates(centre)[2] + radius) if radius is not None else np.linalg.norm(positions, axis=1)
    step = COORDINATE_STEP * np.maximum(distance, 1e-9)  # (P,)
    offsets = np.eye(3)[:, :, None] * step  # (3 directions, 3, P)

    def difference(first: np.ndarray, second: np.ndarray) -> np.ndarray:
        found = first - second
        if radius is not None:
            # the first coordinate is an arc length round the surface's axis (radius x angle): a
            # difference across its cut (longitude pi to -pi) is taken the short way round
            period = 2.0 * math.pi * radius
            found[0] -= period * np.round(found[0] / period)
        return found

    # every pair a <= b's four points, (3, 4, pairs, P), in one evaluation of the map
    axis_a, axis_b = np.triu_indices(3)
    plus, minus = offsets[axis_a] + offsets[axis_b], offsets[axis_a] - offsets[axis_b]  # (pairs, 3, P)
    points = centre[:, None, None] + np.moveaxis(np.stack([plus, minus, -minus, -plus]), 2, 0)
    values = coordinates(points)
    mixed = difference(values[:, 0], values[:, 1]) - difference(values[:, 2], values[:, 3])  # (3, pairs, P)
    mixed /= 4.0 * step * step
    hessians = np.empty((P, 3, 3, 3))
    hessians[:, :, axis_a, axis_b] = hessians[:, :, axis_b, axis_a] = np.moveaxis(mixed, 2, 0)
    return hessians


def fixed_normal_points(count: int, dimension: int) -> np.ndarray:
    """``count`` standard-normal points in ``dimension``, in antithetic pairs (x, -x).

    Fixed, not seeded: I_lin is a deterministic approximation, so its
    quadrature points are part of the method, like Gauss nodes, and every
    seed searches the same landscape.
    """
    half = np.random.default_rng(QUADRATURE_SEED).standard_normal(((count + 1) // 2, dimension))
    return np.concatenate([half, -half])[:count]


def _scaled_cholesky(covariance: np.ndarray) -> np.ndarray:
    """A root R (R R^T = the matrix) of PSD matrices (P, r, r) that may be singular (rows without
    spread): Cholesky's, or where rounding defeats it, the eigen-decomposition's.

    The matrix is scaled to a correlation matrix first, so the small ridge
    that makes it definite is relative to each row's own unit (mm or rad).
    """
    diagonal = np.diagonal(covariance, axis1=1, axis2=2)
    scale = np.sqrt(np.where(diagonal > 0.0, diagonal, 0.0))
    safe = np.where(scale > 0.0, scale, 1.0)
    correlation = covariance / (safe[:, :, None] * safe[:, None, :])
    correlation = correlation + 1e-10 * np.eye(covariance.shape[-1])
    try:
        return np.linalg.cholesky(correlation) * scale[:, :, None]
    except np.linalg.LinAlgError:
        # Rounding left some matrix below the ridge (stds of 1e9 beside 1e-3 cancel in the
        # conditional covariance): a symmetric root with the eigenvalues floored at the ridge,
        # any root R with R R^T the matrix serving the draws as well as Cholesky's.
        values, vectors = np.linalg.eigh(0.5 * (correlation + np.swapaxes(correlation, 1, 2)))
        return (vectors * np.sqrt(np.maximum(values, 1e-10))[:, None, :]) * scale[:, :, None]
