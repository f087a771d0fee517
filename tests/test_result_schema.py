"""Typed results: every document bcad writes names its kind and schema version, validates against
the published JSON Schema (schema/results.schema.json, what `bcad schema --results` prints), and
reads back through its family's model without losing a key."""

from __future__ import annotations

import json

import pytest
from pydantic import ValidationError

import bcad
from bcad.result import checked, result_model

from conftest import ONE_LINK_GRAPH, REPO, run_bcad

jsonschema = pytest.importorskip("jsonschema")
COMMITTED = REPO / "schema" / "results.schema.json"
CALIBRATION = REPO / "problems" / "calibration"


def test_the_committed_schema_is_what_bcad_prints():
    run = run_bcad("schema", "--results")
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout) == json.loads(COMMITTED.read_text()), (
        "regenerate it: bcad schema --results > schema/results.schema.json"
    )


@pytest.fixture(scope="module")
def documents(tmp_path_factory):
    """One document of every kind and of the optional parts each may carry."""
    folder = tmp_path_factory.mktemp("results")
    problem = folder / "one.yaml"
    problem.write_text(ONE_LINK_GRAPH.lstrip("\n"))
    made = {
        "solve": bcad.solve(str(problem), samples=2000),
        "posterior": bcad.posterior(str(problem), values={"unknown.tx": 2.8}, samples=2000),
        "solve with a calibration": bcad.solve(str(CALIBRATION / "ur5_drill_plan.yaml"), samples=2000),
        "maxerror exact with statistics": bcad.maxerror(
            str(REPO / "problems" / "clearance" / "rx90_candle.yaml"),
            model="exact",
            spec={"rotation": 0.001},
            samples=5000,
        ),
        "maxerror allocation": bcad.maxerror(
            str(REPO / "problems" / "clearance" / "zhao_3dof_wall.yaml"), allocate={"dx": 0.09}
        ),
        "calibrate with cameras": bcad.calibrate(str(CALIBRATION / "ur5_eye_in_hand.yaml")),
    }
    documents = {name: json.loads(result.to_json()) for name, result in made.items()}
    for path in (CALIBRATION / "ur5_calibration.json", CALIBRATION / "ur5_eye_in_hand_calibration.json"):
        documents[f"committed {path.name}"] = json.loads(path.read_text())
    return documents


def test_every_kind_of_document_validates_against_the_published_schema(documents):
    schema = json.loads(COMMITTED.read_text())
    kinds = set()
    for name, document in documents.items():
        assert document["schema_version"] == 1, name
        kinds.add(document["kind"])
        jsonschema.validate(document, schema)
    assert kinds == {"solve", "posterior", "maxerror", "calibrate"}


def test_a_document_reads_back_through_its_model_key_for_key(documents):
    for name, document in documents.items():
        typed = result_model(document["kind"]).model_validate(document)
        assert typed.model_dump(mode="json", exclude_unset=True) == document, name


def test_the_schema_refuses_what_is_not_a_result(documents):
    """The check is real: a document missing a required key, or with a wrong type, is refused by
    the model bcad checks with and by the published schema."""
    schema = json.loads(COMMITTED.read_text())
    broken = dict(documents["maxerror allocation"])
    del broken["rotation"]
    with pytest.raises(ValidationError):
        checked(broken)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(broken, schema)
    wrong = json.loads(json.dumps(documents["solve"]))
    wrong["objective"]["samples"] = "many"
    with pytest.raises(ValidationError):
        checked(wrong)


def test_the_api_result_has_its_documents_fields():
    worst = bcad.maxerror(str(REPO / "problems" / "clearance" / "2r.yaml"))
    assert worst.rotation.upper_bound == worst.document["rotation"]["upper_bound"]
    assert worst.rotation.upper_bound >= worst.rotation.max > 0 and worst.units.length == "m"
    with pytest.raises(AttributeError, match="no 'links_of'"):
        worst.links_of  # noqa: B018
