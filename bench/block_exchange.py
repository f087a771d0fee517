"""Diagnostic: do a cell's seeds differ by whole combinations of configurations, or block by block?

    python bench/block_exchange.py CELL.yaml RESULT.json [RESULT.json ...]

For a cell at several configurations (``configurations:``) and the results of ``bcad solve`` on it
(several seeds; ``bench/random_cells.py --keep DIR`` writes both), each result's best maximum of
the search (``diagnostics.search.basins[0]``) is read back, and on the search's stand-in
log p(X) I_lin(X):

* every combination of the results' blocks (one configuration's joints from each result: R^C
  combinations) is screened, and the best ten climbed in full (Newton, 60 steps);
* each result's every block is replaced by the best result's block and climbed on that block
  alone (the others held): the gain, where the best result's branch of one configuration also
  serves the others' branches.

Where the mixed combinations screen well below the results' own and the block gains are 0, the
results are coherent wholes: a configuration's best joints depend on the others' (the
configurations share the robot's errors), and a search that improves one configuration at a
time, the others held, does not move from one whole to a better one.
"""

from __future__ import annotations

import argparse
import itertools
import json

import numpy as np

from bcad.bayes.configurations import configuration_blocks, screen
from bcad.bayes.document import solution_from_dict
from bcad.bayes.model import BayesModel
from bcad.bayes.search import maximise_in_rounds
from bcad.compiler import compile_problem
from bcad.model import load_problem

COMBINATIONS_CLIMBED = 10
STEPS = 60


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("cell")
    parser.add_argument("results", nargs="+")
    args = parser.parse_args()
    compiled = compile_problem(load_problem(args.cell))
    model = BayesModel(compiled)
    blocks = configuration_blocks(compiled)
    if len(blocks) < 2:
        raise SystemExit(f"{args.cell}: fewer than two configurations with joints of their own")
    maxima = []
    for path in args.results:
        basin = json.load(open(path))["diagnostics"]["search"]["basins"][0]["solution"]
        maxima.append(
            solution_from_dict(compiled, {k: v["value"] if isinstance(v, dict) else v for k, v in basin.items()})
        )
    maxima = np.array(maxima)
    own = screen(model, maxima)
    best = int(np.argmax(own))
    print("the results' maxima on the stand-in:", " ".join(f"{v:.3f}" for v in own))
    combos = list(itertools.product(range(len(maxima)), repeat=len(blocks)))
    rows = np.repeat(maxima[:1], len(combos), axis=0)
    for row, combo in zip(rows, combos):
        for mask, result in zip(blocks, combo):
            row[mask] = maxima[result, mask]
    screens = screen(model, rows)
    mixed = [k for k, combo in enumerate(combos) if len(set(combo)) > 1]
    print(
        f"{len(mixed)} mixed combinations: best screen {screens[mixed].max():.3f}, "
        f"median {np.median(screens[mixed]):.3f}"
    )
    order = np.argsort(-screens)[:COMBINATIONS_CLIMBED]
    climbed = maximise_in_rounds(model.search_linear, rows[order], STEPS)
    print("the best ten combinations climbed in full:", " ".join(f"{m.log_value:.3f}" for m in climbed))
    for k, x in enumerate(maxima):
        gains = []
        for mask in blocks:
            start = x.copy()
            start[mask] = maxima[best, mask]
            found = maximise_in_rounds(model.search_linear, np.vstack([x, start]), STEPS, anchor=x, mask=mask)
            gains.append(max(m.log_value for m in found) - own[k])
        print(
            f"result {k} ({own[k]:.3f}): gain of the best result's block, per block:",
            " ".join(f"{g:.3f}" for g in gains),
        )


if __name__ == "__main__":
    main()
