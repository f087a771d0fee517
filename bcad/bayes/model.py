"""A problem's Bayesian model, built once and passed down.

In the spirit of Pinocchio's model/data split: what depends only on the problem is built once
per problem (the compiled graph, the objective p(X) I(X) of Eq. 2, the samplers of L, the
linearisation of every integrand pose in L, the importance sampler), and every solver, estimator
and posterior pass of a run receives it; what depends on X or on a sample batch (a
:class:`~bcad.kinematics.chain.Samples`, a population) is made per call.
"""

from __future__ import annotations

import threading

import numpy as np

from bcad.bayes.alone import configuration_alone
from bcad.bayes.closure import CycleClosure
from bcad.bayes.importance import ImportanceSampler
from bcad.bayes.linear import POLISH_DRAW_SMOOTHING, POLISH_DRAWS, POLISH_SMOOTHING, LinearModel
from bcad.bayes.objective import Objective
from bcad.bayes.sampling import FreeParameterSampler
from bcad.bayes.work import chain_links
from bcad.compiler import CompiledProblem


class BayesModel:
    """The Bayesian family's view of one compiled problem (module docstring)."""

    def __init__(self, compiled: CompiledProblem):
        self.compiled = compiled
        self.objective = Objective(compiled)
        #: draws L from p(L) restricted to the tree links' relations (Sect. 4.1.2, step 1);
        #: scrambled Sobol points first where ``solver.qmc`` asks for them
        self.sampler = FreeParameterSampler(compiled, qmc=compiled.problem.solver.qmc)
        #: the same, always pseudo-random: the importance sampler's proposal starts from it
        self.prior_sampler = self.sampler if not self.sampler.qmc else FreeParameterSampler(compiled)
        #: every integrand pose linearised in L (central differences): I_lin and the contributors
        self.linear = LinearModel(compiled, self.objective)
        # The search evaluates I_lin thousands of times: forward differences halve the cost,
        # and their O(h) error (about 1e-6 relative) is far below what a search resolves.
        self.search_linear = LinearModel(compiled, self.objective, central=False)
        #: the cycles closed with L at nominal (the nominal backend's, the search's starts and
        #: block moves): built once here
        self.closure = CycleClosure(compiled, self.objective)
        self._importance: ImportanceSampler | None = None
        self._building = threading.Lock()
        self._polish_linear: LinearModel | None = None
        self._alone: list[tuple[BayesModel, np.ndarray] | None] | None = None

    @property
    def polish_linear(self) -> LinearModel:
        """I_lin with sharper inequality kernels (POLISH_* of :mod:`bcad.bayes.linear`), closer to
        the exact integrand, that the finalists climb last (built on first use)."""
        if self._polish_linear is None:
            self._polish_linear = LinearModel(
                self.compiled,
                self.objective,
                draws=POLISH_DRAWS,
                central=False,
                smoothing=POLISH_SMOOTHING,
                draw_smoothing=POLISH_DRAW_SMOOTHING,
            )
        return self._polish_linear

    def configurations_alone(self) -> list[tuple[BayesModel, np.ndarray] | None]:
        """Per configuration with X of its own, the model of the cell at that configuration alone and
        the full X's column of each of its X (:func:`bcad.bayes.alone.configuration_alone`:
        None where it has no cycle; nothing without configurations), built on first use."""
        if self._alone is not None:  # (a forked lineage's process reads it without the lock)
            return self._alone
        with self._building:
            if self._alone is None:
                self._alone = [
                    None if cell is None else (BayesModel(cell[0]), cell[1])
                    for cell in configuration_alone(self.compiled)
                ]
        return self._alone

    @property
    def importance(self) -> ImportanceSampler:
        """The importance sampler of I(X), built on first use (the GA's runs never need it), once
        even where threads ask for it together (:func:`bcad.bayes.run.posterior_and_estimate`)."""
        with self._building:
            if self._importance is None:
                self._importance = ImportanceSampler(self.compiled, self.objective, self.linear, self.prior_sampler)
        return self._importance


#: the most X a Bayesian search takes: its Newton steps evaluate n(n + 1)/2 points (200 X: about
#: 20 s on a 2-core machine, bench figures in the README's Limits)
MAX_UNKNOWNS = 200


#: unknowns times cycles of a problem with configurations, at most (module check_solvable)
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
