"""Reading YAML while remembering where every value came from.

Pydantic reports errors by *location* (a tuple of keys and indices such as
``("links", 3, "status")``); :class:`SourceDocument` maps such a location back
to the line and column of the YAML file, so every error can name
``FILE:LINE:COL``.
"""

from __future__ import annotations

import contextvars
import math
import os
import re
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from bcad.errors import NUL_IN_PATH, InputError, acted_on, printable, refuse_nul, shown, unprintable
from bcad.io import record_input

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
        """A path written in this file, resolved against the file's folder; an input of the
        running command from then on (:func:`record_input`), read or not."""
        candidate = Path(text).expanduser()
        path = candidate if candidate.is_absolute() else self.path.parent / candidate
        record_input(path)
        return path

    def named_file(self, loc: Location, text: str, what: str, called: str = "") -> Path:
        """The file this one names at ``loc`` (:meth:`relative_path`); where it is not a regular
        file to read (:func:`file_trouble`), an :class:`InputError` at that key: "CALLED 'TEXT'
        not found (...)", or "'TEXT' is a folder; expected WHAT" and the like.

        Args:
            loc: the key that names the file.
            text: the path as written.
            what: what the file should be ("a URDF file").
            called: the missing file's name in words, with a trailing space ("URDF file ").
        """
        path = self.relative_path(text)
        trouble = file_trouble(path)
        if trouble == "not found":
            raise self.error(loc, f"{called}'{path_shown(text)}' not found (paths are relative to the problem file)")
        if trouble is not None:
            raise self.error(loc, f"'{path_shown(text)}' {trouble}; expected {what}")
        return path


def _mark(node: yaml.Node) -> Mark:
    return Mark(node.start_mark.line + 1, node.start_mark.column + 1)


def _error_at(path: Path, node: yaml.Node, message: str) -> InputError:
    """An input error located where ``node`` starts in ``path``."""
    mark = _mark(node)
    return InputError(path, message, mark.line, mark.column)


#: the largest problem file read (bytes), the most values its aliases may expand to, the deepest nesting
MAX_BYTES = 10_000_000
MAX_VALUES = 1_000_000
MAX_DEPTH = 100


#: libyaml's parser where PyYAML was built with it (its wheels are): 10-20 times faster than the
#: pure-Python one (a 260 kB file of 2000 links, 3.2 s), with the same nodes and marks
_SafeLoader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _Loader(_SafeLoader):
    """PyYAML's safe loader, whose scalar conversions fail with the node's position, and which reads
    numbers in exponent form without a dot or an exponent sign (1e5, 2.5e6) as YAML 1.2 does: YAML
    1.1 reads them as text, so ``posterior_samples: 1e5`` was refused as "not an integer". A name
    of that form is a number too, as in YAML 1.2: quote it ('1e5')."""

    path: Path

    def construct_object(self, node: yaml.Node, deep: bool = False) -> Any:
        try:
            return super().construct_object(node, deep)
        except (InputError, yaml.YAMLError):
            raise
        except (ValueError, TypeError, KeyError, OverflowError, AttributeError) as exc:
            message = f"cannot read the value {str(node.value)[:40]!r} as {node.tag.rsplit(':', 1)[-1]}: {exc}"
            raise _error_at(self.path, node, message) from None


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)[eE][-+]?[0-9]+$"),  # YAML 1.2's, with an exponent
    list("-+0123456789."),
)


