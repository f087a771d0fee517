"""Validating a parsed YAML document against a schema, with errors at their file position."""

from __future__ import annotations

import types
import typing
from typing import Any

from pydantic import BaseModel, ValidationError

from bcad.errors import counted, listed, shown
from bcad.model.base import StrictModel, YesOrNo
from bcad.model.source import Location, SourceDocument


def _resolve_location(doc: SourceDocument, loc: tuple[Any, ...]) -> Location:
    """Drop the parts of a pydantic location that are not in the file (union tags)."""
    path: Location = ()
    for part in loc:
        if path + (part,) in doc.value_marks:
            path = path + (part,)
    return path


def _describe(loc: Location) -> str:
    text = ""
    for part in loc:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text


#: errors that only say the input is not of a union member's type
UNION_MISMATCH = {"model_type", "dict_type", "list_type", "model_attributes_type"}


#: pydantic's bound constraints in words
BOUND_WORDS = {
    "gt": "greater than",
    "ge": "greater than or equal to",
    "lt": "less than",
    "le": "less than or equal to",
}


#: pydantic's errors for an input that is not a whole number (or one too large to parse)
INTEGER_ERRORS = {"int_parsing_size", "int_from_float", "int_parsing", "int_type"}


def _unwrapped(annotation: Any) -> tuple[Any, list]:
    """An annotation without its ``Annotated`` wrapper (whose metadata is returned beside it) or
    its ``| None``."""
    metadata: list = []
    while True:
        origin = typing.get_origin(annotation)
        if origin is typing.Annotated:
            annotation, *extra = typing.get_args(annotation)
            metadata.extend(extra)
        elif origin in (typing.Union, types.UnionType):
            members = [a for a in typing.get_args(annotation) if a is not type(None)]
            if len(members) != 1:
                return annotation, metadata
            annotation = members[0]
        else:
            return annotation, metadata


def _annotation_at(model: type[BaseModel], loc: tuple[Any, ...]) -> tuple[Any, list] | None:
    """The annotation the input at ``loc`` should have (without ``Annotated`` or ``| None``) and the
    metadata of its constraints, following the location's field names through nested models,
    list and tuple items and mapping values; None where it leads elsewhere (a union of models)."""
    current: Any = model
    metadata: list = []
    for part in loc:
        origin, args = typing.get_origin(current), typing.get_args(current)
        if isinstance(part, int) and origin in (list, tuple) and args:
            fixed_tuple = origin is tuple and Ellipsis not in args
            if fixed_tuple and part >= len(args):
                return None
            current, metadata = _unwrapped(args[part] if fixed_tuple else args[0])
        elif origin is dict and len(args) == 2:
            current, metadata = _unwrapped(args[1])
        elif isinstance(current, type) and issubclass(current, BaseModel) and part in current.model_fields:
            info = current.model_fields[part]
            current, metadata = _unwrapped(info.annotation)
            metadata = list(info.metadata) + metadata
        else:
            return None
    return current, metadata


def _field_range(model: type[BaseModel], loc: tuple[Any, ...]) -> tuple[Any, Any] | None:
    """The (>=, <=) bounds of the integer at ``loc`` (either None where it has none; a list item's
    own bounds), None where the location leads to no integer (:func:`_annotation_at`)."""
    found = _annotation_at(model, loc)
    if found is None or found[0] is not int:
        return None
    constraints = [c for item in found[1] for c in getattr(item, "metadata", [item])]
    # pydantic's Field(ge=..., le=...) keeps annotated_types' Ge and Le, which name their bound so
    low = next((c.ge for c in constraints if getattr(c, "ge", None) is not None), None)
    high = next((c.le for c in constraints if getattr(c, "le", None) is not None), None)
    return low, high


def _model_at(model: type[BaseModel], loc: tuple[Any, ...]) -> type[BaseModel] | None:
    """The model class the input at ``loc`` should be (:func:`_annotation_at`), or None."""
    found = _annotation_at(model, loc)
    current = found[0] if found is not None else None
    return current if isinstance(current, type) and issubclass(current, BaseModel) else None


