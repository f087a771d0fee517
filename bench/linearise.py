"""Benchmark: the search's linearisation of the chains in L against an analytic Jacobian.

The search climbs log p(X) I_lin(X); each evaluation linearises every chain in L at its mean by
forward differences (:meth:`bcad.bayes.linear.LinearModel.linearise` of the search's model:
nL + 1 chain evaluations per X, batched). The analytic Jacobian below walks the chain's steps once per X: each L enters a
step about (or along) an axis a of the frame before it, at origin o, so its column is
(a x (t - o), E^-1 a) for a rotation and (a, 0) for a translation, t the chain's end and E the
map from rpy rates to the angular velocity of R = Rz Ry Rx. Printed, on the RX90 example for
random X in the box: the largest difference of the two (relative to the Jacobian's largest
entry: the differences' truncation error) and each one's time per batch of X.

Run: python bench/linearise.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from bcad.bayes.model import BayesModel
from bcad.compiler.problem import compile_any
from bcad.kinematics.chain import ConstantStep, fold_steps, link_steps
from bcad.runtime import tune_allocator

REPO = Path(__file__).resolve().parent.parent
PROBLEM = REPO / "problems" / "rx90_face_on_face.yaml"


def _rotations(axis: int, c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Rotations about ``axis`` by angles of cosines ``c`` and sines ``s``, shape (P, 3, 3)."""
    R = np.zeros((len(c), 3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[:, axis, axis] = 1.0
    R[:, i, i] = R[:, j, j] = c
    R[:, i, j], R[:, j, i] = -s, s
    return R


def analytic_jacobian(steps, population: np.ndarray, l_values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A chain's poses (P, 6) at L = ``l_values`` for each X row, and their Jacobians in L (P, 6, nL)."""
    P = len(population)
    R, t = np.broadcast_to(np.eye(3), (P, 3, 3)).copy(), np.zeros((P, 3))
    moved_by_l = []  # (kind, world axis (P, 3), origin (P, 3), the step's L terms)
    for step in steps:
        if isinstance(step, ConstantStep):
            t, R = t + R @ step.matrix[:3, 3], R @ step.matrix[:3, :3]
            continue
        value = np.full(P, step.value.offset)
        terms = [term for term in step.value.terms if term.source == "l"]
        for term in step.value.terms:
            value = value + term.coefficient * (
                population[:, term.index] if term.source == "x" else l_values[term.index]
            )
        axis = R[:, :, step.axis].copy()
        if terms:
            moved_by_l.append((step.kind, axis, t.copy(), terms))
        if step.kind == "translation":
            t = t + axis * value[:, None]
        else:
            R = R @ _rotations(step.axis, np.cos(value), np.sin(value))
    rx, rz = np.arctan2(R[:, 2, 1], R[:, 2, 2]), np.arctan2(R[:, 1, 0], R[:, 0, 0])
    ry = np.arctan2(-R[:, 2, 0], np.hypot(R[:, 0, 0], R[:, 1, 0]))
    cb, sb, cg, sg = np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    J = np.zeros((P, 6, len(l_values)))
    for kind, a, origin, terms in moved_by_l:
        if kind == "rotation":  # omega = a: rpy rates from omega = ez g' + Rz ey b' + Rz Ry ex a'
            alpha = (cg * a[:, 0] + sg * a[:, 1]) / cb
            rates = np.column_stack([alpha, -sg * a[:, 0] + cg * a[:, 1], a[:, 2] + sb * alpha])
            column = np.column_stack([np.cross(a, t - origin), rates])
        else:
            column = np.column_stack([a, np.zeros((P, 3))])
        for term in terms:
            J[:, :, term.index] += term.coefficient * column
    return np.column_stack([t, rx, ry, rz]), J


def per_call(function, repeats: int) -> float:
    start = time.perf_counter()
    for _ in range(repeats):
        function()
    return (time.perf_counter() - start) / repeats


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    tune_allocator()
    compiled = compile_any(PROBLEM)
    model = BayesModel(compiled).search_linear
    # the chains' steps as links give them, folded (before the plan that caches L-only segments)
    chains = [
        fold_steps([s for link, forward in chain.links for s in link_steps(link, forward)]) for chain in model.chains
    ]
    low, high = model.objective.bounds[:, 0], model.objective.bounds[:, 1]
    rng = np.random.default_rng(0)
    kind = "central" if model.central else "forward"
    print(f"{PROBLEM.name}: {len(model.mean_l)} L, {len(low)} X; {kind} differences with steps 1e-3 std")
    print("   X per batch   finite differences ms   analytic ms   largest difference (relative)")
    for count in (5, 103, 1236):
        population = low + (high - low) * rng.random((count, len(low)))
        reference = model.linearise(population)
        parts = [analytic_jacobian(steps, population, model.mean_l) for steps in chains]
        J = np.concatenate([j for _, j in parts], axis=1)
        poses = np.concatenate([p for p, _ in parts], axis=1)
        assert np.allclose(poses, reference.poses, atol=1e-9)
        relative = np.abs(J - reference.jacobians).max() / np.abs(reference.jacobians).max()
        assert relative < 1e-3, relative  # differences with steps of 1e-3 std: O(1e-5) apart
        fd = per_call(lambda: model.linearise(population), args.repeats)
        exact = per_call(lambda: [analytic_jacobian(s, population, model.mean_l) for s in chains], args.repeats)
        print(f"{count:14d} {fd * 1e3:23.2f} {exact * 1e3:13.2f}   {relative:.1e}")


if __name__ == "__main__":
    main()