def _check_expansion(path: Path, node: yaml.Node) -> None:
    """Refuse recursive aliases, nesting deeper than MAX_DEPTH and alias expansions beyond MAX_VALUES.

    Aliases share nodes, so the expanded size is counted once per node (memoised):
    an "alias bomb" of a few hundred bytes that expands to billions of values is
    caught without expanding it.
    """
    sizes: dict[int, int] = {}
    # Iterative depth-first walk: (node, depth, children visited?) on an explicit stack.
    stack: list[tuple[yaml.Node, int, bool]] = [(node, 1, False)]
    ancestors: set[int] = set()
    while stack:
        current, depth, done = stack.pop()
        key = id(current)
        children = []
        if isinstance(current, yaml.MappingNode):
            children = [child for pair in current.value for child in pair]
        elif isinstance(current, yaml.SequenceNode):
            children = list(current.value)
        if done:
            ancestors.discard(key)
            sizes[key] = 1 + sum(sizes[id(child)] for child in children)
            if sizes[key] > MAX_VALUES:
                raise _error_at(path, current, f"the aliases here expand to more than {MAX_VALUES:,} values")
            continue
        if key in sizes:
            continue
        if depth > MAX_DEPTH:
            raise _error_at(path, current, f"nested more than {MAX_DEPTH} levels deep")
        ancestors.add(key)
        stack.append((current, depth, True))
        for child in children:
            if id(child) in ancestors:
                raise _error_at(path, child, "a recursive alias (a value that contains itself)")
            if id(child) not in sizes:
                stack.append((child, depth + 1, False))


def _record_positions(
    loader: yaml.SafeLoader, node: yaml.Node, loc: Location, doc: SourceDocument, seen_nodes: set[int] | None = None
) -> None:
    """Walk the composed node tree, recording marks and rejecting duplicate keys.

    A node reached again through an alias is not walked again: locations inside
    it resolve to the alias's own position (the longest known prefix).
    """
    seen_nodes = set() if seen_nodes is None else seen_nodes
    doc.value_marks[loc] = _mark(node)
    if id(node) in seen_nodes:
        return
    seen_nodes.add(id(node))
    if isinstance(node, yaml.ScalarNode):
        _check_printable(doc, node, lines=True)
    elif isinstance(node, yaml.MappingNode):
        seen: set[Any] = set()
        for key_node, value_node in node.value:
            if isinstance(key_node, yaml.ScalarNode):
                _check_printable(doc, key_node, lines=False)
            key = loader.construct_object(key_node, deep=True)
            if not isinstance(key, (str, int, float, bool)):
                raise doc.error(loc, "mapping keys must be plain scalars")
            if key in seen:
                raise _error_at(doc.path, key_node, f"duplicate key '{key}': each key may appear once in a mapping")
            seen.add(key)
            doc.key_marks[loc + (key,)] = _mark(key_node)
            _record_positions(loader, value_node, loc + (key,), doc, seen_nodes)
    elif isinstance(node, yaml.SequenceNode):
        for index, item in enumerate(node.value):
            _record_positions(loader, item, loc + (index,), doc, seen_nodes)


def _check_printable(doc: SourceDocument, node: yaml.ScalarNode, lines: bool) -> None:
    """A scalar's text may hold no character that a terminal acts on rather than shows
    (:func:`bcad.errors.unprintable`), even written as an escape (``"\\x1b"``): its names and
    values are printed. ``lines``: a value may hold tabs and newlines (a description's lines; a
    name's are printed as escapes), a key may not."""
    character = unprintable(node.value, lines=lines)
    if character is not None:
        raise _error_at(doc.path, node, f"the text {acted_on(character)}; expected printable text")


#: the folder every file read must lie in, where a run is confined (:func:`confined`)
_CONFINEMENT: contextvars.ContextVar[Path | None] = contextvars.ContextVar("bcad_confinement", default=None)
#: the environment variable that confines every command of a process
CONFINE_VARIABLE = "BCAD_CONFINE"


@contextmanager
def confined(folder: Path | str | None):
    """Within the block, every file bcad reads (problems, URDFs and what a xacro file includes,
    measurement CSVs, results, calibration results, meshes) must lie in ``folder`` once links
    are resolved, and xacro files (whose ``${...}`` expressions are Python) are refused: for a
    service that runs problems others wrote. ``None``: no confinement (or the one of
    :data:`CONFINE_VARIABLE`, where set). Per thread and task (a context variable)."""
    if folder is None:
        yield
        return
    if not isinstance(folder, (str, Path)) or not str(folder).strip():
        raise InputError("confined", f"{shown(folder)} is given; expected a folder's path (str or pathlib.Path)")
    refuse_nul(folder)
    root = Path(os.path.realpath(folder))
    if not root.is_dir():
        raise InputError(folder, "the folder to confine reads to does not exist")
    token = _CONFINEMENT.set(root)
    try:
        yield
    finally:
        _CONFINEMENT.reset(token)