def problem_error_from_validation(doc: SourceDocument, model: type[StrictModel]):
    """Validate ``doc.data`` against ``model``; the first error names its file position."""
    try:
        return model.model_validate(doc.data)
    except ValidationError as exc:
        errors = exc.errors()
        error = errors[0]
        if error["type"] in UNION_MISMATCH and len(errors) > 1:
            # A union (one mapping or a list of them, say) whose first member is not the input's
            # shape: the member that is says what is wrong inside it.
            error = max(errors[1:], key=lambda e: len(e["loc"]))
        elif error["type"] == "float_parsing" and isinstance(error["input"], str) and "(" in error["input"]:
            # a number or a distribution: a shorthand such as normal(1100, -50) is no number, and
            # the distribution's own error (its std) says what is wrong with it
            field = tuple(error["loc"][:-1])
            inside = [
                e
                for e in errors[1:]
                if tuple(e["loc"][: len(field)]) == field
                and len(e["loc"]) > len(field)
                and e["type"] != "float_parsing"
            ]
            error = max(inside, key=lambda e: len(e["loc"])) if inside else error
        loc = _resolve_location(doc, error["loc"])
        is_key = error["type"] == "unknown_key"
        if is_key:
            loc = loc + (error["ctx"]["key"],)
        message = error["msg"].removeprefix("Value error, ")
        bound = next(((key, value) for key, value in error.get("ctx", {}).items() if key in BOUND_WORDS), None)
        if bound is not None and isinstance(bound[1], (int, float)):
            # pydantic writes the bound out in full (1e-12 as 0.000000000001)
            message = f"Input should be {BOUND_WORDS[bound[0]]} {bound[1]:g}"
        if error["type"] in INTEGER_ERRORS:
            # pydantic's words differ by case (a fraction, too large to read, not a number): the
            # value given and the field's range instead
            bounds = _field_range(model, tuple(error["loc"]))
            low, high = bounds if bounds is not None else (None, None)
            expected = "a whole number"
            if low is not None and high is not None:
                expected += f" in [{low:g}, {high:g}]"
            elif low is not None:
                expected += f" >= {low:g}"
            elif high is not None:
                expected += f" <= {high:g}"
            message = f"got {shown(error['input'], 40)}; expected {expected}"
        elif error["type"] in {"model_type", "model_attributes_type"}:
            # pydantic names the class ("a valid dictionary or instance of ConfigurationJoint"):
            # the keys the mapping may have instead
            expected = _model_at(model, tuple(error["loc"]))
            names = [info.alias or name for name, info in expected.model_fields.items()] if expected else []
            keys = f" with keys among {listed(names, 10)}" if names else ""
            message = f"got {shown(error['input'], 40)}; expected a mapping{keys}"
        elif isinstance(error["input"], YesOrNo) and "number" in message:
            # a YAML true or false where the field takes a number: not read as 1 or 0
            message = f"got {error['input']!r}; expected a number"
        elif isinstance(error["input"], YesOrNo):
            # YAML 1.1 reads an unquoted yes, no, on and off as true and false too: a name `no`
            message = (
                f"got {error['input']!r} (YAML reads an unquoted yes, no, on or off so); expected a text: quote it"
            )
        # The innermost field name, when the file has no node for it (a missing key, say).
        # (pydantic names a union's member in the location, 'function-after[...]' or
        # 'list[Clearance]': no name of the user's, so skipped)
        field = next((part for part in reversed(error["loc"]) if isinstance(part, str) and part.isidentifier()), None)
        short = error["type"] == "missing" and bool(error["loc"]) and isinstance(error["loc"][-1], int)
        if short:
            # a tuple's item (a bound's high): the list is short, no key is missing
            count = len(error["input"]) if isinstance(error["input"], (list, tuple)) else 1
            message = f"got {counted(count, 'item')}; expected {error['loc'][-1] + 1} or more ([low, high] for bounds)"
            if len(error["loc"]) >= 2 and isinstance(error["loc"][-2], str):
                loc = _resolve_location(doc, error["loc"][:-1])
        if error["type"] == "missing" and not short:
            message = f"missing key '{field}'"
        elif not is_key and field is not None and field not in loc:
            message = f"{field}: {message}"
        if (
            error["type"] in {"too_short", "too_long"}
            and isinstance(error["input"], (list, dict))
            and len(error["input"]) > 8
        ):
            pass  # pydantic's message counts a long list's items; it is not quoted
        elif error["type"] in {
            "greater_than",
            "less_than",
            "greater_than_equal",
            "less_than_equal",
            "finite_number",
            "float_parsing",
            "too_short",
            "too_long",
            "literal_error",
            "enum",
        }:
            message += f" (got {shown(error['input'], 200)})"
        if error["type"] == "string_type" and isinstance(error["input"], float):
            # 2e3 reads as a number (YAML 1.2's exponent form), 1.5 too
            message += f" (got the number {shown(error['input'], 40)}); quote a name that reads as a number, e.g. '2e3'"
        if (
            error["type"] in {"too_short", "too_long"}
            and isinstance(error["input"], list)
            and any(isinstance(item, str) and item.count("(") != item.count(")") for item in error["input"])
        ):
            # [normal(1, 0.1), 2] is split at the distribution's comma by YAML
            message += "; inside a flow sequence [...], quote a distribution that has commas, e.g. 'normal(1, 0.1)'"
        # (an unknown key is in the message, cut to a few characters: the location names its parent)
        where = _describe(loc[:-1] if is_key else loc)
        raise doc.error(loc, f"{where}: {message}" if where else message, key=is_key) from None
