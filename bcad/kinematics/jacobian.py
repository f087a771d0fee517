"""A chain's poses and their derivatives in L, in one pass and without finite differences.

A chain is a product of constant transforms and axis steps (:mod:`bcad.kinematics.chain`): a
rotation about, or a translation along, a coordinate axis of the frame it starts from, by an
amount theta = offset + sum_j c_j L_j + (terms in X). Moving theta moves every frame after the
step rigidly, as the twist of the step's axis expressed in the base frame:

* a rotation about local axis a of the frame F = (R, p) the step ends in: omega = R e_a (the
  axis does not move under its own rotation) and v = p x omega, so a point q of the chain's end
  moves at omega x (q - p);
* a translation along local axis a: omega = 0 and v = R e_a.

The end T = (R_T, p_T) then moves as dp_T = omega x p_T + v and dR_T = [omega]x R_T, and the
pose's angles (R = Rz(rz) Ry(ry) Rx(rx), :mod:`bcad.kinematics.se3`) as E^-1 omega, where
omega = E (rx', ry', rz') for E = [Rz Ry e_x, Rz e_y, e_z]:

    rx' = (cos rz w_x + sin rz w_y) / cos ry
    ry' = -sin rz w_x + cos rz w_y
    rz' = w_z + sin ry rx'

Each L's column sums the twists of the steps it enters, times its coefficients. The cost is
one pass over the chain's steps for a population of X, against 1 + nL chain evaluations (2nL + 1
central) for differences; the derivatives are exact, where differences carry an O(h) or O(h^2)
error.
"""

from __future__ import annotations

import numpy as np

from bcad.kinematics.chain import Chain, ConstantStep

#: |cos ry| below which the pose's angles have no derivative (gimbal lock: rx and rz turn about
#: one axis); there the rows are left to finite differences (:func:`pose_jacobian` returns None)
GIMBAL_LOCK = 1e-6


def pose_jacobian(
    chain: Chain, population: np.ndarray, l_values: np.ndarray, cartesian: bool = False
) -> tuple[np.ndarray, np.ndarray] | None:
    """The chain's poses at L = ``l_values`` for each X of ``population`` (P, nX), shape (P, 6),
    and their derivatives in L, shape (P, 6, nL); None where the chain's translations are mapped
    to other coordinates (a point on a sphere; unless ``cartesian``) or some pose is at gimbal
    lock, for the caller to difference instead.

    Args:
        chain: the compiled chain.
        population: the unknowns X, one row per individual, shape (P, nX).
        l_values: the free parameters L at which to linearise, shape (nL,).
        cartesian: the translations in Cartesian coordinates even where the chain maps them to
            others (for the caller to apply the chain rule).
    """
    if chain.coordinates is not None and not cartesian:
        return None
    population = np.atleast_2d(np.asarray(population, dtype=float))
    l_values = np.asarray(l_values, dtype=float)
    P, n = population.shape[0], l_values.shape[0]
    # The running transform as A (4, 3, P): A[k] column k of R (k < 3), A[3] the translation p.
    A = np.zeros((4, 3, P))
    for k in range(3):
        A[k, k] = 1.0
    turns: list[tuple[np.ndarray, np.ndarray]] = []  # (omega, the point the axis passes through)
    slides: list[np.ndarray] = []  # the direction of a translation
    entries: list[tuple[str, int, int, float]] = []  # (kind, twist, L, coefficient)
    for step in chain.folded_steps:
        if isinstance(step, ConstantStep):
            A = (step.matrix.T @ A.reshape(4, -1)).reshape(4, 3, P)
            continue
        amount = step.value.offset
        moving = []
        for term in step.value.terms:
            if term.source == "x":
                amount = amount + term.coefficient * population[:, term.index]
            else:
                amount = amount + term.coefficient * l_values[term.index]
                moving.append(term)
        a = step.axis
        if step.kind == "translation":
            A[3] += A[a] * amount
            if moving:
                slides.append(A[a].copy())
                entries.extend(("slide", len(slides) - 1, t.index, t.coefficient) for t in moving)
            continue
        i, j = (a + 1) % 3, (a + 2) % 3
        c, s = np.cos(amount), np.sin(amount)
        column_i = A[i].copy()
        A[i] = column_i * c + A[j] * s
        A[j] = A[j] * c - column_i * s
        if moving:
            turns.append((A[a].copy(), A[3].copy()))
            entries.extend(("turn", len(turns) - 1, t.index, t.coefficient) for t in moving)
    R = np.moveaxis(A[:3], 0, 1)  # (3, 3, P): R[row, column]
    position = A[3]
    rx = np.arctan2(R[2, 1], R[2, 2])
    ry = np.arctan2(-R[2, 0], np.hypot(R[0, 0], R[1, 0]))
    rz = np.arctan2(R[1, 0], R[0, 0])
    cos_ry = np.cos(ry)
    if np.any(np.abs(cos_ry) < GIMBAL_LOCK):
        return None
    poses = np.column_stack([position.T, rx, ry, rz])
    jacobian = np.zeros((P, 6, n))
    if not entries:
        return poses, jacobian
    # Each twist's end velocity omega x (p_T - point) (a turn) or direction (a slide), and omega:
    # twists[k, :3] and twists[k, 3:], (K, 6, P).
    K = len(turns) + len(slides)
    twists = np.zeros((K, 6, P))
    if turns:
        w = np.stack([t[0] for t in turns])  # (K, 3, P)
        arm = position[None] - np.stack([t[1] for t in turns])
        twists[: len(turns), :3] = _cross(w, arm)
        twists[: len(turns), 3:] = w
    if slides:
        twists[len(turns) :, :3] = np.stack(slides)
    weights = np.zeros((K, n))  # each twist's coefficient per L
    for kind, twist, index, coefficient in entries:
        weights[twist if kind == "turn" else len(turns) + twist, index] += coefficient
    # every L's column at once: one matrix product (nL, K) @ (K, 6 P), a tenth of einsum's time
    rates = (weights.T @ twists.reshape(K, -1)).reshape(n, 6, P)
    jacobian[:, :3] = rates[:, :3].transpose(2, 1, 0)
    w_x, w_y, w_z = rates[:, 3:].transpose(1, 2, 0)  # (P, nL) each
    cos_rz, sin_rz = np.cos(rz)[:, None], np.sin(rz)[:, None]
    rate_x = (cos_rz * w_x + sin_rz * w_y) / cos_ry[:, None]
    jacobian[:, 3] = rate_x
    jacobian[:, 4] = -sin_rz * w_x + cos_rz * w_y
    jacobian[:, 5] = w_z + np.sin(ry)[:, None] * rate_x
    return poses, jacobian


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b over axis 1 of (K, 3, P) arrays (numpy's cross costs more in its axis handling than
    in the products on these small batches)."""
    return np.stack(
        [
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ],
        axis=1,
    )
