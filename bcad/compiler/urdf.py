"""A reader for the kinematic subset of URDF: links, and joints with their
origin, axis and limits.

bcad reads URDF with lxml directly rather than through yourdfpy: importing
yourdfpy (and trimesh behind it) costs 0.66 s, a third of the start-up budget
of ``bcad posterior``, and only the kinematic elements are needed. The tests
check this reader against yourdfpy and the resulting kinematics against
Pinocchio. Errors name the URDF file and line.
"""

from __future__ import annotations

import math
import os
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bcad.errors import InputError, acted_on, install_hint, unprintable
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
    line: int
    #: <mimic joint multiplier offset>: q = multiplier * q_master + offset (offset in URDF units)
    mimic: tuple[str, float, float] | None = None


@dataclass(frozen=True)
class UrdfRobot:
    name: str
    links: list[str]
    joints: list[UrdfJoint]
    path: Path


def _number(element, attribute: str, default: str, path: Path) -> float:
    return attribute_floats(element, attribute, default, path, count=1)[0]


def attribute_floats(element, attribute: str, default: str, path: Path, count: int = 3) -> list[float]:
    """``count`` finite, bounded numbers from an XML attribute, or an InputError naming its line."""
    text = element.get(attribute, default) if element is not None else default
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        values = []
    if len(values) != count:
        raise InputError(path, f'<{element.tag} {attribute}="{text}"> needs {count} numbers', element.sourceline)
    if not all(math.isfinite(v) and abs(v) <= LIMIT for v in values):
        raise InputError(
            path,
            f'<{element.tag} {attribute}="{text}">: every number must be finite and at most {LIMIT:g} in size',
            element.sourceline,
        )
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
        raise InputError(answer["error"]["file"], answer["error"]["message"], answer["error"].get("line"))
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
            answer = {"error": {"file": str(exc.file), "message": exc.message, "line": exc.line}}
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
    """Parse a URDF (or xacro) file's links and joints. Raises :class:`InputError` on bad input."""
    from lxml import etree  # here: a DH chain or a problem without robots never loads lxml

    text = urdf_text(path, xacro_args)
    try:
        root = etree.fromstring(text.encode("utf-8"), etree.XMLParser(remove_comments=True, resolve_entities=False))
    except etree.XMLSyntaxError as exc:
        line, column = exc.position if exc.position else (None, None)
        raise InputError(path, f"cannot parse the URDF: {exc.msg}", line, column) from None
    if root.tag != "robot":
        raise InputError(path, f"not a URDF: the root element is <{root.tag}>, expected <robot>", root.sourceline)

    for element in root.iter("link", "joint", "parent", "child", "mimic"):
        for key in ("name", "link", "joint"):
            character = unprintable(element.get(key) or "")
            if character is not None:
                raise InputError(
                    path,
                    f"<{element.tag} {key}=...> {acted_on(character)}; expected a printable name",
                    element.sourceline,
                )

    links = []
    for element in root.findall("link"):
        name = element.get("name")
        if not name:
            raise InputError(path, "<link> without a name", element.sourceline)
        links.append(name)
    if not links:
        raise InputError(path, "not a valid URDF: it declares no <link>", root.sourceline)

    joints = []
    for element in root.findall("joint"):
        name, kind = element.get("name"), element.get("type")
        parent, child = element.find("parent"), element.find("child")
        if not name or not kind or parent is None or child is None:
            raise InputError(
                path, "a <joint> needs a name, a type, a <parent link> and a <child link>", element.sourceline
            )
        mimic = element.find("mimic")
        if mimic is not None:
            master = mimic.get("joint")
            if not master:
                raise InputError(path, f"joint '{name}': <mimic> needs a joint", mimic.sourceline)
            factor, offset = (
                _number(mimic, key, default, path) for key, default in (("multiplier", "1"), ("offset", "0"))
            )
            mimic = (master, factor, offset)
        for end in (parent, child):
            if end.get("link") not in links:
                raise InputError(path, f"joint '{name}' refers to unknown link '{end.get('link')}'", end.sourceline)
        origin = element.find("origin")
        xyz = attribute_floats(origin, "xyz", "0 0 0", path)
        rpy = attribute_floats(origin, "rpy", "0 0 0", path)
        axis = np.array(attribute_floats(element.find("axis"), "xyz", "1 0 0", path))
        if not np.linalg.norm(axis) > 0:
            raise InputError(path, f"joint '{name}' has a zero axis", element.sourceline)
        limit = element.find("limit")
        bounds = []
        for key in ("lower", "upper"):
            text = limit.get(key) if limit is not None else None
            try:
                number = float(text) if text is not None else None
            except ValueError:
                raise InputError(
                    path, f"joint '{name}': limit {key}=\"{text}\" is not a number", limit.sourceline
                ) from None
            if number is not None and not (math.isfinite(number) and abs(number) <= LIMIT):
                raise InputError(
                    path,
                    f"joint '{name}': limit {key}=\"{text}\" must be finite and at most {LIMIT:g} in size",
                    limit.sourceline,
                )
            bounds.append(number)
        if None not in bounds and not bounds[0] < bounds[1] and kind not in ("fixed", "continuous"):
            # Swapping them silently would hide a mistake in the file; equal limits leave nothing to move.
            raise InputError(
                path, f"joint '{name}': limit lower={bounds[0]:g} must be below upper={bounds[1]:g}", limit.sourceline
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
                element.sourceline,
                mimic,
            )
        )
    names = {joint.name for joint in joints}
    for joint in joints:
        if joint.mimic is not None and joint.mimic[0] not in names:
            raise InputError(path, f"joint '{joint.name}' mimics unknown joint '{joint.mimic[0]}'", joint.line)
    return UrdfRobot(root.get("name", path.stem), links, joints, path)
