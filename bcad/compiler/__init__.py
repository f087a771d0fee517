"""From a validated problem to a probabilistic kinematic graph.

:func:`compile_problem` and :class:`CompiledProblem` live in :mod:`bcad.compiler.problem`,
loaded on first use (PEP 562), so that a light submodule (:mod:`bcad.compiler.units`) does
not bring in the whole graph compiler. ``bcad.compile(problem)`` is the API's entry.
"""

_NAMES = ("CompiledProblem", "ProblemStats", "compile_any", "compile_problem")

__all__ = list(_NAMES)


def __getattr__(name: str):
    if name in _NAMES:
        from bcad.compiler import problem

        return getattr(problem, name)
    raise AttributeError(f"module 'bcad.compiler' has no attribute {name!r}")
