"""The schema of a clearance problem: a serial chain and its joints' clearances.

This is the worst-case question of Berger et al. (2010): the largest
end-effector rotation and translation error that joint clearances can cause.

```yaml
name: rr-clearance
units: {length: m, angle: rad}   # optional, as in every bcad problem
chain:
  dh:                            # classic DH rows, base to end effector (Eq. 2)
    - {a: 0.5, alpha: 0.0, d: 0.0, theta: 0.3}
    - {a: 0.4, alpha: 0.0, d: 0.0, theta: -0.8}
  # angles: absolute             # rot_z bounds each link's turn from the base (planar arms)
  # or: {urdf: robots/rx90.urdf, q: [0, 0.5, ...], tip: link_6}
clearance:                       # one mapping for all joints, or a list, one per joint
  rot_xy: 1.0e-3                 # sqrt(dr_x^2 + dr_y^2) <= rot_xy        (Eq. 6)
  rot_z: 5.0e-4                  # |dr_z| <= rot_z                        (Eq. 7)
  trans_xy: 1.0e-4               # sqrt(dt_x^2 + dt_y^2) <= trans_xy      (Eq. 8)
  trans_z: 5.0e-5                # |dt_z| <= trans_z                      (Eq. 9)
```
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Literal

from pydantic import Discriminator, Field, PrivateAttr, Tag, model_validator

from bcad.model.base import StrictModel
from bcad.model.dh import DhJoint
from bcad.model.pose import LIMIT, Value
from bcad.model.source import SourceDocument, load_yaml, mapping_document
from bcad.model.units import RADIANS_PER_UNIT, Units
from bcad.model.validation import problem_error_from_validation

#: joints of a clearance chain at most
MAX_JOINTS = 20
#: the keys of a spec (``maxerror --spec``, ``--allocate``): the error's norms, and the tool
#: point's displacement along an axis of the base frame (:mod:`bcad.worstcase.directional`)
SPEC_KEYS = ("rotation", "translation", "dx", "dy", "dz", "-dx", "-dy", "-dz")


def spec_limits(value, where: str) -> dict[str, float]:
    """A spec, ``rotation=R,translation=T,dx=D,...`` (text) or the same as a mapping: each key of
    :data:`SPEC_KEYS` at most once, each limit a number from 1e-12 to 1e9 (problem units: a smaller
    one is below what the clearances resolve, each 0 or at least 1e-12)."""
    from bcad.errors import InputError

    if isinstance(value, str):
        pairs = []
        for part in value.split(",")[: len(SPEC_KEYS) + 1]:
            key, _, text = part.partition("=")
            try:
                number = float(text)
            except ValueError:
                number = float("nan")
            pairs.append((key.strip(), number, part))
    elif isinstance(value, dict):
        pairs = [(key, number, f"{key}={number!r}"[:80]) for key, number in value.items()]
    else:
        raise InputError(
            where, f"a spec is {type(value).__name__}; expected 'rotation=R,translation=T,dx=D,...' or a mapping"
        )
    if not pairs or len(pairs) > len(SPEC_KEYS):
        raise InputError(where, f"a spec has 1 to {len(SPEC_KEYS)} limits, each key once")
    limits: dict[str, float] = {}
    for key, number, shown in pairs:
        if key not in SPEC_KEYS or key in limits:
            raise InputError(
                where,
                f"'{shown[:80]}': expected KEY=VALUE, each key once, a key among rotation, translation "
                "(the error's norms) and dx, dy, dz, -dx, -dy, -dz (the tool point's displacement "
                "along an axis of the base frame)",
            )
        if isinstance(number, bool) or not isinstance(number, (int, float)) or not 1e-12 <= number <= 1e9:
            raise InputError(
                where,
                f"'{shown[:80]}': the limit must be a number from 1e-12 to 1e9 (below 1e-12 it is under what the "
                "clearances resolve, each 0 or at least 1e-12)",
            )
        limits[key] = float(number)
    return limits


def clearance_weights(value, where: str) -> list[float]:
    """Per-joint weights of ``--allocate``'s scale (text ``1,1,2`` or a list): numbers in
    [1e-6, 1e6], at most as many as a chain has joints."""
    from bcad.errors import InputError

    parts = value.split(",") if isinstance(value, str) else value
    if not isinstance(parts, (list, tuple)) or not 1 <= len(parts) <= MAX_JOINTS:
        raise InputError(where, f"expected 1 to {MAX_JOINTS} weights (one per joint)")
    weights = []
    for part in parts:
        try:
            number = float(part) if isinstance(part, str) else part
        except ValueError:
            number = float("nan")
        if isinstance(number, bool) or not isinstance(number, (int, float)) or not 1e-6 <= number <= 1e6:
            raise InputError(where, f"'{str(part)[:40]}': a weight is a number in [1e-6, 1e6]")
        weights.append(float(number))
    return weights


#: one classic Denavit-Hartenberg row (Eq. 2 of the 2010 paper; its b is our d): the rows of a
#: problem's DH robot (``robots: - {dh: [...]}``), so that one table describes the arm in both
#: parts of bcad; a clearance chain's joints are revolute.
DhRow = DhJoint


class DhChain(StrictModel):
    # At most MAX_JOINTS rows: the certified search's work grows quickly with the joints.
    dh: list[DhRow] = Field(min_length=1, max_length=MAX_JOINTS)
    angles: Literal["relative", "absolute"] = Field(
        "relative",
        description="what a joint's rot_z clearance bounds: the turn of its link relative to the previous "
        "link (relative, Eq. 7), or relative to the base (absolute: a planar arm whose links are each driven from the "
        "base, as in belt- and parallelogram-driven arms; every alpha must be 0)",
    )

    @model_validator(mode="after")
    def _revolute(self) -> DhChain:
        for i, row in enumerate(self.dh):
            if row.type != "revolute":
                raise ValueError(f"row {i + 1} is {row.type}: the clearance model (Eqs. 6-9) is of revolute joints")
        if self.angles == "absolute":
            for i, row in enumerate(self.dh):
                if row.alpha != 0.0:
                    raise ValueError(
                        f"row {i + 1} has alpha {row.alpha:g}: absolute angles are those of a planar arm, "
                        "whose joint axes are parallel (every alpha 0)"
                    )
        return self


class UrdfChain(StrictModel):
    """A chain read from URDF: each revolute joint (axis along +-x, +-y or +-z) gives an F_j with z along its axis."""

    urdf: str = Field(description="path to the URDF, relative to the problem file")
    q: list[Value] = Field(
        max_length=MAX_JOINTS,
        description=(
            "joint values, one per actuated joint that mimics none, in the problem's units "
            "(a <mimic> joint follows its master)"
        ),
    )
    tip: str | None = Field(None, description="end-effector link (default: child of the last actuated joint)")


#: the largest rotation clearance, rad: the error model (Eqs. 6-9) is of small rotations; checked
#: in the problem's angle unit once the units are known (:func:`check_rotations`: the fields
#: themselves take any finite number, so that one message, in the problem's unit, says it)
MAX_ROTATION_CLEARANCE = 1.0


class Clearance(StrictModel):
    """Bounds of one joint's error screw (Eq. 6-9); zero means no clearance there."""

    rot_xy: float = Field(
        0.0,
        ge=0.0,
        description="bound of sqrt(dr_x^2 + dr_y^2) (Eq. 6), in the problem's angle unit: at most 1 rad (57.3 deg)",
    )
    rot_z: float = Field(
        0.0,
        ge=0.0,
        description="bound of |dr_z| (Eq. 7), in the problem's angle unit: at most 1 rad (57.3 deg)",
    )
    trans_xy: float = Field(0.0, ge=0.0, le=LIMIT)
    trans_z: float = Field(0.0, ge=0.0, le=LIMIT)

    @model_validator(mode="after")
    def _zero_or_resolvable(self) -> Clearance:
        for name in ("rot_xy", "rot_z", "trans_xy", "trans_z"):
            value = getattr(self, name)
            if 0.0 < value < 1e-12:
                raise ValueError(f"{name} = {value:g}: a clearance is 0 or at least 1e-12")
        return self


