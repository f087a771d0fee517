"""Benchmark: bcad batch on one machine and on a Dask LocalCluster.

A study of 24 problems (the planar 2R of problems/studies/ swept over its
second joint's zero-offset std) runs three ways: a serial loop in this
process, the local process pool (--jobs = number of cores) and a Dask
LocalCluster with one single-threaded worker process per core. Prints the
wall time of each and the speed-ups over the serial loop, and checks that
the three give the same results.

Run: python bench/batch.py [--problems 24]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from bcad.batch import Sweep, plan_tasks, run_batch

PROBLEM = Path(__file__).resolve().parent.parent / "problems" / "studies" / "planar_2r.yaml"


def results(folder: Path) -> dict:
    def strip(value):
        if isinstance(value, dict):
            return {k: strip(v) for k, v in value.items() if k not in ("seconds", "timings")}
        return [strip(v) for v in value] if isinstance(value, list) else value

    return {path.name: strip(json.loads(path.read_text())) for path in folder.glob("*.json")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--problems", type=int, default=24)
    args = parser.parse_args()
    cores = os.cpu_count() or 1
    sweep = Sweep(
        "links.zero2.distributions.rz.std", tuple(float(v) for v in np.round(np.linspace(0.01, 0.2, args.problems), 4))
    )
    figures, task_seconds = {}, {}
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)

        def timed(name: str, **options) -> None:
            out = folder / name
            out.mkdir()
            tasks = plan_tasks([PROBLEM], out, 0, [sweep])
            start = time.perf_counter()
            outcome = run_batch(tasks, **options)
            figures[name] = time.perf_counter() - start
            assert outcome.failed == 0, outcome.summaries
            task_seconds[name] = sum(line["seconds"] for line in outcome.summaries)

        timed("serial", jobs=1)
        timed("pool", jobs=cores)
        from dask.distributed import LocalCluster

        with LocalCluster(
            n_workers=cores, processes=True, threads_per_worker=1, host="127.0.0.1", dashboard_address=None
        ) as cluster:
            timed("dask", jobs=cores, scheduler=cluster.scheduler_address)
        same = results(folder / "serial") == results(folder / "pool") == results(folder / "dask")

    print(f"{args.problems} problems, {cores} cores")
    print(f"serial loop, in process:          {figures['serial']:7.2f} s")
    print(
        f"local pool (--jobs {cores}):             {figures['pool']:7.2f} s   speed-up {figures['serial'] / figures['pool']:.2f}x"
    )
    print(
        f"Dask LocalCluster ({cores} workers):     {figures['dask']:7.2f} s   speed-up {figures['serial'] / figures['dask']:.2f}x"
    )
    print(f"identical results: {same}")
    print("sum of per-task seconds: " + ", ".join(f"{name} {value:.2f} s" for name, value in task_seconds.items()))


if __name__ == "__main__":
    main()
