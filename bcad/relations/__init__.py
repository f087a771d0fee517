"""The geometric relations of the problem language, one module per kind.

Every module of this package but :mod:`~bcad.relations.geometry` (the constraints' shared
geometry) and :mod:`~bcad.relations.kind` (what a kind declares) defines ``RELATION``, a
:class:`~bcad.relations.kind.RelationKind`. They are found when the package is imported, so that
adding a relation is adding one module (and its test): the schema accepts its name, the compiler
builds it and the language reference documents it.
"""

from __future__ import annotations

import importlib
import pkgutil

from bcad.relations.kind import RelationError, RelationKind

__all__ = ["RELATIONS", "RelationError", "RelationKind", "relation_kind"]

_SHARED = {"geometry", "kind"}


def _discover() -> dict[str, RelationKind]:
    found: dict[str, RelationKind] = {}
    for module in sorted(info.name for info in pkgutil.iter_modules(__path__)):
        if module in _SHARED or module.startswith("_"):
            continue
        kind = importlib.import_module(f"{__name__}.{module}").RELATION
        if kind.name != module:
            raise ImportError(f"bcad.relations.{module} declares the relation '{kind.name}': name it as its module")
        found[kind.name] = kind
    return found


#: every relation kind, by name (alphabetical)
RELATIONS: dict[str, RelationKind] = _discover()


def relation_kind(name: str) -> RelationKind:
    """The kind named ``name`` (a schema-validated relation's ``type``)."""
    return RELATIONS[name]