def _chain_kind(value) -> str | None:
    """Which chain ``value`` is: DH rows (``dh``) or a URDF (``urdf``, or its model); None where it
    names neither (its error then says both)."""
    if isinstance(value, DhChain):
        return "dh"
    if isinstance(value, dict):
        return "dh" if "dh" in value else "urdf" if "urdf" in value else None
    return "urdf" if isinstance(value, UrdfChain) else None


class ChainProblem(StrictModel):
    name: str
    description: str = ""
    units: Units = Field(default_factory=Units)
    chain: Annotated[
        Annotated[DhChain, Tag("dh")] | Annotated[UrdfChain, Tag("urdf")],
        Discriminator(
            _chain_kind,
            custom_error_type="chain_kind",
            custom_error_message="expected a mapping with dh: [rows] or urdf: FILE",
        ),
    ]
    clearance: Clearance | list[Clearance]

    _source: SourceDocument | None = PrivateAttr(default=None)

    @property
    def source(self) -> SourceDocument:
        return self._source if self._source is not None else SourceDocument(path=Path("<memory>"), data=None)


def is_clearance_problem(data: object) -> bool:
    """Whether parsed YAML is a clearance problem (it has a ``chain``) rather than a Bayesian one."""
    return isinstance(data, dict) and "chain" in data