def confinement() -> Path | None:
    """The folder reads are confined to: :func:`confined`'s, else :data:`CONFINE_VARIABLE`'s."""
    folder = _CONFINEMENT.get()
    if folder is None and os.environ.get(CONFINE_VARIABLE):
        folder = Path(os.path.realpath(os.environ[CONFINE_VARIABLE]))
    return folder


def check_confined(path: Path, what: str) -> None:
    """Refuse a file outside the confinement (through any link), and a xacro file under one."""
    root = confinement()
    if root is None:
        return
    real = Path(os.path.realpath(path))
    if real != root and root not in real.parents:
        raise InputError(path, f"is outside {root}, the folder this run may read ({what} must lie there)")
    if real.suffix == ".xacro":
        raise InputError(
            path,
            "is a xacro file, which a confined run refuses (its ${...} expressions are Python): "
            "expand it to URDF first",
        )


@dataclass
class JsonDocument:
    """A parsed JSON file, whose messages name the position of the value they are about."""

    path: Path
    data: Any
    text: str

    def error(self, loc: Location, message: str) -> InputError:
        """An :class:`InputError` at the value ``loc`` names (keys and list indices from the top);
        where the file has no such value (a missing key), at the nearest one that holds it."""
        for depth in range(len(loc), 0, -1):
            try:
                found = json_position(self.text, loc[:depth])
            except RecursionError:  # a value beside the path nested as deep as json.loads allows
                break
            if found is not None:
                return InputError(self.path, message, *found)
        return InputError(self.path, message)


def json_position(text: str, loc: Location) -> tuple[int, int] | None:
    """The 1-based line and column where the value at ``loc`` starts in the JSON ``text`` (which
    json.loads accepts), or None where there is no such value. Only the path is walked: the values
    beside it are skipped by the decoder; of a key written twice, the last one counts, as
    json.loads keeps it."""
    import json
    from json.decoder import scanstring

    decoder = json.JSONDecoder()
    space = re.compile(r"[ \t\n\r]*")

    def skip(at: int) -> int:
        return space.match(text, at).end()

    at = skip(0)
    for step in loc:
        if text.startswith("{", at):
            at, found = skip(at + 1), None
            while not text.startswith("}", at):
                key, at = scanstring(text, at + 1)
                at = skip(skip(at) + 1)  # past the colon
                if key == step:
                    found = at
                at = skip(decoder.raw_decode(text, at)[1])
                at = skip(at + 1) if text.startswith(",", at) else at
        elif text.startswith("[", at) and isinstance(step, int) and not isinstance(step, bool):
            at, found, index = skip(at + 1), None, 0
            while not text.startswith("]", at):
                if index == step:
                    found = at
                    break
                at = skip(decoder.raw_decode(text, at)[1])
                at = skip(at + 1) if text.startswith(",", at) else at
                index += 1
        else:
            return None
        if found is None:
            return None
        at = found
    line = text.count("\n", 0, at) + 1
    return line, at - (text.rfind("\n", 0, at) + 1) + 1


def read_json(path: Path, what: str, kind: str) -> JsonDocument:
    """The parsed JSON of a file that :func:`read_text` accepts, or an :class:`InputError` saying
    what is wrong with it: not JSON (with its line and column), nested too deeply, or a number of
    more digits than Python converts.

    Args:
        path: the file.
        what: what the file should be, for read_text's messages ("a bcad result (JSON)").
        kind: what the file should be, for the messages here ("a bcad result").
    """
    import json

    text = read_text(path, what)
    try:
        return JsonDocument(path, json.loads(text), text)
    except json.JSONDecodeError as exc:
        raise InputError(path, f"not valid JSON: {exc.msg}", exc.lineno, exc.colno) from None
    except RecursionError:
        raise InputError(path, f"not {kind}: nested too deeply") from None
    except ValueError as exc:  # an integer of more digits than Python converts
        raise InputError(path, f"not {kind}: {exc}") from None


