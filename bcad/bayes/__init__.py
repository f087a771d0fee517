"""The Bayesian family (Mekhnacha, Mazer and Bessière 2000): X* = argmax p(X) I(X) (Eq. 2) and
the closing links' posterior there.

The problem's model is built once (:mod:`bcad.bayes.model`) and passed down: the objective
(:mod:`~bcad.bayes.objective`), the estimators of I(X) (:mod:`~bcad.bayes.linear`,
:mod:`~bcad.bayes.importance`, :mod:`~bcad.bayes.estimators`), the global search on the
linearised objective (:mod:`~bcad.bayes.search`), the paper's GA (:mod:`~bcad.bayes.genetic`,
:mod:`~bcad.bayes.refine`, :mod:`~bcad.bayes.genetic_search`), the nominal backend
(:mod:`~bcad.bayes.nominal`), the posterior (:mod:`~bcad.bayes.posterior`), the contributors to
its variance and the verdicts (:mod:`~bcad.bayes.trust`).
"""
