"""What a posterior costs, in chain links, and the refusal of one past about half a minute.

Kept apart from the model (:mod:`bcad.bayes.model`, which builds the estimators) so that
``bcad validate`` checks a problem's own ``solver.posterior_samples`` without importing them.
"""

from __future__ import annotations

from bcad.compiler import CompiledProblem
from bcad.errors import InputError

#: posterior samples times what each costs (:func:`posterior_work`), at most: 4e8 is about 30 s on
#: 2 cores (the RX90 example: 95 per sample, 1e6 samples in 6 s; an edge on a rail: 26, 1e6 in 1.6 s)
MAX_POSTERIOR_WORK = 400_000_000
#: what a sample costs beside its chains' links, in links (drawing, weighting, summing)
SAMPLE_OVERHEAD = 16


def chain_links(compiled: CompiledProblem) -> int:
    """The links of all cycles' chains together: each cycle's tree path and its closing link."""
    return sum(len(cycle.path) + 1 for cycle in compiled.graph.cycles)


def posterior_work(compiled: CompiledProblem) -> int:
    """What one posterior sample costs, in links: every cycle's chain (its tree path and closing
    link), one per L drawn, and :data:`SAMPLE_OVERHEAD`."""
    return chain_links(compiled) + len(compiled.parameters.l) + SAMPLE_OVERHEAD


def check_posterior_work(compiled: CompiledProblem, samples: int, option: str | None) -> None:
    """Refuse (exit 2) a posterior whose samples would take past about half a minute
    (:data:`MAX_POSTERIOR_WORK`), before drawing any. ``option`` names where the count came
    from (``--samples``, ``samples=``); None: the problem's ``solver.posterior_samples``."""
    per_sample = posterior_work(compiled)
    if samples * per_sample <= MAX_POSTERIOR_WORK:
        return
    most = MAX_POSTERIOR_WORK // per_sample
    message = (
        f"{samples:,} posterior samples of this problem (costing {per_sample} chain links each) would take "
        f"more than about half a minute; at most {most:,} are taken (samples x links <= "
        f"{MAX_POSTERIOR_WORK:.0e}); the standard error falls as one over the square root of the samples, "
        "so 4 times fewer only doubles it"
    )
    if option is None:
        raise compiled.problem.source.error(("solver", "posterior_samples"), message)
    raise InputError(option, message)
