"""The nonlinear clearance model P' = prod_j exp(dS_j) S_j (Eq. 10) and a local
search for its largest error, started from the first-order maximiser.

The exact error is that of dP = P^-1 P' (Eq. 11): its rotation angle and the
norm of its translation, in F_{n+1} like the first-order dp. The local
search (scipy SLSQP on the clearance-scaled variables, with the discs as
inequality constraints and the intervals as bounds) finds a feasible point,
so its value is a true lower bound of the exact maximum; it is not a
certificate (the exact problem is not certified by bcad).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bcad.worstcase.error_map import ErrorMap
from bcad.kinematics.se3 import invert


def twist_exponential(screw: np.ndarray) -> np.ndarray:
    """exp of the twist [dr; dt] as a 4x4 matrix (Rodrigues, with the SE(3) V matrix)."""
    omega, v = screw[:3], screw[3:]
    theta = float(np.linalg.norm(omega))
    W = np.array([[0, -omega[2], omega[1]], [omega[2], 0, -omega[0]], [-omega[1], omega[0], 0]])
    if theta < 1e-8:
        # Series to second order: exact to double precision for such small angles.
        R = np.eye(3) + W + 0.5 * W @ W
        V = np.eye(3) + 0.5 * W + W @ W / 6.0
    else:
        a = np.sin(theta) / theta
        b = (1 - np.cos(theta)) / theta**2
        c = (theta - np.sin(theta)) / theta**3
        R = np.eye(3) + a * W + b * W @ W
        V = np.eye(3) + b * W + c * W @ W
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = V @ v
    return T


def exact_errors(error_map: ErrorMap, screws: np.ndarray) -> tuple[float, float]:
    """(rotation angle, translation norm) of P^-1 P' for error screws (n, 6)."""
    P = np.eye(4)
    shifted = np.eye(4)
    for S, screw in zip(error_map.S, screws):
        P = P @ S
        shifted = shifted @ twist_exponential(screw) @ S
    delta = invert(P) @ shifted
    R = delta[:3, :3]
    sine = 0.5 * np.linalg.norm([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    cosine = 0.5 * (np.trace(R) - 1.0)
    return float(np.arctan2(sine, cosine)), float(np.linalg.norm(delta[:3, 3]))


@dataclass
class ExactSearch:
    max: float
    argmax: np.ndarray
    start_value: float


def exact_local_maximum(error_map: ErrorMap, start: np.ndarray, problem: str) -> ExactSearch:
    """Largest exact error found by SLSQP from ``start`` (the first-order argmax)."""
    from scipy.optimize import minimize

    which = 0 if problem == "rotation" else 1
    n = error_map.joints
    # (slots, clearance column, kind): dr_xy, dr_z, dt_xy, dt_z.
    groups = [((0, 1), 0, "disc"), ((2,), 1, "interval"), ((3, 4), 2, "disc"), ((5,), 3, "interval")]
    if problem == "rotation":
        groups = groups[:2]  # the rotation of dP does not depend on dt
    variables = []  # (joint, slot, scale)
    discs = []
    for j in range(n):
        for slots, column, kind in groups:
            radius = error_map.clearance[j, column]
            if radius <= 0:
                continue
            first = len(variables)
            variables += [(j, slot, radius) for slot in slots]
            if kind == "disc":
                discs.append((first, first + 1))
    if not variables:
        return ExactSearch(0.0, np.zeros((n, 6)), 0.0)

    def screws_of(y: np.ndarray) -> np.ndarray:
        screws = np.zeros((n, 6))
        for value, (j, slot, scale) in zip(y, variables):
            screws[j, slot] = value * scale
        return screws

    y0 = np.array([start[j, slot] / scale for j, slot, scale in variables])
    constraints = [{"type": "ineq", "fun": (lambda y, a=a, b=b: 1.0 - y[a] ** 2 - y[b] ** 2)} for a, b in discs]
    result = minimize(
        lambda y: -exact_errors(error_map, screws_of(y))[which],
        y0,
        method="SLSQP",
        bounds=[(-1.0, 1.0)] * len(variables),
        constraints=constraints,
        options={"maxiter": 200, "ftol": 1e-16},
    )
    y = result.x
    # Pull back inside the discs, should SLSQP end a hair outside.
    for a, b in discs:
        norm = np.hypot(y[a], y[b])
        if norm > 1.0:
            y[[a, b]] /= norm * (1.0 + 1e-15)
    start_value = exact_errors(error_map, start)[which]
    value = exact_errors(error_map, screws_of(y))[which]
    if value < start_value:
        return ExactSearch(start_value, start, start_value)
    return ExactSearch(value, screws_of(y), start_value)
