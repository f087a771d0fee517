"""From a validated problem to a probabilistic kinematic graph.

The package is callable: ``bcad.compile(problem)`` is :func:`compile_any` (a problem,
a path or a mapping to its :class:`CompiledProblem`), while ``bcad.compile.compile_problem``
and the submodules stay what they are.
"""

import sys
import types

from bcad.compile.compiler import CompiledProblem, ProblemStats, compile_any, compile_problem

__all__ = ["CompiledProblem", "ProblemStats", "compile_any", "compile_problem"]


class _CallablePackage(types.ModuleType):
    def __call__(self, problem) -> CompiledProblem:
        return compile_any(problem)


sys.modules[__name__].__class__ = _CallablePackage
