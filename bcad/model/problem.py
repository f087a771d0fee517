"""The problem language: the schema of a bcad problem file.

A problem is a probabilistic kinematic graph (Sect. 3.1 of the 2000 paper):
``frames`` are its vertices; ``links``, ``robots`` (each URDF joint and link)
and ``relations`` between geometric ``entities`` are its edges. Every edge
carries a nominal ``pose``, a 6-letter ``status`` and, for its L (and
optionally X) parameters, ``distributions``; X parameters have ``bounds``.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal

from pydantic import Field, PrivateAttr, field_validator, model_validator

from bcad.errors import InputError, shown
from bcad.model.base import StrictModel
from bcad.model.camera import Camera
from bcad.model.dh import MAX_DH_ROWS, DhJoint
from bcad.model.distributions import Distribution
from bcad.model.entities import Entity
from bcad.model.measurement import Measurement
from bcad.model.pose import LIMIT, Bounds, Pose, Status, Value, parameter_group
from bcad.model.solver import SolverSettings
from bcad.model.source import SourceDocument, load_yaml, mapping_document
from bcad.model.units import Units
from bcad.model.validation import problem_error_from_validation
from bcad.relations import RELATIONS


class PoseSpec(StrictModel):
    """What every edge of the graph carries: pose, status, distributions, bounds.

    * ``pose``: nominal values; F parameters keep them, L parameters deviate
      from them by a draw of their distribution, X parameters start there.
    * ``distributions``: for L parameters, the distribution of the deviation
      from the nominal value (required); for X parameters, an optional prior on
      the value (default: uniform on the bounds). A key may name two
      parameters (``tx,ty: disc(0.05)``).
    * ``bounds``: ``[low, high]`` of each X parameter's value.
    """

    pose: Pose = Field(default_factory=lambda: [0.0] * 6)
    status: Status = "FFFFFF"
    distributions: dict[str, Distribution] = Field(default_factory=dict)
    bounds: dict[str, Bounds] = Field(default_factory=dict)

    @field_validator("distributions", "bounds")
    @classmethod
    def _parameter_keys(cls, value: dict[str, Any]) -> dict[str, Any]:
        for key in value:
            parameter_group(key)
        return value


class Parametrised(PoseSpec):
    """An edge the user declares. ``close: true`` asks for it to be a cycle's
    closing link, ``false`` keeps it in the spanning tree; by default relations
    close cycles and other links do not."""

    close: bool | None = None


class Link(Parametrised):
    """A probabilistic kinematic link from ``parent`` frame to ``child`` frame."""

    name: str
    parent: str
    child: str


def _relation_doc() -> str:
    kinds = "\n".join(f"* ``{k.name}`` ({k.parent}, {k.child}): {k.summary}" for k in RELATIONS.values())
    return f"""A geometric relation between two entities: a link between their frames.

The link's pose is that of the child entity's frame in the parent entity's frame. The relation
fixes which parameters it constrains (its equality constraints) and adds inequality constraints:

