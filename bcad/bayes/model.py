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
