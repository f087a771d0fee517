"""Benchmark: the search's stand-in objective, log p(X) + log I_lin(X), per batch of X.

Every Newton step of the search evaluates the stand-in (:mod:`bcad.bayes.linear`) on a batch of
X: the chains linearised in L at each X, the linear-Gaussian algebra, and where the problem has
relations, their inequalities smoothed over fixed draws (:meth:`LinearModel._log_inequalities`).
Printed for problems of the repository, on 1000 X of the box moved towards closure: the batch's
time, the linearisation's alone (its lower bound: every evaluation needs it) and their ratio.

Run: python bench/standin.py [--repeats 5] [--count 1000]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from timing import as_the_command_line, best_of  # noqa: E402  (bench/ is on the path)

from bcad.bayes.model import BayesModel
from bcad.compiler.problem import compile_any

REPO = Path(__file__).resolve().parent.parent
PROBLEMS = [
    REPO / "problems" / "rx90_face_on_face.yaml",
    REPO / "problems" / "ur5_probe_face.yaml",
    REPO / "problems" / "studies" / "ur5_peg_placement.yaml",
    REPO / "problems" / "relations" / "ur5_probe_sphere.yaml",
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--count", type=int, default=1000)
    args = parser.parse_args()
    as_the_command_line()
    print(f"{'problem':<28} {'X':>3} {'L':>3} {'stand-in ms':>12} {'linearise ms':>13} {'ratio':>6}")
    for path in PROBLEMS:
        model = BayesModel(compile_any(path))
        linear = model.search_linear
        bounds = model.objective.bounds
        rng = np.random.default_rng(0)
        x = bounds[:, 0] + (bounds[:, 1] - bounds[:, 0]) * rng.random((args.count, len(bounds)))
        x, _ = model.closure.close_many(x, 30)
        linear.log_integral_parts(x[:5])  # anything built on first use
        whole = best_of(lambda: linear.log_integral_parts(x), args.repeats)
        bound = best_of(lambda: linear.linearise(x), args.repeats)
        print(
            f"{path.name:<28} {len(bounds):>3} {len(linear.mean_l):>3} {whole * 1e3:>12.1f} {bound * 1e3:>13.1f} "
            f"{whole / bound:>6.1f}"
        )


if __name__ == "__main__":
    main()
