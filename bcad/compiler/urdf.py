"""A reader for the kinematic subset of URDF: links, and joints with their
origin, axis and limits.

bcad reads URDF with lxml directly rather than through yourdfpy: importing
yourdfpy (and trimesh behind it) costs 0.66 s, a third of the start-up budget
of ``bcad posterior``, and only the kinematic elements are needed. The tests
check this reader against yourdfpy and the resulting kinematics against
Pinocchio. Errors name the URDF file and line.
"""

from __future__ import annotations

import bisect
import math
import os
import re
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bcad.errors import InputError, acted_on, install_hint, quoted, unprintable
from bcad.kinematics.se3 import pose_to_matrix
from bcad.model.pose import LIMIT


@dataclass(frozen=True)
class UrdfJoint:
    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray  # 4x4, metres
    xyz: tuple[float, float, float]  # the origin as written: metres
    rpy: tuple[float, float, float]  # and radians
    axis: np.ndarray  # unit vector in the joint frame
    lower: float | None
    upper: float | None
    line: int  # where its <joint> starts, 1-based
    column: int
    #: <mimic joint multiplier offset>: q = multiplier * q_master + offset (offset in URDF units)
    mimic: tuple[str, float, float] | None = None


@dataclass(frozen=True)
class UrdfRobot:
    name: str
    links: list[str]
    joints: list[UrdfJoint]
    path: Path
    #: where each <link> and the <robot> element start: (line, column), 1-based
    link_places: dict[str, tuple[int, int]] = field(default_factory=dict)
    place: tuple[int, int] = (1, 1)

    def root(self) -> str:
        """The root link (the one that is no joint's child), or an :class:`InputError` at a
        second root's <link>, or at the first <joint> of a cycle where every link is a child."""
        children = {joint.child for joint in self.joints}
        roots = [link for link in self.links if link not in children]
        if len(roots) > 1:
            raise InputError(
                self.path,
                f"link {quoted(roots[1])} is no joint's child, nor is {quoted(roots[0])}: a URDF needs "
                "exactly one root link (add the joint that holds one of them)",
                *self.link_places.get(roots[1], self.place),
            )
        if roots:
            return roots[0]
        if not self.links:
            raise InputError(self.path, "not a valid URDF: it declares no <link>", *self.place)
        by_child = {joint.child: joint for joint in self.joints}
        walk, link = [], self.links[0]
        while by_child[link] not in walk:  # every link has a parent joint: the walk comes round
            walk.append(by_child[link])
            link = by_child[link].parent
        cycle = walk[walk.index(by_child[link]) :][::-1]  # from parent to child
        first = min(cycle, key=lambda joint: (joint.line, joint.column))
        cycle = cycle[cycle.index(first) :] + cycle[: cycle.index(first)]
        names = ", ".join(quoted(joint.name) for joint in cycle[:5]) + (", ..." if len(cycle) > 5 else "")
        raise InputError(
            self.path,
            f"the joints {names} form a cycle, so every link is a joint's child; a URDF needs exactly "
            "one root link (a tree of joints)",
            first.line,
            first.column,
        )


#: an attribute of a start tag: its name (group 1) and its quoted value
_ATTRIBUTE = re.compile(r"""\s*([^\s=/>]+)\s*=\s*(?:"[^"]*"|'[^']*')""")
#: a start tag: its name (group 1), its attributes
_START_TAG = re.compile(rf"<([\w.-]+)(?:{_ATTRIBUTE.pattern})*\s*/?>")


#: libxml2's complaints that quote a name from the file, and what they say without it
_QUOTED_NAMES = (
    (re.compile(r"(mismatch):.*$"), r"\1"),
    (re.compile(r"(in tag|Start Tag|for attribute)\s+\S+.*$"), r"\1"),
    (re.compile(r"Attribute \S+ redefined.*$"), "an attribute redefined"),
    (re.compile(r"Entity '[^']*'"), "an entity"),
    (re.compile(r"\s+line \d+.*$"), ""),
)


def xml_complaint(message: str) -> str:
    """libxml2's complaint without the names it quotes from the file ("Opening and ending tag
    mismatch: NAME line 1 and OTHER", "Premature end of data in tag NAME"): a file that is not XML
    of the kind expected is not shown; the line and column say where."""
    for pattern, replacement in _QUOTED_NAMES:
        message = pattern.sub(replacement, message)
    return message.strip(" ,;") or "not well-formed XML"


