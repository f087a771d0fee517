"""The base of every schema model: strict keys with a helpful "did you mean"."""

from __future__ import annotations

import difflib
from typing import Any

from pydantic import BaseModel, ConfigDict, model_validator
from pydantic_core import PydanticCustomError


class StrictModel(BaseModel):
    """A schema model that rejects unknown keys and suggests the closest valid one."""

    # allow_inf_nan=False: every number of the language is finite (1e400 reads as inf).
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, defer_build=True)

    @model_validator(mode="before")
    @classmethod
    def _reject_unknown_keys(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        allowed = list(cls.model_fields)
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
                "unknown key '{key}'; {hint}expected one of: {allowed}",
                {"key": str(key), "hint": hint, "allowed": ", ".join(allowed)},
            )
        return data
