"""Benchmark: the chains' linearisation in L, analytic against forward differences.

Every evaluation of the search's objective log p(X) I_lin(X) linearises every chain in L at its
mean. :meth:`bcad.bayes.linear.LinearModel.linearise` walks each chain's steps once per X
(:func:`bcad.kinematics.jacobian.pose_jacobian`: each L's column is the twist of the steps it
moves); forward differences, which it replaced, evaluate the chain at the mean and at the mean
moved by 1e-3 std along each L: nL + 1 chain evaluations per X, batched, with the L-only segments
and the sines and cosines of the L cached per batch. Printed, on the RX90 example for random X in
the box: each one's time per batch of X, and their largest difference (relative to the
Jacobian's largest entry: the differences' truncation error).

Run: python bench/linearise.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from timing import as_the_command_line  # noqa: E402  (bench/ is on the path)

from bcad.bayes.model import BayesModel
from bcad.compiler.problem import compile_any
from bcad.kinematics.chain import Samples

REPO = Path(__file__).resolve().parent.parent
PROBLEM = REPO / "problems" / "rx90_face_on_face.yaml"


def forward_differences(model, population: np.ndarray, points: Samples) -> np.ndarray:
    """Every chain's Jacobian in L by forward differences on ``points`` (the mean, then the mean
    moved along each L), shape (P, 6 chains, nL)."""
    parts = []
    for chain in model.chains:
        poses = chain.evaluate_population(population, points).poses()  # (P, 1 + n, 6)
        difference = poses[:, 1:] - poses[:, :1]
        difference[..., 3:] = (difference[..., 3:] + np.pi) % (2 * np.pi) - np.pi
        parts.append(np.swapaxes(difference / model.step[None, :, None], 1, 2))
    return np.concatenate(parts, axis=1)


def per_call(function, repeats: int) -> float:
    start = time.perf_counter()
    for _ in range(repeats):
        function()
    return (time.perf_counter() - start) / repeats


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    as_the_command_line()
    compiled = compile_any(PROBLEM)
    model = BayesModel(compiled).search_linear
    n = len(model.mean_l)
    points = np.repeat(model.mean_l[None], 1 + n, axis=0)
    points[1:] += np.diag(model.step)
    points = Samples(points)
    low, high = model.objective.bounds[:, 0], model.objective.bounds[:, 1]
    rng = np.random.default_rng(0)
    print(f"{PROBLEM.name}: {n} L, {len(low)} X; forward differences with steps 1e-3 std")
    print("   X per batch   forward differences ms   analytic ms   largest difference (relative)")
    for count in (5, 103, 1236):
        population = low + (high - low) * rng.random((count, len(low)))
        analytic = model.linearise(population).jacobians
        differences = forward_differences(model, population, points)
        relative = np.abs(analytic - differences).max() / np.abs(analytic).max()
        assert relative < 1e-3, relative  # differences with steps of 1e-3 std: O(1e-5) apart
        fd = per_call(lambda: forward_differences(model, population, points), args.repeats)
        exact = per_call(lambda: model.linearise(population), args.repeats)
        print(f"{count:14d} {fd * 1e3:24.2f} {exact * 1e3:13.2f}   {relative:.1e}")


if __name__ == "__main__":
    main()
