"""Benchmark: the Bayesian solver on the RX90 Face-On-Face example.

Prints Table 1 of the 2000 paper for bcad's reconstruction (with the solve
time), then compares, seed by seed, the genetic algorithm of ``estimator:
mc`` in the paper-faithful configuration (no common random numbers, no
refinement: the GA's best as it is) and with common random numbers,
re-ranking and validated refinement, on wall time and on the final log
objective log p(X*) I(X*), both estimated on the same independent 1e5
samples. Last, the wall time of the two commands as a user runs them
(start-up included; the default estimator, importance: see
bench/estimators.py for its figures).

Run: python bench/solve_rx90.py [--seeds 3]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from timing import as_the_command_line  # noqa: E402  (bench/ is on the path)
from user_environment import user_environment, warm_bytecode  # noqa: E402  (bench/ is on the path)

from bcad.bayes.genetic_search import solve_bayes
from bcad.bayes.model import BayesModel
from bcad.bayes.sampling import FreeParameterSampler
from bcad.compiler import compile_problem
from bcad.kinematics import Samples
from bcad.model import load_problem
from bcad.model.solver import SolverSettings

PROBLEM = Path(__file__).resolve().parent.parent / "problems" / "rx90_face_on_face.yaml"


def wall(command: list[str]) -> float:
    """A command's wall time. Exit 3 (a result written with warnings) is a result: its timing
    counts and its warnings are printed; any other failure stops the benchmark with its stderr."""
    start = time.perf_counter()
    run = subprocess.run(command, capture_output=True, text=True, env=user_environment())
    seconds = time.perf_counter() - start
    if run.returncode == 3:
        print(f"note: {' '.join(command[2:4])} exited 3 (untrusted result): " + run.stderr.strip().splitlines()[-1])
    elif run.returncode != 0:
        sys.exit(f"{' '.join(command[2:])} failed with exit {run.returncode}:\n{run.stderr[-2000:]}")
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args()
    warm_bytecode()
    as_the_command_line()
    compiled = compile_problem(load_problem(PROBLEM))
    model = BayesModel(compiled)
    objective = model.objective
    judge = Samples(FreeParameterSampler(compiled).draw(np.random.default_rng(12345), 100000))

    rows = {"paper": [], "ga-crn": []}
    for seed in range(args.seeds):
        for name, settings in (("paper", SolverSettings.paper()), ("ga-crn", SolverSettings(estimator="mc"))):
            start = time.perf_counter()
            solution = solve_bayes(model, settings, seed)
            seconds = time.perf_counter() - start
            value = float(objective.log_value(solution.x, judge, 0.0)[0])
            rows[name].append((seconds, value))
            print(f"seed {seed}  {name:7s}  {seconds:6.2f} s  log p(X*) I(X*) = {value:8.3f}", flush=True)

    with tempfile.TemporaryDirectory() as folder:
        result = Path(folder) / "result.json"
        solve_wall = wall([sys.executable, "-m", "bcad.cli", "solve", str(PROBLEM), "-o", str(result), "--quiet"])
        posterior_wall = wall(
            [sys.executable, "-m", "bcad.cli", "posterior", str(PROBLEM), "--at", str(result), "--samples", "1e5"]
        )

    stats = compiled.stats
    print()
    print("Table 1 (bcad's reconstruction; the paper's values in brackets)")
    print(f"  Integration space dimension       {stats.integration_dim:6d}   [50]")
    print(f"  Optimization space dimension      {stats.optimization_dim:6d}   [12]")
    print(f"  Number of cycles                  {stats.cycles:6d}   [1]")
    print(f"  Number of frames                  {stats.frames:6d}   [28]")
    print(f"  Number of inequality constraints  {stats.inequality_constraints:6d}   [16]")
    print(f"  Computation time (seconds)        {solve_wall:6.2f}   [13, PowerPC G3/400]")
    print()
    print(f"{'configuration':14s} {'time (s), mean':>15s} {'log objective, mean':>20s} {'min':>9s} {'max':>9s}")
    for name, values in rows.items():
        times, objectives = zip(*values)
        print(
            f"{name:14s} {statistics.mean(times):15.2f} {statistics.mean(objectives):20.3f} "
            f"{min(objectives):9.3f} {max(objectives):9.3f}"
        )
    print()
    print(f"bcad solve (wall, start-up included):            {solve_wall:6.2f} s")
    print(f"bcad posterior --samples 1e5 (wall, start-up included): {posterior_wall:6.2f} s")


if __name__ == "__main__":
    main()
