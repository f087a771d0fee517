"""The base of every schema model: strict keys with a helpful "did you mean"."""

from __future__ import annotations

import difflib
import typing
from typing import Any, ClassVar

from pydantic import BaseModel, ConfigDict, model_validator
from pydantic_core import PydanticCustomError

from bcad.errors import quoted


class YesOrNo:
    """A YAML ``true`` or ``false`` where the field takes no yes/no (a number, a text): pydantic's lax
    mode reads True as 1 (``std: true`` was a std of 1), while no type of the language takes this,
    so the field is refused at its place, shown as written."""

    __slots__ = ("value",)

    def __init__(self, value: bool):
        self.value = value

    def __repr__(self) -> str:
        return "true" if self.value else "false"


def _takes_yes_or_no(annotation) -> bool:
    """Whether a field's annotation takes a yes/no anywhere in it, or a model (which checks its own
    fields) or anything."""
    if annotation is bool or annotation is Any:
        return True
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return True
    return any(_takes_yes_or_no(argument) for argument in typing.get_args(annotation))


def _marked(value):
    """``value`` with each yes/no in it (in lists and mappings too) a :class:`YesOrNo`; ``value``
    itself where it holds none."""
    if isinstance(value, bool):
        return YesOrNo(value)
    if isinstance(value, (list, tuple)):
        items = [_marked(item) for item in value]
        return items if any(new is not old for new, old in zip(items, value)) else value
    if isinstance(value, dict):
        items = {key: _marked(item) for key, item in value.items()}
        return items if any(items[key] is not item for key, item in value.items()) else value
    return value


#: per model, the fields that take no yes/no (:func:`_takes_yes_or_no`), found on first use
_NO_YES_OR_NO: dict[type, frozenset[str]] = {}


def yes_or_no_marked(model: type[BaseModel], data: dict) -> dict:
    """A model's input mapping with each yes/no given to a field that takes none a
    :class:`YesOrNo` (refused there by the field's own type); ``data`` itself where there is none."""
    numbers = _NO_YES_OR_NO.get(model)
    if numbers is None:
        numbers = _NO_YES_OR_NO[model] = frozenset(
            name for name, field in model.model_fields.items() if not _takes_yes_or_no(field.annotation)
        )
    changed = {key: marked for key in numbers & data.keys() if (marked := _marked(data[key])) is not data[key]}
    return {**data, **changed} if changed else data


class StrictModel(BaseModel):
    """A schema model that rejects unknown keys and suggests the closest valid one."""

    # allow_inf_nan=False: every number of the language is finite (1e400 reads as inf).
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, defer_build=True)
    #: a whole document's model (a problem): a mapping none of whose keys it knows is another kind
    #: of file, refused without quoting it
    document_root: ClassVar[bool] = False

    @model_validator(mode="before")
    @classmethod
    def _reject_unknown_keys(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        allowed = list(cls.model_fields)
        if cls.document_root and data and not any(key in cls.model_fields for key in data):
            raise PydanticCustomError(
                "not_a_document",
                "not a bcad problem: none of its keys is one of {allowed}",
                {"allowed": ", ".join(allowed)},
            )
        for key in data:
            if key in cls.model_fields:
                continue
            close = difflib.get_close_matches(str(key), allowed, n=1, cutoff=0.6)
            hint = f"did you mean '{close[0]}'? " if close else ""
            if str(key).rstrip().endswith(")"):
                # normal(0, 0.05) inside {...} is split at its comma by YAML.
                hint = "a distribution such as normal(0, 0.05) inside a flow mapping {...} must be quoted; "
            raise PydanticCustomError(
                "unknown_key",
                "unknown key {shown}; {hint}expected one of: {allowed}",
                # the key as the file has it (a number too), for its place in the file
                {"key": key, "shown": quoted(key), "hint": hint, "allowed": ", ".join(allowed)},
            )
        return yes_or_no_marked(cls, data)
