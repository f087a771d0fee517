"""Benchmark of the certified exact-model bound: is it ever below the exact error a
30-start search finds, how tight is it, and how fast?

    python bench/maxerror_exact.py [--starts 30] [--random 2] [--scales 1,10,100] [--repeats 3]

For the chains in problems/clearance/ and random DH chains of 2 to 20 joints (``--random`` per
size, seeded), each at 1x, 10x and 100x its clearances: the first-order certified maximum
(branch and bound, tol 1e-6), the certified bound on the exact model (exact.bound: the sharp
bound of bcad/worstcase/exact_bound.py where it beats the scalar one), and the best
exact error of bcad's multi-start search (exact_maximum: +-x* and ``--starts`` random starts, every point
feasible: a true lower bound of the exact maximum). Prints, per scale, the worst ratio
found / bound (must stay <= 1) and the gaps (bound - found) / bound; then the wall time of
``bcad maxerror FILE --model exact`` (a fresh process, start-up included) at 7 and 20 joints and
of the first-order path at 20 joints. Last, the yield of a spec on the 2R example by bcad
(``--yield-samples`` samples) against a plain Monte Carlo of as many fresh samples evaluated with
scipy's matrix exponential (not bcad's formula): the difference in combined standard errors.
"""

from __future__ import annotations

import argparse
import math
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml
from user_environment import user_environment, warm_bytecode  # noqa: E402  (bench/ is on the path)

from bcad.model.clearance import chain_problem_from_document, load_chain_problem
from bcad.model.source import SourceDocument
from bcad.worstcase.branch_and_bound import certified_maximum
from bcad.worstcase.error_map import build_error_map
from bcad.worstcase.exact import exact_maximum, exact_upper_bounds
from bcad.worstcase.exact_bound import exact_bound

FOLDER = Path(__file__).resolve().parent.parent / "problems" / "clearance"
CLEARANCE = {"rot_xy": 1.0e-4, "rot_z": 5.0e-5, "trans_xy": 1.0e-5, "trans_z": 5.0e-6}


def random_chain(joints: int, seed: int) -> dict:
    """A DH chain of ``joints`` rows (a in [0, 0.5], d in [0, 0.4], alpha in {0, +-pi/2}, theta
    uniform) with the 7r example's clearances."""
    rng = np.random.default_rng(seed)
    rows = [
        {
            "a": float(rng.uniform(0, 0.5)),
            "alpha": float(rng.choice([0.0, math.pi / 2, -math.pi / 2])),
            "d": float(rng.uniform(0, 0.4)),
            "theta": float(rng.uniform(-math.pi, math.pi)),
        }
        for _ in range(joints)
    ]
    return {"name": f"random-{joints}-{seed}", "chain": {"dh": rows}, "clearance": dict(CLEARANCE)}


def scaled(document: dict, factor: float) -> dict:
    document = yaml.safe_load(yaml.safe_dump(document))
    rows = document["clearance"] if isinstance(document["clearance"], list) else [document["clearance"]]
    for row in rows:
        for key in row:
            row[key] = row[key] * factor
    return document


def check(document: dict, folder: Path, starts: int) -> list[tuple[str, float, float]]:
    """(kind, found / bound, gap) for both kinds."""
    problem = chain_problem_from_document(SourceDocument(path=folder / "chain.yaml", data=document))
    error_map = build_error_map(problem)
    out = []
    for index, kind in enumerate(("rotation", "translation")):
        first = certified_maximum(error_map, kind, 1e-6)
        bound = exact_upper_bounds(error_map, first.upper_bound, first.upper_bound)[index]
        # the bound as bcad reports it: the sharp one (from +-x*'s search, as the command runs it)
        # where it beats the scalar one
        own = exact_maximum(error_map, first.argmax, kind)
        sharp = exact_bound(error_map, kind, own.max, own.argmax, 1e-6, bound)
        bound = bound if sharp is None else sharp.bound
        found = exact_maximum(error_map, first.argmax, kind, starts=starts, rng=np.random.default_rng(7)).max
        out.append((kind, found / bound if bound > 0 else 0.0, (bound - found) / bound if bound > 0 else 0.0))
    return out