{kinds}
"""


class Relation(Parametrised):
    __doc__ = _relation_doc()

    name: str
    type: Literal[tuple(RELATIONS)]  # type: ignore[valid-type]
    parent: str = Field(description="name of the parent entity")
    child: str = Field(description="name of the child entity")


class Joint(StrictModel):
    """Settings of one joint of a robot (or of all, under the key ``default``).

    ``status`` X makes the joint variable an unknown bounded by the URDF limits
    (or ``bounds``); F holds it at ``value``. ``zero`` is the distribution of
    the joint's zero-position error (an L parameter).

    Geometric errors, the usual calibration models, are L
    parameters too:

    * ``origin_error`` (URDF robots): distributions of a pose error of the
      joint's ``<origin>``, keyed by pose parameter as a link's
      ``distributions`` (``tx: normal(0, 0.1)``, ``rx,ry: ...``): the joint's
      frame becomes ``origin · T(error)`` before its motion.
    * ``dh_error`` (DH robots): distributions of the errors of the row's
      ``a``, ``alpha``, ``d`` and ``theta`` (the zero error is ``theta``'s in a
      revolute row, ``d``'s, a length along the axis, in a prismatic one: give
      it here or as ``zero``, not both), and ``beta``, Hayati's
      rotation about the row's y axis (nominally 0): DH cannot describe a
      small tilt of a parallel next axis about y with small errors, beta can.
    """

    status: Literal["X", "F"] = "X"
    value: Value | None = None
    zero: Distribution | None = None
    bounds: Bounds | None = None
    prior: Distribution | None = None
    origin_error: dict[str, Distribution] = Field(default_factory=dict)
    dh_error: dict[Literal["a", "alpha", "d", "theta", "beta"], Distribution] = Field(default_factory=dict)

    @field_validator("origin_error")
    @classmethod
    def _origin_keys(cls, value: dict[str, Distribution]) -> dict[str, Distribution]:
        for key in value:
            parameter_group(key)
        return value


#: a xacro argument's name, and its value: a literal. A value is substituted into the
#: xacro file's expressions (``${$(arg l1) * 1.0}``), which xacro evaluates as Python: a value
#: with parentheses, quotes, operators or spaces could run code there, so only numbers and plain
#: words (letters, digits, _ . / -, no double underscore) pass.
XACRO_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,127}$")
XACRO_WORD = re.compile(r"^[A-Za-z0-9_./-]{1,1000}$")


def _python_number(text: str) -> float | None:
    """The number Python reads in a word that float() does not (0x1f, 0b101, 0o17, 1j), which
    xacro's expressions would: an integer as a float (inf past its range), a complex as NaN (no
    length is one); None for a word that is no number (a plain word, 2nd)."""
    import ast

    if not re.match(r"[+-]?[0-9]", text):
        return None
    try:
        number = ast.literal_eval(text)
    except (ValueError, SyntaxError, MemoryError, RecursionError):
        return None
    if isinstance(number, bool) or not isinstance(number, (int, float, complex)):
        return None
    if isinstance(number, complex):
        return math.nan
    return float(number) if abs(number) < 2**1024 else math.inf


def _xacro_literal(name: str, value: str) -> None:
    if not XACRO_NAME.match(name):
        raise ValueError(f"xacro argument name {name[:60]!r}: expected an identifier (letters, digits, _)")
    text = value.strip()
    try:
        number = float(text)
    except ValueError:
        number = _python_number(text)
    if number is not None and XACRO_WORD.match(text.lstrip("+")):
        # a word Python reads as a number ("1e400", "inf", "1_0") is one, bounded as a YAML number is
        if math.isfinite(number) and abs(number) <= LIMIT:
            return
        raise ValueError(f"xacro argument {name!r} is {value[:60]!r}; expected a finite number of at most {LIMIT:g}")
    if XACRO_WORD.match(text) and "__" not in text:
        return
    raise ValueError(
        f"xacro argument {name!r} is {value[:60]!r}: a xacro argument is a literal, a number or a plain word "
        "(letters, digits, _ . / -, no '__'); xacro evaluates the expressions it is substituted into, so "
        "nothing else is passed to it"
    )


class Robot(PoseSpec):
    """An arm loaded from URDF, or given by DH rows, placed at ``pose`` in the ``parent`` frame.

    Its URDF links become frames ``NAME/LINK``; its joints become links
    ``NAME/JOINT``. A DH robot's frames are ``NAME/link_0`` (its base) to
    ``NAME/link_N`` (after row N). ``pose``, ``status``, ``distributions`` and
    ``bounds`` describe the base link ``NAME/base`` from ``parent`` to the root.
    """

    name: str
    urdf: str | None = Field(None, description="path to the URDF (or a .urdf.xacro file), relative to the problem file")
    xacro_args: dict[
        str,
        Annotated[str, Field(max_length=10_000)]
        | Annotated[int, Field(strict=True)]
        | Annotated[float, Field(strict=True)],
    ] = Field(
        default_factory=dict,
        max_length=1000,
        description="the xacro file's `xacro:arg` values: numbers, or plain words",
    )
    dh: list[DhJoint] | None = Field(None, min_length=1, max_length=MAX_DH_ROWS, description="DH rows, base to tip")
    convention: Literal["classic", "modified"] = "classic"
    parent: str
    joints: dict[str, Joint] = Field(default_factory=dict)

    @field_validator("xacro_args")
    @classmethod
    def _literal_xacro_args(cls, value: dict[str, str | int | float]) -> dict[str, str]:
        # a number is passed as it is written in Python (0.6, 2, 1e-05), as xacro reads it
        for name, number in value.items():
            # (compared as it is: an integer of 400 digits has no float, nor one of 5000 a repr)
            if not isinstance(number, str) and not abs(number) <= LIMIT:
                raise ValueError(
                    f"xacro argument {name!r} is {shown(number)}; expected a finite number of at most {LIMIT:g}"
                )
        value = {name: text if isinstance(text, str) else repr(text) for name, text in value.items()}
        for name, text in value.items():
            _xacro_literal(name, text)
        return value

    @model_validator(mode="after")
    def _one_description(self) -> Robot:
        if (self.urdf is None) == (self.dh is None):
            raise ValueError(f"robot '{self.name}' needs exactly one of urdf: (a file) or dh: (rows)")
        return self


#: a configuration's name: a plain identifier (it becomes a suffix ``@NAME`` of frame, link and
#: parameter names)
ConfigurationName = Annotated[str, Field(min_length=1, max_length=64, pattern=r"^[A-Za-z_][A-Za-z0-9_-]*$")]
#: configurations of one problem at most
MAX_CONFIGURATIONS = 16


class ConfigurationJoint(StrictModel):
    """A joint's setting in one configuration: its variable's status, value, bounds and prior
    (what is unset falls back to the robot's own ``joints:`` setting). Its errors (zero, origin,
    DH) are the robot's, shared by every configuration."""

    status: Literal["X", "F"] | None = None
    value: Value | None = None
    bounds: Bounds | None = None
    prior: Distribution | None = None


