"""Pydantic schemas of the problem language, and reading them from YAML."""

from bcad.model.problem import Joint, Link, Problem, Relation, Robot, Units, load_problem

__all__ = ["Joint", "Link", "Problem", "Relation", "Robot", "Units", "load_problem"]