def file_trouble(path: Path) -> str | None:
    """Why ``path`` is not a regular file to read, in words that follow its name in a message
    ("not found", "is a folder", ...), or None where it is one. It never raises: a name too long
    for the file system or a folder one may not enter is a reason like the others."""
    import stat

    if "\x00" in str(path):
        return NUL_IN_PATH
    try:
        info = path.stat()
    except FileNotFoundError:
        return "not found"
    except OSError as exc:
        return f"cannot be read ({exc.strerror or exc})"
    if stat.S_ISDIR(info.st_mode):
        return "is a folder"
    if not stat.S_ISREG(info.st_mode):
        return "is not a regular file (a device, pipe or socket)"
    return None


def path_shown(path: Path | str, limit: int = 80) -> str:
    """A path as a message shows it: whole, or its first ``limit`` characters and an ellipsis."""
    text = str(path)
    return text if len(text) <= limit else text[:limit] + "…"


def read_text(path: Path, what: str = "a YAML problem file") -> str:
    """The text of a regular file of at most MAX_BYTES, or an :class:`InputError`.

    The file is recorded as an input (:func:`record_input`): no result may replace it. Under
    :func:`confined`, a file outside the folder is refused.
    """
    import stat

    refuse_nul(path)
    check_confined(path, what)

    try:
        info = path.stat()
    except FileNotFoundError:
        if "\n" in str(path) and ":" in str(path):  # a problem's text given where its path goes
            raise InputError(
                path_shown(printable(str(path))),
                f"no such file: a text of {len(str(path).splitlines())} lines, which looks like YAML, not a path; "
                "expected a file's path (from Python, or the mapping yaml.safe_load(text) gives)",
            ) from None
        raise InputError(path, "no such file") from None
    except OSError as exc:
        raise InputError(path, f"cannot read the file: {exc.strerror or exc}") from None
    if stat.S_ISDIR(info.st_mode):
        raise InputError(path, f"is a folder, expected {what}")
    if not stat.S_ISREG(info.st_mode):
        raise InputError(path, f"is not a regular file (a device, pipe or socket), expected {what}")
    if info.st_size > MAX_BYTES:
        raise InputError(path, f"is {info.st_size:,} bytes; problem files are limited to {MAX_BYTES:,} bytes")
    try:
        with open(path, "rb") as stream:
            data = stream.read(MAX_BYTES + 1)
    except OSError as exc:
        raise InputError(path, f"cannot read the file: {exc.strerror or exc}") from None
    if len(data) > MAX_BYTES:
        raise InputError(path, f"is larger than {MAX_BYTES:,} bytes, the limit of a problem file")
    record_input(path, info)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise InputError(
            path, f"not UTF-8 text: byte 0x{data[exc.start]:02x} cannot be decoded", line, column
        ) from None


def _character_at(text: str, mark) -> str:
    """The character of ``text`` at a parser's mark (0-based line and column), or ''."""
    lines = text.split("\n", mark.line + 1)
    return lines[mark.line][mark.column : mark.column + 1] if mark.line < len(lines) else ""


def load_yaml(path: Path | str) -> SourceDocument:
    """Read a YAML file into a :class:`SourceDocument`.

    Raises :class:`InputError` for a missing, unreadable, non-regular or too large
    file, a syntax error (with the parser's line and column), an empty file,
    duplicate keys, recursive or exploding aliases, too deep nesting, or a value
    that its tag cannot convert.
    """
    path = Path(path)
    return load_yaml_text(path, read_text(path))


#: the parser's contexts of a bracket or quote left open, whose start a syntax error names
UNCLOSED_CONTEXTS = ("while parsing a flow mapping", "while parsing a flow sequence", "while scanning a quoted scalar")