class Configuration(StrictModel):
    """The cell at another pose of its robots.

    ``joints`` names, per robot, the joints whose variables this configuration has of its own
    (``default``: every actuated joint of the robot), with their settings. Every joint a
    configuration names is replicated in each configuration: the robot's frames downstream of
    it (and what is attached to them: tools, entities, relations) exist once per configuration,
    named ``FRAME@CONFIGURATION``. ``relations`` and ``links`` list those that belong to this
    configuration only; a relation or link on the replicated frames that no configuration lists
    holds in every configuration. Every L and every X that is not a replicated joint variable is
    shared: the physical robot has one set of errors.
    """

    name: ConfigurationName
    joints: dict[str, dict[str, ConfigurationJoint]] = Field(default_factory=dict, max_length=64)
    relations: list[str] = Field(default_factory=list, max_length=10_000)
    links: list[str] = Field(default_factory=list, max_length=10_000)


class Problem(StrictModel):
    """A whole bcad problem file."""

    document_root: ClassVar[bool] = True

    name: str
    description: str = ""
    units: Units = Field(default_factory=Units)
    frames: list[str] = Field(min_length=1)
    robots: list[Robot] = Field(default_factory=list)
    links: list[Link] = Field(default_factory=list)
    entities: list[Entity] = Field(default_factory=list)
    relations: list[Relation] = Field(default_factory=list)
    solver: SolverSettings = Field(default_factory=SolverSettings)
    configurations: list[Configuration] = Field(
        default_factory=list,
        max_length=MAX_CONFIGURATIONS,
        description="the cell at several poses of its robots, sharing every error (at most 16)",
    )
    cameras: list[Camera] = Field(
        default_factory=list, max_length=100, description="pinhole cameras: sensors whose measurements are pixels"
    )
    measurements: list[Measurement] = Field(default_factory=list, max_length=100)
    calibration: list[Annotated[str, Field(min_length=1, max_length=4096)]] = Field(
        default_factory=list,
        max_length=16,
        description="results of bcad calibrate (JSON files, relative to this file): every parameter a result names "
        "that is L here takes the result's joint posterior (its MAP and Laplace covariance, correlations kept)",
    )

    _source: SourceDocument | None = PrivateAttr(default=None)

    @property
    def source(self) -> SourceDocument:
        """The file this problem was read from (for error positions and relative paths)."""
        if self._source is None:
            return SourceDocument(path=Path("<memory>"), data=None)
        return self._source


def problem_from_document(doc: SourceDocument) -> Problem:
    """Validate parsed YAML against the schema; errors name the file position."""
    if not isinstance(doc.data, dict):
        raise doc.error((), "a problem file must be a YAML mapping with keys such as name, frames, links")
    if "chain" in doc.data and "frames" not in doc.data:
        raise doc.error(("chain",), "this is a clearance problem (it has a chain): run 'bcad maxerror' on it", key=True)
    problem = problem_error_from_validation(doc, Problem)
    problem._source = doc
    # Every file the problem names is an input of the command, read by it or not (a plot
    # does not read the measurements): relative_path records it, so no output replaces it.
    for named in [
        *(r.urdf for r in problem.robots),
        *(m.data for m in problem.measurements),
        *problem.calibration,
        *(c.camera_info for c in problem.cameras),
    ]:
        if named is not None:
            doc.relative_path(named)
    return problem


def load_problem(path: Path | str) -> Problem:
    """Read and validate a problem file. Raises :class:`InputError` on bad input."""
    return problem_from_document(load_yaml(path))


__all__ = [
    "Problem",
    "Link",
    "Relation",
    "Robot",
    "Joint",
    "DhJoint",
    "Units",
    "Configuration",
    "ConfigurationJoint",
    "load_problem",
    "InputError",
]


def load(source: str | Path | dict | Problem) -> Problem:
    """A problem from a YAML file (path) or from a mapping of the same keys (``dict``); a
    :class:`Problem` as it is. Paths in a mapping (``urdf``, ``data``) are relative to the current
    folder. Raises :class:`InputError` naming the file and line of anything wrong."""
    if isinstance(source, Problem):
        return source
    if isinstance(source, dict):
        return problem_from_document(mapping_document(source))
    if not isinstance(source, (str, Path)) or not str(source).strip():
        shown = repr(source)
        raise InputError(
            "<api>",
            f"a problem is {type(source).__name__} {shown[:60]}{'...' if len(shown) > 60 else ''}; expected a "
            "file's path (str or pathlib.Path), a mapping of a problem's keys (dict) or a loaded problem",
        )
    return load_problem(Path(source))
