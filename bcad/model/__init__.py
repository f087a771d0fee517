"""Pydantic schemas of the problem language, and reading them from YAML.

The names below come from :mod:`bcad.model.problem`, loaded on first use (PEP 562): a
clearance problem (:mod:`bcad.model.clearance`) needs none of the graph language's schemas,
whose classes take a tenth of a second to build."""

_NAMES = ("Joint", "Link", "Problem", "Relation", "Robot", "Units", "load_problem")

__all__ = list(_NAMES)


def __getattr__(name: str):
    if name in _NAMES:
        from bcad.model import problem

        return getattr(problem, name)
    raise AttributeError(f"module 'bcad.model' has no attribute {name!r}")
