"""The relation kinds are a registry: one module each, found at import, listed by the schema
and the language reference, built by the compiler."""

from __future__ import annotations

import sys
import textwrap
import typing

import pytest

from bcad import relations
from bcad.model.entities import Entity
from bcad.model.problem import Relation

from conftest import REPO

KIND_MODULES = sorted(
    path.stem
    for path in (REPO / "bcad" / "relations").glob("*.py")
    if path.stem not in {"__init__", "geometry", "kind"}
)


def test_every_module_of_the_package_is_a_registered_kind_of_its_name():
    assert sorted(relations.RELATIONS) == KIND_MODULES
    for name, kind in relations.RELATIONS.items():
        assert kind.name == name


def test_the_schema_accepts_exactly_the_registered_kinds_and_documents_each():
    accepted = typing.get_args(Relation.model_fields["type"].annotation)
    assert sorted(accepted) == KIND_MODULES
    entity_types = {
        typing.get_args(member.model_fields["type"].annotation)[0]
        for member in typing.get_args(typing.get_args(Entity)[0])
    }
    for kind in relations.RELATIONS.values():
        assert {kind.parent, kind.child} <= entity_types, kind.name
        assert f"``{kind.name}`` ({kind.parent}, {kind.child}): {kind.summary}" in Relation.__doc__


@pytest.fixture
def extra_kinds(tmp_path, monkeypatch):
    """A folder searched as part of the package; what it adds is forgotten afterwards."""
    monkeypatch.setattr(relations, "__path__", [*relations.__path__, str(tmp_path)])
    yield tmp_path
    for name in [module for module in sys.modules if module.startswith("bcad.relations.")]:
        if not hasattr(sys.modules[name], "__file__") or str(tmp_path) in str(sys.modules[name].__file__):
            sys.modules.pop(name)
            if hasattr(relations, name.rpartition(".")[2]):
                delattr(relations, name.rpartition(".")[2])


def test_a_module_added_to_the_package_is_found(extra_kinds):
    (extra_kinds / "ring_on_face.py").write_text(
        textwrap.dedent(
            """
            from bcad.relations.kind import RelationKind
            from bcad.relations.point_on_face import constraint

            RELATION = RelationKind(
                name="ring_on_face", parent="face", child="point", summary="tz = 0.",
                build=lambda parent, child: constraint(parent.polygon()),
            )
            """
        )
    )
    found = relations._discover()
    assert set(found) == set(relations.RELATIONS) | {"ring_on_face"}
    assert found["ring_on_face"].parent == "face"


def test_a_module_whose_relation_is_named_otherwise_is_refused(extra_kinds):
    (extra_kinds / "misnamed.py").write_text("from bcad.relations.point_on_point import RELATION\n")
    with pytest.raises(ImportError, match="declares the relation 'point_on_point'"):
        relations._discover()
