"""From a validated problem to a probabilistic kinematic graph.

The package is callable: ``bcad.compile(problem)`` is :func:`compile_any` (a problem,
a path or a mapping to its :class:`CompiledProblem`), while ``bcad.compile.compile_problem``
and the submodules stay what they are. The compiler is loaded on first use (PEP 562), so that
a light submodule (:mod:`bcad.compile.units`) does not bring in the whole graph compiler.
"""

import sys
import types

_NAMES = ("CompiledProblem", "ProblemStats", "compile_any", "compile_problem")

__all__ = list(_NAMES)


def __getattr__(name: str):
    if name in _NAMES:
        from bcad.compile import compiler

        return getattr(compiler, name)
    raise AttributeError(f"module 'bcad.compile' has no attribute {name!r}")


class _CallablePackage(types.ModuleType):
    def __call__(self, problem):
        from bcad.compile.compiler import compile_any

        return compile_any(problem)


sys.modules[__name__].__class__ = _CallablePackage
