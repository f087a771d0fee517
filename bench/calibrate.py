"""Benchmark of calibration: a 6R full-DH calibration from 50 and 500 measurements.

    python bench/calibrate.py [--repeats 5]

The robot is the UR5 of problems/calibration/ur5_tracker.yaml (classic DH,
its base in the tracker frame X, every row's theta, d, a and alpha errors L,
Hayati's beta on rows 2 and 3, the reflector offset L: 6 + 29 parameters),
measured at N random configurations of the true robot of ur5_truth.py with
0.05 mm noise. For each N it prints the wall time of ``bcad calibrate`` as a
user runs it (a fresh process, a user's environment with bcad's bytecode
cached: bench/user_environment.py; start-up and the importance-sampling check with its default 1000 samples included; the
median of --repeats runs), the time of the solve alone in this process, and
the fit (whitened RMS residual, 1 when the model explains the data).
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
import yaml
from user_environment import user_environment, warm_bytecode  # noqa: E402  (bench/ is on the path)

REPO = Path(__file__).resolve().parent.parent
EXAMPLE = REPO / "problems" / "calibration"
sys.path.insert(0, str(EXAMPLE))

import ur5_truth  # noqa: E402

from bcad.calibration.model import CalibrationModel  # noqa: E402
from bcad.calibration.solve import calibrate  # noqa: E402
from bcad.compiler import compile_problem  # noqa: E402
from bcad.model import load_problem  # noqa: E402


def full_dh_problem(folder: Path, count: int, seed: int, full: bool = True) -> Path:
    """The example with ``count`` measurements and, if ``full``, every row's four DH errors
    (the example leaves out those of row 1 that are the base's and those of row 6 that are the reflector's)."""
    document = yaml.safe_load((EXAMPLE / "ur5_tracker.yaml").read_text())
    joints = document["robots"][0]["joints"]
    errors = {"theta": "normal(0, 0.01)", "d": "normal(0, 2)", "a": "normal(0, 2)", "alpha": "normal(0, 0.01)"}
    for name in ("joint_1", "joint_4", "joint_5", "joint_6") if full else ():
        joints[name] = {"dh_error": dict(errors)}
    rng = np.random.default_rng(seed)
    q = ur5_truth.configurations(rng, count)
    measured = np.array([ur5_truth.reflector_in_tracker(row) for row in q]) + rng.normal(0, ur5_truth.NOISE, (count, 3))
    lines = [",".join(ur5_truth.JOINTS + ["tx", "ty", "tz"])]
    lines += [",".join(repr(float(v)) for v in [*q[r], *measured[r]]) for r in range(count)]
    (folder / f"data{count}.csv").write_text("\n".join(lines) + "\n")
    document["measurements"][0]["data"] = f"data{count}.csv"
    path = folder / f"{'full_dh' if full else 'example'}_{count}.yaml"
    path.write_text(yaml.safe_dump(document, sort_keys=False))
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    warm_bytecode()
    with tempfile.TemporaryDirectory() as folder:
        for count, full in ((50, True), (500, True), (50, False), (500, False)):
            path = full_dh_problem(Path(folder), count, seed=count, full=full)
            walls = []
            for _ in range(args.repeats):
                start = time.perf_counter()
                run = subprocess.run(
                    ["bcad", "calibrate", str(path), "--json", "--quiet"],
                    capture_output=True,
                    text=True,
                    env=user_environment(),
                )
                walls.append(time.perf_counter() - start)
                if run.returncode not in (0, 3):
                    sys.exit(f"bcad calibrate failed: {run.stderr}")
            document = json.loads(run.stdout)
            compiled = compile_problem(load_problem(path))
            model = CalibrationModel(compiled)
            solves = []
            for _ in range(args.repeats):
                start = time.perf_counter()
                calibrate(compiled, model)
                solves.append(time.perf_counter() - start)
            n = len(document["parameters"])
            print(
                f"{'full DH' if full else 'example model'}, {count} measurements, {n} parameters: `bcad calibrate` {statistics.median(walls):.2f} s wall "
                f"(median of {args.repeats}, check included: ESS {document['check']['effective_samples']:.0f}, "
                f"k {document['check']['pareto_k']}); solve alone {statistics.median(solves) * 1000:.0f} ms; "
                f"whitened RMS {document['residuals']['rms_whitened_after']:.3f}; "
                f"{len(document['unobservable'])} unobservable combinations; warnings {[w['code'] for w in document['warnings']]}"
            )


if __name__ == "__main__":
    main()
