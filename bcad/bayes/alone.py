"""Each configuration's cell on its own: the branch search's other ranking of a configuration's
branches (:mod:`bcad.bayes.branches`), where the other configurations' branches do not weigh.

A cell at C configurations shares its L (one robot's errors) and its shared X (a base placement)
across them; each configuration's own X (its replicated joints) enter only its own cycles. Its
cell alone keeps every L and every shared X and drops the relations and links that only other
configurations list.
"""

from __future__ import annotations

import numpy as np

from bcad.compiler import CompiledProblem, compile_problem
from bcad.errors import InputError


def configuration_alone(compiled: CompiledProblem) -> list[tuple[CompiledProblem, np.ndarray] | None]:
    """Per configuration with X of its own (in the order of
    :func:`bcad.bayes.configurations.configuration_blocks`), the cell at that configuration alone:
    the relations and links that only other configurations list dropped, every L and shared X
    kept. With it, the full X's column of each of its X; None where that cell has no
    cycle left to score or does not stand alone (it needs a link another configuration lists, or
    its X are not the full cell's: configurations that name different joints).
    Nothing for a cell without configurations."""
    problem = compiled.problem
    if not problem.configurations:
        return []
    columns = {p.name: k for k, p in enumerate(compiled.parameters.x)}
    found = []
    for configuration, mask in zip(problem.configurations, configuration_masks(compiled)):
        if not mask.any():
            continue
        # a configuration lists links and relations under either key
        others = {name for c in problem.configurations if c is not configuration for name in c.relations + c.links}
        try:
            alone = compile_problem(
                problem.model_copy(
                    update={
                        "configurations": [configuration],
                        "relations": [r for r in problem.relations if r.name not in others],
                        "links": [link for link in problem.links if link.name not in others],
                    }
                )
            )
        except InputError:  # the cell leans on what another configuration lists: no cell of its own
            found.append(None)
            continue
        names = [p.name for p in alone.parameters.x]
        # Where configurations name different joints, the full cell replicates every joint any of
        # them names and the cell alone only its own: its X are not the full cell's, so no cell.
        if not alone.graph.cycles or any(name not in columns for name in names):
            found.append(None)
            continue
        found.append((alone, np.array([columns[name] for name in names], dtype=int)))
    return found


def configuration_masks(compiled: CompiledProblem) -> list[np.ndarray]:
    """Per configuration, a mask of the X columns that are its own (its replicated joints), empty
    masks kept."""
    links = compiled.graph.links
    owner = [links[p.link].configuration if p.link >= 0 else None for p in compiled.parameters.x]
    return [np.array([o == c.name for o in owner]) for c in compiled.configurations]
