"""From a validated problem to a probabilistic kinematic graph."""

from bcad.compile.compiler import CompiledProblem, ProblemStats, compile_problem

__all__ = ["CompiledProblem", "ProblemStats", "compile_problem"]
