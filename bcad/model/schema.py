"""The JSON Schema of the problem language, for editors (``bcad schema``).

One schema for both kinds of problem file: a graph problem (:class:`Problem`) or a
clearance problem (:class:`ChainProblem`), generated from the pydantic models so that
it cannot drift from what bcad accepts. Editors that speak the YAML language server
validate and complete a problem file whose first line is
``# yaml-language-server: $schema=PATH/bcad.schema.json``. The schema checks shapes and
ranges; what needs the whole file (names that refer to each other, a status against
its distributions, the graph) is ``bcad validate``'s.
"""

from __future__ import annotations

from pydantic.json_schema import models_json_schema

from bcad.version import __version__

SCHEMA_DRAFT = "https://json-schema.org/draft/2020-12/schema"


def json_schema_of(models: list, mode: str, name: str, title: str, description: str) -> dict:
    """One JSON Schema document that is any one of ``models`` (pydantic), their definitions shared.

    Args:
        models: the pydantic models, in the order the schema lists them.
        mode: "validation" (what bcad reads) or "serialization" (what it writes).
        name: the file name the schema is published under (its $id).
        title, description: the schema's own.
    """
    references, definitions = models_json_schema([(model, mode) for model in models], ref_template="#/$defs/{model}")
    return {
        "$schema": SCHEMA_DRAFT,
        "$id": f"https://bcad.invalid/schema/{name}",
        "title": title,
        "description": description,
        "anyOf": [references[(model, mode)] for model in models],
        "$defs": definitions["$defs"],
    }


def problem_json_schema() -> dict:
    from bcad.model.clearance import ChainProblem
    from bcad.model.problem import Problem

    return json_schema_of(
        [Problem, ChainProblem],
        "validation",
        "bcad.schema.json",
        f"bcad problem (bcad {__version__})",
        "A bcad problem file: a probabilistic kinematic graph (frames, robots, links, entities, relations, "
        "measurements) or a clearance chain (chain, clearance).",
    )
