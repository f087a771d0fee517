"""Reading YAML while remembering where every value came from.

Pydantic reports errors by *location* (a tuple of keys and indices such as
``("links", 3, "status")``); :class:`SourceDocument` maps such a location back
to the line and column of the YAML file, so every error can name
``FILE:LINE:COL``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from bcad.errors import InputError

Location = tuple[str | int, ...]


@dataclass(frozen=True)
class Mark:
    """A 1-based line and column in a source file."""

    line: int
    column: int


@dataclass
class SourceDocument:
    """Parsed YAML data with the position of every key and value."""

    path: Path
    data: Any
    value_marks: dict[Location, Mark] = field(default_factory=dict)
    key_marks: dict[Location, Mark] = field(default_factory=dict)

    def mark(self, loc: Location, *, key: bool = False) -> Mark:
        """Position of ``loc``, or of its longest known prefix.

        With ``key=True`` the position of the mapping key itself is preferred
        (what an "unknown key" error should point at).
        """
        loc = tuple(loc)
        for end in range(len(loc), -1, -1):
            prefix = loc[:end]
            if key and prefix in self.key_marks:
                return self.key_marks[prefix]
            if prefix in self.value_marks:
                return self.value_marks[prefix]
        return Mark(1, 1)

    def error(self, loc: Location, message: str, *, key: bool = False) -> InputError:
        """An :class:`InputError` pointing at ``loc``."""
        mark = self.mark(loc, key=key)
        return InputError(self.path, message, mark.line, mark.column)

    def relative_path(self, text: str) -> Path:
        """A path written in this file, resolved against the file's folder."""
        candidate = Path(text).expanduser()
        return candidate if candidate.is_absolute() else self.path.parent / candidate


def _mark(node: yaml.Node) -> Mark:
    return Mark(node.start_mark.line + 1, node.start_mark.column + 1)


def _record_positions(
    loader: yaml.SafeLoader, node: yaml.Node, loc: Location, doc: SourceDocument
) -> None:
    """Walk the composed node tree, recording marks and rejecting duplicate keys."""
    doc.value_marks[loc] = _mark(node)
    if isinstance(node, yaml.MappingNode):
        seen: set[Any] = set()
        for key_node, value_node in node.value:
            key = loader.construct_object(key_node, deep=True)
            if not isinstance(key, (str, int, float, bool)):
                raise doc.error(loc, "mapping keys must be plain scalars")
            if key in seen:
                mark = _mark(key_node)
                raise InputError(
                    doc.path,
                    f"duplicate key '{key}': each key may appear once in a mapping",
                    mark.line,
                    mark.column,
                )
            seen.add(key)
            doc.key_marks[loc + (key,)] = _mark(key_node)
            _record_positions(loader, value_node, loc + (key,), doc)
    elif isinstance(node, yaml.SequenceNode):
        for index, item in enumerate(node.value):
            _record_positions(loader, item, loc + (index,), doc)


def load_yaml(path: Path | str) -> SourceDocument:
    """Read a YAML file into a :class:`SourceDocument`.

    Raises :class:`InputError` for a missing or unreadable file, a syntax error
    (with the parser's line and column), an empty file, or duplicate keys.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except IsADirectoryError:
        raise InputError(path, "is a folder, expected a YAML problem file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path, f"cannot read the file: {exc}") from None

    loader = yaml.SafeLoader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            raise InputError(path, "the file is empty; expected a YAML mapping describing a problem", 1, 1)
        doc = SourceDocument(path=path, data=None)
        _record_positions(loader, node, (), doc)
        doc.data = loader.construct_document(node)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        problem = exc.problem or "invalid YAML"
        context = f" ({exc.context})" if exc.context else ""
        raise InputError(
            path,
            f"YAML syntax error: {problem}{context}",
            mark.line + 1 if mark else None,
            mark.column + 1 if mark else None,
        ) from None
    except yaml.YAMLError as exc:
        raise InputError(path, f"YAML error: {exc}") from None
    finally:
        loader.dispose()
    return doc