class UrdfText:
    """A URDF's text, parsed, and where its elements and attributes are: lxml gives an
    element's line only (the line where its start tag ends), so messages find the start tag on
    that line and, in it, the attribute at fault (:meth:`place`)."""

    def __init__(self, path: Path, text: str):
        self.path, self.text = path, text
        self._line_ends: list[int] | None = None
        #: built at the first :meth:`place`, in one pass each (a call per element stays linear): the
        #: start tags' offsets by (name, line where the start tag ends), and each element's rank
        #: among the elements of its name on its line
        self._tags: dict[tuple[str, int], list[int]] | None = None
        self._ranks: dict | None = None

    def parse(self, keep_comments: bool = False):
        """The root element, or an :class:`InputError` at lxml's line and column. Entities are
        never resolved, nothing is fetched from the network."""
        from lxml import etree  # here: a DH chain or a problem without robots never loads lxml

        parser = etree.XMLParser(remove_comments=not keep_comments, resolve_entities=False, no_network=True)
        try:
            return etree.fromstring(self.text.encode("utf-8"), parser)
        except etree.XMLSyntaxError as exc:
            line, column = exc.position if exc.position else (None, None)
            raise InputError(self.path, f"cannot parse the URDF: {xml_complaint(exc.msg)}", line, column) from None

    def _line_of(self, offset: int) -> int:
        if self._line_ends is None:
            self._line_ends = [match.start() for match in re.finditer("\n", self.text)]
        return bisect.bisect_left(self._line_ends, offset) + 1

    def _at(self, offset: int) -> tuple[int, int]:
        return self._line_of(offset), offset - self.text.rfind("\n", 0, offset)

    def place(self, element, attribute: str | None = None) -> tuple[int, int]:
        """(line, column), 1-based, of ``attribute`` in ``element``'s start tag, or of the start
        tag where it has no such attribute; the element's line and column 1 where its start tag
        is not found in the text (an element a xacro expansion wrote, say)."""
        line = element.sourceline or 1
        tag = element.tag
        if not isinstance(tag, str) or not re.fullmatch(r"[\w.-]+", tag):
            return line, 1
        if self._tags is None or self._ranks is None:
            self._tags, self._ranks, counts = {}, {}, {}
            for match in _START_TAG.finditer(self.text):
                self._tags.setdefault((match.group(1), self._line_of(match.end() - 1)), []).append(match.start())
            for other in element.getroottree().iter():
                if isinstance(other.tag, str):
                    key = (other.tag, other.sourceline)
                    self._ranks[other] = counts.get(key, 0)
                    counts[key] = self._ranks[other] + 1
        # the start tags of this name that end on this line, and this element's rank among its kind there
        tags = self._tags.get((tag, line), [])
        rank = self._ranks.get(element, 0)
        if rank >= len(tags):
            return line, 1
        start = _START_TAG.match(self.text, tags[rank])
        if attribute is not None:
            for match in _ATTRIBUTE.finditer(start.group(), len(tag) + 1):
                if match.group(1) == attribute:
                    return self._at(start.start() + match.start(1))
        return self._at(start.start())

    def error(self, element, message: str, attribute: str | None = None) -> InputError:
        """An :class:`InputError` at ``element`` (or its ``attribute``: :meth:`place`)."""
        return InputError(self.path, message, *self.place(element, attribute))


def _shown(text: str) -> str:
    """An attribute's value as a message shows it between its quotes: cut, escapes for what a
    terminal would act on (:func:`bcad.errors.quoted`)."""
    return quoted(text, 40)[1:-1]


def _number(element, attribute: str, default: str, source: UrdfText) -> float:
    return attribute_floats(element, attribute, default, source, count=1)[0]


def attribute_floats(element, attribute: str, default: str, source: UrdfText, count: int = 3) -> list[float]:
    """``count`` finite, bounded numbers from an XML attribute, or an InputError at it."""
    text = element.get(attribute, default) if element is not None else default
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        values = []
    shown = f'<{element.tag} {attribute}="{_shown(text)}">' if element is not None else ""
    if len(values) != count:
        raise source.error(element, f"{shown} needs {count} numbers", attribute)
    if not all(math.isfinite(v) and abs(v) <= LIMIT for v in values):
        raise source.error(element, f"{shown}: every number must be finite and at most {LIMIT:g} in size", attribute)
    return values


#: the largest URDF a xacro file may expand to (the size of a URDF file bcad reads)
MAX_EXPANDED = 10_000_000


