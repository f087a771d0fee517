"""Each command's wall time as a user's shell sees it, beside its lower bound and its target.

    python bench/commands.py [--repeats 5] [--samples 1e5]

Every command runs in a fresh process, in a user's environment with the bytecode cache written
(bench/user_environment.py); the figure is the median of ``--repeats`` runs, start-up included.
Beside it:

* the lower bound: Python's own start-up (``python -c pass``), plus, for the commands that draw
  posterior samples, the chain's cost for those samples evaluated from scratch (drawing the L and
  evaluating every closing link once: what bench/kinematics.py calls "from scratch");
* the libraries' floor: Python with the third-party libraries each command imports (typer for
  every command, rich for those that print; numpy, pydantic's models and yaml for those that read a problem, and python-flint
  for maxerror; the posterior from Python, ``bcad.posterior``, imports numpy, pydantic and
  yaml), plus the chain's cost where there is one: what no change to bcad's own code can
  go below;
* the target each command should meet on a 2-core machine;
* both as multiples of a plain numpy workload timed here (sines and a matrix product), so that a
  machine faster or slower than the reference moves the targets with it.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from timing import as_the_command_line
from user_environment import user_environment, warm_bytecode

REPO = Path(__file__).resolve().parent.parent
RX90 = REPO / "problems" / "rx90_face_on_face.yaml"
SEVEN_R = REPO / "problems" / "clearance" / "7r.yaml"
#: the numpy workload's time on the machine the targets were set on, s (see --help)
REFERENCE_WORKLOAD = 0.094
#: the third-party modules a program calling the Python API on a problem imports, and the commands:
#: every command, those that read a problem, maxerror
#: (pydantic's models: ``import pydantic`` alone defers them, and bcad's schema is made of them)
API_LIBRARIES = ("numpy", "pydantic.main", "yaml")
HELP_LIBRARIES = ("typer",)  # --help prints typer's text: no rich
CLI_LIBRARIES = (*HELP_LIBRARIES, "rich.console")
PROBLEM_LIBRARIES = (*CLI_LIBRARIES, *API_LIBRARIES)
FLINT_LIBRARIES = (*PROBLEM_LIBRARIES, "flint")
#: the posterior from Python, as a program calls it: bcad.posterior(PROBLEM, at=RESULT, samples=N)
API_POSTERIOR = "import sys, bcad; bcad.posterior(sys.argv[1], at=sys.argv[2], samples=int(sys.argv[3]))"


def median_wall(command: list[str], repeats: int) -> float:
    """The median wall time of ``command`` run ``repeats`` times in a user's environment, s."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run = subprocess.run(command, cwd=REPO, env=user_environment(), capture_output=True, text=True)
        times.append(time.perf_counter() - start)
        if run.returncode not in (0, 3):
            raise SystemExit(f"{' '.join(command)} exited {run.returncode}: {run.stderr[-500:]}")
    return statistics.median(times)


def numpy_workload() -> float:
    """The best of three runs of a fixed numpy workload, s: the machine's yardstick."""
    rng = np.random.default_rng(0)
    values, a = rng.standard_normal(4_000_000), rng.standard_normal((400, 400))
    best = float("inf")
    for _ in range(3):
        start = time.perf_counter()
        np.sin(values).sum()
        np.cos(values).sum()
        for _ in range(10):
            a @ a
        best = min(best, time.perf_counter() - start)
    return best


