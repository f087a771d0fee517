"""Writing results: JSON, atomically, never over a problem file."""

from __future__ import annotations

import json
import os
from pathlib import Path

from bcad.errors import InputError


def json_text(document: dict) -> str:
    return json.dumps(document, indent=2) + "\n"


def write_json_atomic(document: dict, path: Path, protected: Path | None = None) -> None:
    """Write to a temporary file beside ``path``, then rename: readers never see half a file."""
    if protected is not None and path.exists() and path.resolve() == protected.resolve():
        raise InputError(path, "refusing to overwrite the problem file with a result; choose another output")
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        temporary.write_text(json_text(document), encoding="utf-8")
        os.replace(temporary, path)
    except OSError as exc:
        temporary.unlink(missing_ok=True)
        raise InputError(path, f"cannot write the result: {exc.strerror or exc}") from None
