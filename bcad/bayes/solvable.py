"""Whether a problem is a Bayesian inverse problem that solve and posterior take: the refusals
(exit code 2) before any estimator is built.

Kept apart from the model (:mod:`bcad.bayes.model`, which builds the estimators) so that
``bcad validate`` tells what solve would refuse without importing them.
"""

from __future__ import annotations

from bcad.bayes.work import chain_links
from bcad.compiler import CompiledProblem

#: the most X a Bayesian search takes: its Newton steps evaluate n(n + 1)/2 points (200 X: about
#: 20 s on a 2-core machine, bench figures in the README's Limits)
MAX_UNKNOWNS = 200


#: unknowns times cycles of a problem with configurations, at most (:func:`check_solvable`)
MAX_CONFIGURATION_WORK = 512
#: the most cycles a Bayesian problem has (relations and closing links): every posterior sample
#: evaluates each cycle's chain
MAX_CYCLES = 200
#: the links of all cycles' chains together that a search takes, at most: it costs about 0.1 s per
#: link on 2 cores (a UR5 touching a face through its whole chain, 18 links a relation: 10, 20, 40
#: relations in 17, 34, 70 s and 0.6, 1.0, 1.8 GB; the RX90 example: 31 links, 3.3 s)
MAX_SEARCH_LINKS = 400


def check_solvable(compiled: CompiledProblem, needs_unknowns: bool = True) -> None:
    """The checks that make a problem a Bayesian inverse problem (exit code 2 otherwise).

    ``needs_unknowns=False`` accepts a problem without X: its posterior is a pure
    propagation of uncertainty, which ``bcad posterior`` can sample.
    """
    doc = compiled.problem.source
    if compiled.problem.measurements:
        # The measurements are edges of the graph (the paper's calibration), but the solver's
        # integrand does not condition on them yet: refuse rather than ignore them.
        raise doc.error(
            ("measurements",),
            f"the problem has {len(compiled.problem.measurements)} measurement set(s), which solve and "
            "posterior do not condition on (they would be ignored); run 'bcad calibrate' on it to identify "
            "its L from them, then plan in a problem without measurements that names the result in "
            "'calibration:' (or pass it with --calibration)",
            key=True,
        )
    if needs_unknowns and not compiled.parameters.x:
        raise doc.error(
            (), "the problem has no X (unknown) parameter, so there is nothing to optimise; mark some parameters X"
        )
    if needs_unknowns and len(compiled.parameters.x) > MAX_UNKNOWNS:
        raise doc.error(
            (),
            f"the problem has {len(compiled.parameters.x)} unknown parameters (X); the search handles at most "
            f"{MAX_UNKNOWNS} (each Newton step evaluates n(n + 1)/2 points): fix some (F), or give them a "
            "distribution (L) and integrate over them",
        )
    if not compiled.graph.cycles:
        raise doc.error(
            (), "the problem has no cycle, so there is nothing to close; add a link or relation that closes a loop"
        )
    if compiled.configurations and len(compiled.parameters.x) * len(compiled.graph.cycles) > MAX_CONFIGURATION_WORK:
        # the branch search climbs every configuration's joints and combines them, and each
        # whole-X Newton step evaluates n^2 points of every cycle
        raise doc.error(
            ("configurations",),
            f"{len(compiled.configurations)} configurations make {len(compiled.parameters.x)} "
            f"X in {len(compiled.graph.cycles)} cycles; the search takes X x cycles <= {MAX_CONFIGURATION_WORK} "
            "(a 2-joint arm at 16 configurations: 32 x 16, about 40 s): fewer configurations, or fewer X "
            "(F joints that need not move)",
            key=True,
        )
    if len(compiled.graph.cycles) > MAX_CYCLES:
        raise doc.error(
            ("relations",) if compiled.problem.relations else (),
            f"the problem has {len(compiled.graph.cycles)} cycles; solve and posterior take at most {MAX_CYCLES} "
            "(each sample evaluates every cycle's chain: 100 cycles of a point on a face take about 20 s): "
            "split the problem, or check fewer relations at once",
            key=bool(compiled.problem.relations),
        )
    links = chain_links(compiled)
    if needs_unknowns and links > MAX_SEARCH_LINKS:
        raise doc.error(
            ("relations",) if compiled.problem.relations else (),
            f"the problem's {len(compiled.graph.cycles)} "
            f"cycles hold {links} links in all (each cycle's chain, from its closing link round the tree); "
            f"the search takes at most {MAX_SEARCH_LINKS} (about 0.1 s each: 20 touches of a UR5 through its "
            "whole chain, 360 links, take 34 s): fewer relations, or relations that close nearer (between "
            "a part's own entities rather than through the robot); posterior takes it as it is",
            key=bool(compiled.problem.relations),
        )
    for cycle in compiled.graph.cycles:
        link = compiled.graph.links[cycle.closing_link]
        scored_by_inequalities = link.relation is not None and link.relation.inequality_count > 0
        if not link.distributions and not scored_by_inequalities:
            raise doc.error(
                link.loc + ("status",),
                f"'{link.name}' closes a cycle but has no distribution to score the closure (status {link.status}); "
                "make the parameters it constrains L with a distribution, e.g. 'tz: normal(0, 0.5)' "
                "(a relation with inequalities, such as a peg in a hole, is scored by them alone)",
            )
