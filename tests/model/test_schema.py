"""`bcad schema`: the JSON Schema of the problem language validates every example in
problems/ (each names it on its first line for the YAML language server) and refuses what bcad
refuses in a file's shape."""

from __future__ import annotations

import json
import os

import jsonschema
import pytest
import yaml

from conftest import REPO, run_bcad

EXAMPLES = sorted((REPO / "problems").rglob("*.yaml"))
COMMITTED = REPO / "schema" / "bcad.schema.json"


@pytest.fixture(scope="module")
def schema() -> dict:
    run = run_bcad("schema")
    assert run.returncode == 0, run.stderr
    document = json.loads(run.stdout)
    jsonschema.Draft202012Validator.check_schema(document)
    return document


def test_the_committed_schema_is_what_bcad_schema_prints(schema):
    assert json.loads(COMMITTED.read_text()) == schema, "regenerate it: bcad schema > schema/bcad.schema.json"


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: str(p.relative_to(REPO / "problems")))
def test_every_example_names_the_schema_and_validates(schema, path):
    first = path.read_text().splitlines()[0]
    assert first == f"# yaml-language-server: $schema={os.path.relpath(COMMITTED, path.parent)}"
    jsonschema.validate(yaml.safe_load(path.read_text()), schema, cls=jsonschema.Draft202012Validator)


@pytest.mark.parametrize(
    "change",
    [
        {"bogus": 1},  # an unknown key
        {
            "links": [{"name": "l", "parent": "a", "child": "b", "distributions": {"tx": "normall(0, 1)"}}]
        },  # a misspelt distribution
        {"links": [{"name": "l", "parent": "a", "child": "b", "pose": [1e10, 0, 0, 0, 0, 0]}]},  # a length past 1e9
        {"solver": {"population": 0}},  # a setting out of its range
    ],
)
def test_the_schema_refuses_what_bcad_refuses(schema, tmp_path, change):
    document = {"name": "x", "frames": ["a", "b"], **change}
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(document, schema, cls=jsonschema.Draft202012Validator)
    path = tmp_path / "x.yaml"
    path.write_text(yaml.safe_dump(document))
    assert run_bcad("validate", path).returncode == 2