def chain_from_scratch(samples: int) -> float:
    """The RX90 example's chain evaluated from scratch for ``samples`` draws (best of 3), s: the L
    drawn by the sampler the commands use, then every closing link evaluated once, with the
    allocator and BLAS's threads as the ``bcad`` command sets them (:func:`timing.as_the_command_line`)."""
    from bcad.bayes.sampling import FreeParameterSampler
    from bcad.compiler import compile_problem
    from bcad.kinematics.chain import Samples
    from bcad.model import load_problem

    as_the_command_line()
    compiled = compile_problem(load_problem(RX90))
    sampler = FreeParameterSampler(compiled)
    x = np.array(compiled.parameters.x_nominal)
    best = float("inf")
    for seed in range(3):
        start = time.perf_counter()
        drawn = Samples(sampler.draw(np.random.default_rng(seed), samples))
        compiled.closing_poses(x, drawn)
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--samples", type=float, default=1e5, help="posterior samples of the posterior command")
    args = parser.parse_args()
    samples = int(args.samples)
    warm_bytecode()
    bcad = [sys.executable, "-m", "bcad.cli"]
    startup = median_wall([sys.executable, "-c", "pass"], args.repeats)
    help_libraries, cli_libraries, problem_libraries, flint_libraries, api_libraries = (
        median_wall([sys.executable, "-c", "import " + ", ".join(modules)], args.repeats)
        for modules in (HELP_LIBRARIES, CLI_LIBRARIES, PROBLEM_LIBRARIES, FLINT_LIBRARIES, API_LIBRARIES)
    )
    workload = numpy_workload()
    chain = chain_from_scratch(samples)
    scale = workload / REFERENCE_WORKLOAD
    with tempfile.TemporaryDirectory() as folder:
        # the solve runs first: its timed runs write the result the posterior rows start from
        solved = Path(folder) / "rx90.json"
        solve = [*bcad, "solve", str(RX90), "-o", str(solved), "--quiet"]
        measured = {"bcad solve rx90": median_wall(solve, args.repeats)}
        posterior_samples = json.loads(solved.read_text())["posterior"]["samples"]
        rows = [
            ("bcad --help", [*bcad, "--help"], 0.0, help_libraries, 0.12),
            ("bcad validate rx90", [*bcad, "validate", str(RX90)], 0.0, problem_libraries, 0.3),
            (
                f"bcad posterior rx90 --samples {samples:.0e}",
                [*bcad, "posterior", str(RX90), "--at", str(solved), "--samples", str(samples), "--json"],
                chain,
                problem_libraries,
                0.5,
            ),
            (
                f"bcad.posterior (Python) rx90, {samples:.0e}",
                [sys.executable, "-c", API_POSTERIOR, str(RX90), str(solved), str(samples)],
                chain,
                api_libraries,
                None,
            ),
            ("bcad solve rx90", solve, chain * posterior_samples / samples, problem_libraries, 1.5),
            (
                "bcad maxerror 7r --model exact",
                [*bcad, "maxerror", str(SEVEN_R), "--model", "exact", "--quiet"],
                0.0,
                flint_libraries,
                0.4,
            ),
            ("bcad maxerror 7r", [*bcad, "maxerror", str(SEVEN_R), "--quiet"], 0.0, flint_libraries, None),
        ]
        print(
            f"machine: numpy workload {workload:.3f} s ({scale:.2f} x the reference's {REFERENCE_WORKLOAD} s); "
            f"python start-up {startup * 1e3:.0f} ms; RX90 chain from scratch, {samples:.0e} samples: "
            f"{chain * 1e3:.0f} ms; typer imported {help_libraries * 1e3:.0f} ms, with rich {cli_libraries * 1e3:.0f} ms, "
            f"with numpy, pydantic and "
            f"yaml {problem_libraries * 1e3:.0f} ms, and flint {flint_libraries * 1e3:.0f} ms; numpy, pydantic and yaml "
            f"alone {api_libraries * 1e3:.0f} ms; medians of {args.repeats}"
        )
        print(
            f"{'command':40s} {'wall s':>8s} {'bound s':>8s} {'/bound':>6s} {'libraries s':>12s} {'/floor':>6s} "
            f"{'target s':>9s} {'met':>4s}"
        )
        for label, command, work, libraries, target in rows:
            wall = measured[label] if label in measured else median_wall(command, args.repeats)
            bound, floor = startup + work, libraries + work
            scaled = None if target is None else target * scale
            met = "" if scaled is None else ("yes" if wall <= scaled else "no")
            shown = "" if scaled is None else f"{scaled:.2f}"
            print(
                f"{label:40s} {wall:8.3f} {bound:8.3f} {wall / bound:6.1f} {floor:12.3f} {wall / floor:6.1f} "
                f"{shown:>9s} {met:>4s}"
            )


if __name__ == "__main__":
    main()