def problem_or_chain_from_document(doc: SourceDocument):
    """The problem a parsed document holds: a clearance problem where it has a ``chain``, else a
    problem (:func:`bcad.model.problem.problem_from_document`). Raises :class:`InputError`."""
    from bcad.model.problem import problem_from_document

    return (chain_problem_from_document if is_clearance_problem(doc.data) else problem_from_document)(doc)


def load_problem_or_chain(source):
    """A problem (:func:`bcad.model.problem.load`) or, where it has a ``chain``, a clearance problem:
    from a path or a mapping (``bcad.load``)."""
    from bcad.model.problem import load

    if isinstance(source, dict) and is_clearance_problem(source):
        return chain_problem_from_document(mapping_document(source))
    if isinstance(source, (str, Path)) and str(source).strip():
        return problem_or_chain_from_document(load_yaml(Path(source)))
    return load(source)


def load_chain_problem(path: Path | str) -> ChainProblem:
    """Read and validate a clearance problem. Raises :class:`InputError` on bad input."""
    return chain_problem_from_document(load_yaml(path))


def chain_problem_from_document(doc: SourceDocument) -> ChainProblem:
    """Validate parsed YAML as a clearance problem; errors name the file position."""
    if not isinstance(doc.data, dict):
        raise doc.error((), "a clearance problem must be a YAML mapping with keys name, chain, clearance")
    if "frames" in doc.data and "chain" not in doc.data:
        raise doc.error(
            ("frames",),
            (
                "this is a problem with measurements (it has frames): run 'bcad calibrate' or 'bcad validate' on it"
                if doc.data.get("measurements")
                else "this is a Bayesian problem (it has frames): run 'bcad solve' or 'bcad validate' on it"
            ),
            key=True,
        )
    problem = problem_error_from_validation(doc, ChainProblem)
    problem._source = doc
    check_rotations(problem)
    return problem


def check_rotations(problem: ChainProblem) -> None:
    """Rotation clearances of at most MAX_ROTATION_CLEARANCE rad in the problem's angle unit, the
    error model's small rotations; refused at the field (exit 2). For a problem from a file and
    for one made in Python alike."""
    doc = problem.source
    unit = problem.units.angle
    radians_per_unit = RADIANS_PER_UNIT[unit]
    listed = isinstance(problem.clearance, list)
    for k, clearance in enumerate(problem.clearance if listed else [problem.clearance]):
        for name in ("rot_xy", "rot_z"):
            value = getattr(clearance, name)
            if value * radians_per_unit > MAX_ROTATION_CLEARANCE:
                loc = ("clearance", k, name) if listed else ("clearance", name)
                raise doc.error(
                    loc,
                    f"{'.'.join(map(str, loc))}: {value:g} {unit} is too large a rotation clearance; expected at most "
                    f"{MAX_ROTATION_CLEARANCE:g} rad ({math.degrees(MAX_ROTATION_CLEARANCE):.4g} deg), where the error "
                    "model's small rotations (Eqs. 6-9) hold",
                )