def wall(path: Path, *args: str) -> float:
    # the console script beside this interpreter, as a user runs it (else the module)
    script = Path(sys.executable).with_name("bcad")
    command = [str(script)] if script.exists() else [sys.executable, "-m", "bcad.cli"]
    start = time.perf_counter()
    run = subprocess.run(
        [*command, "maxerror", str(path), "--json", *args], capture_output=True, text=True, env=user_environment()
    )
    if run.returncode not in (0, 3):  # 3: a gap above --tol, said with a warning (both figures certified)
        sys.exit(f"{path.name}: exit {run.returncode}\n{run.stderr[-2000:]}")
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--starts", type=int, default=30)
    parser.add_argument("--random", type=int, default=2, help="random chains per size (2, 5, 10, 15, 20 joints)")
    parser.add_argument("--yield-samples", type=float, default=1e6)
    parser.add_argument("--scales", default="1,10,100", help="clearance scales, comma-separated")
    parser.add_argument(
        "--repeats", type=int, default=5, help="runs per wall time (the best and the median are printed)"
    )
    parser.add_argument(
        "--timings-only", action="store_true", help="only the wall times and the in-process first-order time"
    )
    args = parser.parse_args()
    warm_bytecode()
    examples = [yaml.safe_load(path.read_text()) for path in sorted(FOLDER.glob("*.yaml"))]
    # URDF chains need their files: the DH ones here; and the norm problems (the wall problem's unit
    # clearance of absolute angles is tests/worstcase/test_directional.py's)
    examples = [
        d for d in examples if "dh" in d.get("chain", {}) and d["chain"].get("angles", "relative") == "relative"
    ]
    chains = examples + [random_chain(n, seed) for n in (2, 5, 10, 15, 20) for seed in range(args.random)]
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        print(f"{len(chains)} chains ({len(examples)} examples), {args.starts + 2} starts per exact search")
        print(f"{'scale':>6} {'kind':<12} {'max found/bound':>16} {'below':>6} {'gap median':>11} {'gap max':>9}")
        for factor in [] if args.timings_only else [float(v) for v in args.scales.split(",")]:
            for kind in ("rotation", "translation"):
                rows = [r for d in chains for r in check(scaled(d, factor), folder, args.starts) if r[0] == kind]
                ratios = [r[1] for r in rows]
                gaps = [r[2] for r in rows]
                print(
                    f"{factor:>5g}x {kind:<12} {max(ratios):>16.9f} {sum(r > 1 for r in ratios):>6} "
                    f"{statistics.median(gaps):>11.2e} {max(gaps):>9.2e}"
                )
        seven = FOLDER / "7r.yaml"
        twenty = folder / "random20.yaml"
        twenty.write_text(yaml.safe_dump(random_chain(20, 0)))
        for label, path, extra in (
            ("7 joints, --model exact", seven, ["--model", "exact"]),
            ("20 joints, --model exact", twenty, ["--model", "exact"]),
            ("20 joints, first-order", twenty, []),
        ):
            times = [wall(path, *extra) for _ in range(args.repeats)]
            print(
                f"bcad maxerror ({label}): {min(times):.2f} s wall best, {statistics.median(times):.2f} s median "
                f"of {args.repeats}, start-up included"
            )
        error_map = build_error_map(load_chain_problem(twenty))
        start = time.perf_counter()
        for kind in ("rotation", "translation"):
            certified_maximum(error_map, kind, 1e-6)
        print(f"first-order certified maximum, 20 joints, both kinds, in process: {time.perf_counter() - start:.3f} s")
    if not args.timings_only:
        yield_check(int(args.yield_samples))


def yield_check(samples: int) -> None:
    from bcad.worstcase.statistics import error_statistics, sample_screws

    problem = load_chain_problem(FOLDER / "2r.yaml")
    error_map = build_error_map(problem)
    spec = {"rotation": 0.0015, "translation": 0.001}
    found = error_statistics(error_map, problem.name, "m", samples, np.random.default_rng(5), spec)["yield"]
    # The independent evaluation (scipy's expm of each twist) is the test suite's, shared here.
    sys.path[:0] = [str(FOLDER.parent.parent / "tests"), str(FOLDER.parent.parent / "tests" / "worstcase")]
    from test_maxerror_exact import _independent_errors

    inside = 0
    rng = np.random.default_rng(6)
    for start in range(0, samples, 100_000):
        angle, translation = _independent_errors(
            error_map, sample_screws(error_map, min(100_000, samples - start), rng)
        )
        inside += int(np.sum((angle <= spec["rotation"]) & (translation <= spec["translation"])))
    share = inside / samples
    se = math.sqrt(share * (1 - share) / samples)
    combined = math.hypot(se, found["se"])
    print(
        f"yield of rotation <= 1.5 mrad and translation <= 1 mm on 2r, {samples} samples each: bcad {found['value']:.5f} "
        f"± {found['se']:.5f}, plain Monte Carlo with expm {share:.5f} ± {se:.5f}: "
        f"{abs(found['value'] - share) / combined:.2f} combined se apart"
    )


if __name__ == "__main__":
    main()
