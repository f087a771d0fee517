"""What every result document shares: the command that wrote it (``kind``), the version of its
schema, its units and its messages.

Each family owns the model of its result (:mod:`bcad.bayes.result`, :mod:`bcad.worstcase.result`,
:mod:`bcad.calibration.result`); ``bcad schema --results`` prints their JSON Schema
(``schema/results.schema.json`` is its copy). A document is checked against its model as it is
written, so the schema holds for every result bcad writes.

``schema_version`` grows when a key changes meaning or goes away; a new key does not change it
(readers must ignore keys they do not know: every model here keeps them).
"""

from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict

#: the version of the result documents' schema
SCHEMA_VERSION = 1


class ResultModel(BaseModel):
    """A part of a result document: the keys listed are checked, others are kept as they are."""

    model_config = ConfigDict(extra="allow", serialize_by_alias=True, validate_by_name=True, validate_by_alias=True)


def checked(document: dict, model: type[ResultModel]) -> dict:
    """The document, once its family's ``model`` has checked it: the published schema holds for
    every result bcad writes (a mismatch is a bug, reported as one). Its numbers are Python's own
    (a numpy scalar or array becomes a float, an int, a bool or a list), so that any serialiser
    writes it, not only json's."""
    document = plain(document)
    model.model_validate(document)
    return document


def plain(value):
    """``value`` with every numpy scalar and array inside it (dicts, lists, tuples) made Python's own."""
    if isinstance(value, dict):
        return {key: plain(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(item) for item in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


class Units(ResultModel):
    """The units of every length and angle in the document: the problem's."""

    length: str
    angle: str


class Message(ResultModel):
    """A warning (the result cannot be trusted: exit 3) or a finding (worth knowing: exit 0)."""

    code: str
    message: str