@contextmanager
def _xacro_reads_bounded(path: Path):
    """While a xacro file expands: its includes resolve against its own folder (xacro's
    file stack, which xacrodoc leaves empty, so they would resolve against the working
    folder), every file it includes or loads is read as bcad reads a problem (a regular
    file of bounded size, never /dev/zero or a pipe) and recorded as an input."""
    import xacro

    from bcad.model.source import read_text

    parse, load_yaml = xacro.parse, xacro.load_yaml

    def bounded_parse(inp, filename=None):
        if inp is None and filename is not None:
            inp = read_text(Path(os.path.join(xacro.root_dir, filename)), "a file that a xacro file includes")
        return parse(inp, filename)

    def bounded_load_yaml(filename):
        read_text(Path(xacro.abs_filename_spec(filename)), "a YAML file that a xacro file loads")
        return load_yaml(filename)

    xacro.parse, xacro.load_yaml = bounded_parse, bounded_load_yaml
    xacro.init_stacks(str(path))
    try:
        yield
    finally:
        xacro.parse, xacro.load_yaml = parse, load_yaml
        xacro.filestack = None


#: a xacro expansion's limits: its ${...} are Python (10**10**8 runs for hours, a macro that
#: doubles 26 times fills the memory), so it runs in a child process bounded in both
XACRO_SECONDS = 30
XACRO_MEMORY = 2 << 30


def urdf_text(path: Path, xacro_args: dict[str, str] | None = None) -> str:
    """The URDF text of ``path``: the file itself, or a ``.xacro`` file expanded by xacrodoc
    (the optional extra ``bcad[xacro]``) with ``xacro_args``, in a child process of at most
    XACRO_SECONDS and XACRO_MEMORY bytes (:func:`expand_in_child`)."""
    from bcad.model.source import read_text

    # read_text: a regular file of bounded size (never /dev/zero or a pipe), UTF-8.
    text = read_text(path, "a URDF or xacro file")
    if path.suffix != ".xacro":
        return text
    import importlib.util

    if importlib.util.find_spec("xacrodoc") is None:
        raise InputError(
            path,
            f"a xacro file needs xacrodoc: {install_hint('xacro')}, or expand it to URDF first",
        )
    import json
    import subprocess
    import sys

    from bcad.io import record_input

    request = json.dumps({"path": str(path), "args": dict(xacro_args or {})})
    try:
        run = subprocess.run(
            [sys.executable, "-c", "from bcad.compiler.urdf import expand_in_child; expand_in_child()"],
            input=request,
            capture_output=True,
            text=True,
            timeout=XACRO_SECONDS,
        )
    except subprocess.TimeoutExpired:
        raise InputError(
            path,
            f"the xacro file did not expand within {XACRO_SECONDS} s (its ${{...}} expressions or "
            "macros grow without bound?); expand it to URDF yourself",
        ) from None
    try:
        answer = json.loads(run.stdout)
    except json.JSONDecodeError:
        why = "ran out of its memory" if run.returncode != 0 else "gave no answer"
        raise InputError(
            path,
            f"cannot expand the xacro file: the expansion {why} (at most {XACRO_MEMORY >> 30} GiB); "
            "expand it to URDF yourself",
        ) from None
    for read in answer.get("read", []):
        record_input(read)  # what it included: no output may replace it
    if "error" in answer:
        error = answer["error"]
        raise InputError(error["file"], error["message"], error.get("line"), error.get("column"))
    return answer["urdf"]


def expand_in_child() -> None:
    """The child process of :func:`urdf_text`: expands the xacro file of the JSON request on
    stdin, within XACRO_MEMORY bytes, and writes {"urdf", "read"} or {"error", "read"} as JSON."""
    import json
    import sys

    try:
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (XACRO_MEMORY, XACRO_MEMORY))
    except (ImportError, ValueError, OSError):
        pass  # no such limit here (Windows): the time limit still holds
    from bcad.io import recording_inputs

    request = json.loads(sys.stdin.read())
    path = Path(request["path"])
    with recording_inputs() as read:
        try:
            answer = {"urdf": _expanded(path, request["args"])}
        except InputError as exc:
            answer = {"error": {"file": str(exc.file), "message": exc.message, "line": exc.line, "column": exc.column}}
        except MemoryError:
            answer = {
                "error": {
                    "file": str(path),
                    "message": "cannot expand the xacro file: it needs more than "
                    f"{XACRO_MEMORY >> 30} GiB; expand it to URDF yourself",
                }
            }
    answer["read"] = [str(p) for p in read.values()]
    sys.stdout.write(json.dumps(answer))