def load_yaml_text(path: Path, text: str) -> SourceDocument:
    """:func:`load_yaml` of a file's text already read (and maybe adapted: an OpenCV
    FileStorage file's directive and tags)."""
    loader = None
    try:
        loader = _Loader(text)
        loader.path = path
        node = loader.get_single_node()
        if node is None:
            raise InputError(path, "the file is empty; expected a YAML mapping describing a problem", 1, 1)
        _check_expansion(path, node)
        doc = SourceDocument(path=path, data=None)
        _record_positions(loader, node, (), doc)
        doc.data = loader.construct_document(node)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        problem = exc.problem or "invalid YAML"
        context = f" ({exc.context})" if exc.context else ""
        opened = exc.context_mark
        if exc.context in UNCLOSED_CONTEXTS and opened is not None and mark is not None and opened.line != mark.line:
            # an unclosed bracket or quote is seen lines later (at the end of the file): say where it opened
            context = f" ({exc.context} opened at line {opened.line + 1}, column {opened.column + 1})"
        if exc.context == "while parsing a flow mapping" and mark and _character_at(text, mark) == "[":
            # reference: plate.edge[0] inside {...}: a bracket there opens a list
            context += "; inside a flow mapping {...}, a value with brackets must be quoted: reference: 'plate.edge[0]'"
        raise InputError(
            path,
            f"YAML syntax error: {problem}{context}",
            mark.line + 1 if mark else None,
            mark.column + 1 if mark else None,
        ) from None
    except yaml.reader.ReaderError as exc:
        line = text.count("\n", 0, exc.position) + 1
        column = exc.position - (text.rfind("\n", 0, exc.position) + 1) + 1
        code = ord(exc.character) if isinstance(exc.character, str) else int(exc.character)
        raise InputError(
            path, f"YAML error: the control character U+{code:04X} is not allowed in YAML text", line, column
        ) from None
    except yaml.YAMLError as exc:
        raise InputError(path, f"YAML error: {exc}") from None
    except RecursionError:
        raise InputError(path, f"nested too deeply for the YAML parser (at most {MAX_DEPTH} levels)") from None
    finally:
        if loader is not None:
            loader.dispose()
    return doc


def mapping_document(data: dict) -> SourceDocument:
    """A problem given as a mapping (the keys of a file), as :func:`load_yaml` gives a file's:
    refused where it is not plain data as a file gives it (:func:`not_plain_data`)."""
    why = not_plain_data(data)
    if why:  # a set's order is not the user's, a tuple or an object is nothing a file can say
        raise InputError("<dict>", f"the problem {why}")
    return SourceDocument(path=Path("<dict>"), data=data)


def not_plain_data(item: Any, max_depth: int = MAX_DEPTH, max_values: int = MAX_VALUES) -> str | None:
    """Why ``item`` is not plain data as a YAML file gives it (mappings with string keys, lists,
    strings, finite numbers, booleans, null): a set, a tuple, bytes, a date, an object, a
    non-finite number, nesting deeper than ``max_depth`` (or containing itself), more than
    ``max_values`` values, a text with a character a terminal acts on (as a file's scalars: a key
    holds no tab or newline, a value may); None where it is plain. Checked iteratively: no
    recursion limit."""
    count = 0
    stack = [(item, 0)]
    while stack:
        node, depth = stack.pop()
        count += 1
        if depth > max_depth:
            return f"is nested more than {max_depth} deep (or contains itself)"
        if count > max_values:
            return f"holds more than {max_values} values"
        if isinstance(node, str):
            character = unprintable(node, lines=True)
            if character is not None:
                return f"has a text that {acted_on(character)}; expected printable text"
            continue
        if node is None or isinstance(node, (bool, int)):
            continue
        if isinstance(node, float):
            if not math.isfinite(node):
                return "holds a number that is not finite"
        elif isinstance(node, list):
            stack.extend((child, depth + 1) for child in node)
        elif isinstance(node, dict):
            if not all(isinstance(key, str) for key in node):
                return "has a key that is not a word"
            character = next((c for c in map(unprintable, node) if c is not None), None)
            if character is not None:
                return f"has a key that {acted_on(character)}; expected printable text"
            stack.extend((child, depth + 1) for child in node.values())
        else:
            return (
                f"holds a {type(node).__name__}, not plain data (mappings, lists, strings, numbers, true/false, null)"
            )
    return None