def _expanded(path: Path, xacro_args: dict[str, str]) -> str:
    """A xacro file expanded by xacrodoc, its reads bounded (:func:`_xacro_reads_bounded`)."""
    from xacrodoc import XacroDoc

    try:
        with _xacro_reads_bounded(path):
            expanded = XacroDoc.from_file(str(path), subargs=dict(xacro_args), walk_up=False).to_urdf_string(
                pretty=False
            )
    except (InputError, MemoryError):
        raise  # an include that read_text refused: its own message
    except Exception as exc:  # xacro reports its errors as many exception types
        raise InputError(
            path, f"cannot expand the xacro file: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}"
        ) from None
    if len(expanded) > MAX_EXPANDED:
        raise InputError(path, f"the xacro file expands to more than {MAX_EXPANDED:,} characters")
    return expanded


def read_urdf(path: Path, xacro_args: dict[str, str] | None = None) -> UrdfRobot:
    """Parse a URDF (or xacro) file's links and joints. Raises :class:`InputError` on bad input,
    at the line and column of the element or attribute at fault (:class:`UrdfText`)."""
    source = UrdfText(path, urdf_text(path, xacro_args))
    root = source.parse()
    if root.tag != "robot":
        raise source.error(root, f"not a URDF: the root element is <{quoted(root.tag)[1:-1]}>, expected <robot>")

    for element in root.iter("link", "joint", "parent", "child", "mimic"):
        for key in ("name", "link", "joint"):
            character = unprintable(element.get(key) or "")
            if character is not None:
                raise source.error(
                    element, f"<{element.tag} {key}=...> {acted_on(character)}; expected a printable name", key
                )

    links, link_places = [], {}
    for element in root.findall("link"):
        name = element.get("name")
        if not name:
            raise source.error(element, "<link> without a name")
        links.append(name)
        link_places.setdefault(name, source.place(element))
    if not links:
        raise source.error(root, "not a valid URDF: it declares no <link>")

    joints = []
    joint_names = {element.get("name") for element in root.findall("joint")}
    for element in root.findall("joint"):
        name, kind = element.get("name"), element.get("type")
        parent, child = element.find("parent"), element.find("child")
        if not name or not kind or parent is None or child is None:
            raise source.error(element, "a <joint> needs a name, a type, a <parent link> and a <child link>")
        mimic = element.find("mimic")
        if mimic is not None:
            master = mimic.get("joint")
            if not master:
                raise source.error(mimic, f"joint {quoted(name)}: <mimic> needs a joint")
            if master not in joint_names:
                raise source.error(mimic, f"joint {quoted(name)} mimics unknown joint {quoted(master)}", "joint")
            factor, offset = (
                _number(mimic, key, default, source) for key, default in (("multiplier", "1"), ("offset", "0"))
            )
            mimic = (master, factor, offset)
        for end in (parent, child):
            if end.get("link") not in link_places:
                raise source.error(
                    end, f"joint {quoted(name)} refers to unknown link {quoted(end.get('link'))}", "link"
                )
        origin = element.find("origin")
        xyz = attribute_floats(origin, "xyz", "0 0 0", source)
        rpy = attribute_floats(origin, "rpy", "0 0 0", source)
        axis = np.array(attribute_floats(element.find("axis"), "xyz", "1 0 0", source))
        if not np.linalg.norm(axis) > 0:
            raise source.error(element.find("axis"), f"joint {quoted(name)} has a zero axis", "xyz")
        limit = element.find("limit")
        bounds = []
        for key in ("lower", "upper"):
            text = limit.get(key) if limit is not None else None
            try:
                number = float(text) if text is not None else None
            except ValueError:
                raise source.error(
                    limit, f'joint {quoted(name)}: limit {key}="{_shown(text)}" is not a number', key
                ) from None
            if number is not None and not (math.isfinite(number) and abs(number) <= LIMIT):
                raise source.error(
                    limit,
                    f'joint {quoted(name)}: limit {key}="{_shown(text)}" must be finite and at most {LIMIT:g} in size',
                    key,
                )
            bounds.append(number)
        if None not in bounds and not bounds[0] < bounds[1] and kind not in ("fixed", "continuous"):
            # Swapping them silently would hide a mistake in the file; equal limits leave nothing to move.
            raise source.error(
                limit, f"joint {quoted(name)}: limit lower={bounds[0]:g} must be below upper={bounds[1]:g}", "lower"
            )
        joints.append(
            UrdfJoint(
                name,
                kind,
                parent.get("link"),
                child.get("link"),
                pose_to_matrix(np.array(xyz + rpy)),
                tuple(xyz),
                tuple(rpy),
                axis / np.linalg.norm(axis),
                bounds[0],
                bounds[1],
                *source.place(element),
                mimic,
            )
        )
    return UrdfRobot(root.get("name", path.stem), links, joints, path, link_places, source.place(root))
