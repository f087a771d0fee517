"""URDF robots compiled into frames and links of the kinematic graph.

Every URDF link becomes a frame ``ROBOT/LINK``. A fixed joint becomes one
link ``ROBOT/JOINT`` carrying its origin. An actuated joint (revolute,
continuous or prismatic, axis along a coordinate axis) becomes:

* with a zero-position distribution: a link ``ROBOT/JOINT/zero`` from the
  parent link to a joint frame ``ROBOT/JOINT/zero`` (the URDF origin, then the
  zero error as an L parameter about the joint axis), and a link
  ``ROBOT/JOINT`` from that frame to the child link (the joint variable,
  status X or F). The two are two links because the paper's pose vectors
  give each parameter one status; the kinematics folds them back into one
  rotation by q + dq.
* without one: a single link ``ROBOT/JOINT`` (origin, then the joint variable).

The joint variable is the link parameter about (or along) the joint's axis:
``rz`` for axis ``0 0 1``. For a negative axis such as ``0 0 -1`` the link
parameter is ``-q``, and its bounds are the negated limits.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass

import numpy as np

from bcad.compiler.edges import check_edge, edge_from_spec, prior_outside_bounds, prior_outside_message
from bcad.compiler.graph import GraphLink
from bcad.compiler.units import angle_scale, urdf_length_scale
from bcad.compiler.urdf import UrdfJoint, UrdfRobot, read_urdf
from bcad.errors import InputError
from bcad.model.pose import PARAMETERS, parameter_group
from bcad.model.problem import Joint, PoseSpec, Robot, Units
from bcad.model.source import Location, SourceDocument

ACTUATED = {"revolute", "continuous", "prismatic"}


def _load_urdf(robot: Robot, doc: SourceDocument, loc: Location) -> UrdfRobot:
    path = doc.named_file(loc + ("urdf",), robot.urdf, "a URDF file", "URDF file ")
    if robot.xacro_args and path.suffix != ".xacro":
        raise doc.error(loc + ("xacro_args",), f"xacro_args are for a .xacro file; '{path.name}' is none", key=True)
    return read_urdf(path, robot.xacro_args)


def _joint_settings(robot: Robot, name: str) -> Joint:
    merged = {}
    for key in ("default", name):
        if key in robot.joints:
            merged.update(robot.joints[key].model_dump(exclude_unset=True))
    return Joint.model_validate(merged)


#: bounds or a value past a joint's limits by less than this share of the limits' width are the
#: limits written in other units (+-180 deg against a URDF's +-3.14159 rad): held to the limits
LIMIT_ROUNDING = 1e-4


def _setting_loc(robot: Robot, name: str, key: str, loc: Location) -> Location:
    """Where a joint's ``key`` (bounds, value) is written: under its own name, or under ``default``."""
    for source in (name, "default"):
        if source in robot.joints and key in robot.joints[source].model_fields_set:
            return loc + ("joints", source, key)
    return loc


def _within_limits(
    robot: Robot,
    name: str,
    settings: Joint,
    limits: tuple[float, float],
    bounds: tuple[float, float],
    value: float,
    revolute: bool,
    units: Units,
    loc: Location,
    doc,
) -> tuple[tuple[float, float], float]:
    """A joint's ``bounds`` (given, or its limits) and its ``value`` (internal units), checked and
    held by :func:`within_limits`, each error at the setting's place."""
    return within_limits(
        name,
        limits,
        bounds if settings.bounds is not None else None,
        value if settings.value is not None else None,
        revolute,
        units,
        (_setting_loc(robot, name, "bounds", loc), _setting_loc(robot, name, "value", loc)),
        doc,
        (bounds, value),
    )


def within_limits(
    name: str,
    limits: tuple[float, float],
    bounds: tuple[float, float] | None,
    value: float | None,
    revolute: bool,
    units: Units,
    locs: tuple[Location, Location],
    doc,
    defaults: tuple[tuple[float, float], float],
) -> tuple[tuple[float, float], float]:
    """A joint's ``bounds`` and ``value`` as the problem gives them (internal units; None: not
    given, ``defaults`` stand for them), refused at their place (``locs``: the bounds', the
    value's) where they reach beyond the joint's ``limits`` (the robot cannot go there: a planned
    or fixed joint value past its travel would be a configuration no robot reaches), and held to
    them within LIMIT_ROUNDING of their width. Messages in the problem's ``units``."""
    scale, unit = (angle_scale(units), units.angle) if revolute else (1.0, units.length)
    low, high = limits
    slack = LIMIT_ROUNDING * max(high - low, 1e-12)

    def shown(pair) -> str:
        return f"[{pair[0] / scale:.6g}, {pair[1] / scale:.6g}] {unit}"

    if bounds is not None and (bounds[0] < low - slack or bounds[1] > high + slack):
        raise doc.error(
            locs[0],
            f"joint '{name}': bounds {shown(bounds)} reach beyond its limits {shown(limits)}, where the robot "
            "cannot go; give bounds within the limits",
        )
    if value is not None and not low - slack <= value <= high + slack:
        raise doc.error(
            locs[1],
            f"joint '{name}': value {value / scale:.6g} {unit} is beyond its limits {shown(limits)}, where the "
            "robot cannot go",
        )
    bounds = defaults[0] if bounds is None else bounds
    value = defaults[1] if value is None else value
    held = (min(max(bounds[0], low), high), max(min(bounds[1], high), low))
    return held, min(max(value, low), high)


def _check_prior(robot: Robot, name: str, settings: Joint, bounds: tuple[float, float], scale: float, loc, doc) -> None:
    """A joint's prior that puts no probability within its bounds (internal units; ``scale``:
    problem units -> internal) is refused at its place."""
    low, high = bounds[0] / scale, bounds[1] / scale
    if settings.status == "X" and settings.prior is not None and prior_outside_bounds(settings.prior, low, high):
        raise doc.error(
            _setting_loc(robot, name, "prior", loc), prior_outside_message(f"joint '{name}'", settings.prior, low, high)
        )


def _axis_of(joint: UrdfJoint) -> tuple[int, float, np.ndarray]:
    """The joint's axis as (coordinate axis, sign, turn): an axis along +-x, +-y or +-z is that
    coordinate axis with no turn; any other is z after the turn ``Ra`` (a rotation taking z to
    the axis), folded into the constant parts of the links: origin . Ra . Rz(q) . Ra^T is the
    rotation by q about the axis (Rodrigues), and likewise for a translation along it."""
    axis = joint.axis  # a unit vector: the URDF reader refuses a zero axis and normalises the rest
    k = int(np.argmax(np.abs(axis)))
    if np.count_nonzero(np.abs(axis) > 1e-12) == 1:
        return k, float(np.sign(axis[k])), np.eye(4)
    return 2, 1.0, turn_z_to(axis)


def turn_z_to(axis: np.ndarray) -> np.ndarray:
    """A rotation (4 x 4) taking the z axis to the unit vector ``axis``."""
    z = np.asarray(axis, dtype=float)
    helper = np.eye(3)[int(np.argmin(np.abs(z)))]
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    return T


def _check_joint_names(robot: Robot, joint_names: set[str], loc: Location, doc: SourceDocument) -> None:
    """Every key of ``joints:`` names a joint of the robot (or is ``default``)."""
    for key in robot.joints:
        if key != "default" and key not in joint_names:
            close = difflib.get_close_matches(key, sorted(joint_names), n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise doc.error(
                loc + ("joints", key),
                f"robot '{robot.name}' has no joint '{key}'{hint}; its joints are {', '.join(sorted(joint_names))}",
                key=True,
            )


def _error_link(
    name: str,
    parent: str,
    child: str,
    pose: list[float],
    errors: dict[str, object],
    units: Units,
    loc: Location,
    doc: SourceDocument,
    origin: np.ndarray | None = None,
) -> GraphLink:
    """A robot link of nominal ``pose`` (problem units) whose parameters named in ``errors``
    (pose-parameter keys, as a link's distributions) are L with those distributions."""
    covered = {parameter for key in errors for parameter in parameter_group(key)}
    status = "".join("L" if parameter in covered else "F" for parameter in PARAMETERS)
    spec = PoseSpec(pose=pose, status=status, distributions=errors)
    check_edge(spec, loc, doc)
    link = edge_from_spec(name, parent, child, spec, loc, units, rank="robot")
    if origin is not None:
        link.origin = origin
    return link


def _motion_link(
    name: str,
    parent: str,
    child: str,
    settings: Joint,
    slot: int,
    sign: float,
    limits: tuple[float, float],
    value: float,
    user_scale: float,
    loc: Location,
    hard_limits: tuple[float, float] | None = None,
) -> GraphLink:
    """A joint's motion link: its variable is the link parameter ``slot`` (= sign x the joint's value,
    internal units), X within ``limits`` (with the joint's prior, if any) or F at ``value``;
    ``hard_limits``: the joint's own travel (:attr:`GraphLink.hard_limits`)."""
    parameter = PARAMETERS[slot]
    status = ["F"] * 6
    status[slot] = settings.status
    nominal = np.zeros(6)
    nominal[slot] = sign * value
    motion = GraphLink(name, parent, child, nominal, "".join(status), rank="robot", loc=loc)
    motion.joint = (name, sign, user_scale)
    motion.joint_slot = slot
    motion.joint_limits = (float(limits[0]), float(limits[1]))
    motion.hard_limits = hard_limits
    motion.bounds_given = settings.bounds is not None
    if settings.status == "X":
        motion.bounds[parameter] = tuple(sorted((sign * limits[0], sign * limits[1])))
        if settings.prior is not None:
            motion.distributions[(parameter,)] = settings.prior.scaled(sign * user_scale)
    return motion


@dataclass(frozen=True)
class RobotFrames:
    """Where a compiled robot is: its base frame and its actuated joints' child frames, in order."""

    name: str
    base_frame: str
    joint_frames: tuple[str, ...]

    @property
    def wrist_frame(self) -> str:
        """The child frame of the second-to-last actuated joint: the wrist centre of a
        6-axis arm with a spherical wrist whose URDF puts J5 at the wrist centre (the RX90)."""
        return self.joint_frames[-2] if len(self.joint_frames) >= 2 else self.joint_frames[-1]


def robot_frames_and_links(
    robot: Robot, robot_index: int, units: Units, doc: SourceDocument
) -> tuple[list[str], list[GraphLink], RobotFrames]:
    """Frames and links contributed by one robot, base link included."""
    loc: Location = ("robots", robot_index)
    if robot.dh is not None:
        return dh_robot_frames_and_links(robot, robot_index, units, doc)
    urdf = _load_urdf(robot, doc, loc)
    path = urdf.path
    length = urdf_length_scale(units)
    angle = angle_scale(units)
    prefix = robot.name + "/"

    _check_joint_names(robot, {joint.name for joint in urdf.joints}, loc, doc)

    frames = [prefix + link for link in urdf.links]
    root = urdf.root()
    links: list[GraphLink] = []
    joint_frames: list[str] = []
    mimics: list[tuple[GraphLink, int, float, float, UrdfJoint]] = []

    def scaled_origin(joint: UrdfJoint) -> np.ndarray:
        origin = joint.origin.copy()
        origin[:3, 3] *= length
        return origin

    for joint in urdf.joints:
        name = prefix + joint.name
        parent, child = prefix + joint.parent, prefix + joint.child
        joint_loc = loc + ("joints", joint.name) if joint.name in robot.joints else loc
        if joint.type == "fixed":
            links.append(
                GraphLink(
                    name, parent, child, np.zeros(6), "FFFFFF", origin=scaled_origin(joint), rank="robot", loc=loc
                )
            )
            continue
        if joint.type not in ACTUATED:
            raise InputError(
                path,
                f"joint '{joint.name}' is of type '{joint.type}'; bcad supports revolute, continuous, "
                "prismatic and fixed joints",
                joint.line,
                joint.column,
            )
        settings = _joint_settings(robot, joint.name)
        if joint.mimic is not None:
            if (
                joint.name in robot.joints
                and robot.joints[joint.name].model_dump(exclude_unset=True).get("status") == "X"
            ):
                raise doc.error(
                    joint_loc + ("status",),
                    f"joint '{joint.name}' mimics '{joint.mimic[0]}': its value follows that joint, it cannot be X",
                )
            settings = settings.model_copy(update={"status": "F"})
        axis, sign, turn = _axis_of(joint)
        joint_frames.append(child)
        revolute = joint.type != "prismatic"
        parameter = ("rx", "ry", "rz")[axis] if revolute else ("tx", "ty", "tz")[axis]
        slot = ("tx", "ty", "tz", "rx", "ry", "rz").index(parameter)
        user_scale = angle if revolute else 1.0  # problem units -> internal
        urdf_scale = 1.0 if revolute else length  # URDF units -> internal

        if settings.bounds is not None:
            low, high = (value * user_scale for value in settings.bounds)
        elif joint.type == "continuous":
            low, high = -math.pi, math.pi
        elif joint.lower is None or joint.upper is None:
            raise InputError(
                path,
                f"joint '{joint.name}' has no <limit lower upper>; give bounds under "
                f"robots[{robot_index}].joints.{joint.name}",
                joint.line,
                joint.column,
            )
        else:
            low, high = joint.lower * urdf_scale, joint.upper * urdf_scale
        value = (settings.value * user_scale) if settings.value is not None else min(max(0.0, low), high)
        hard_limits = None
        if joint.type != "continuous" and joint.lower is not None and joint.upper is not None:
            limits = hard_limits = (joint.lower * urdf_scale, joint.upper * urdf_scale)
            (low, high), value = _within_limits(
                robot, joint.name, settings, limits, (low, high), value, revolute, units, loc, doc
            )
        _check_prior(robot, joint.name, settings, (low, high), user_scale, loc, doc)

        motion = _motion_link(
            name, parent, child, settings, slot, sign, (low, high), value, user_scale, joint_loc, hard_limits
        )
        if joint.mimic is not None:
            mimics.append((motion, slot, sign, urdf_scale, joint))

        if settings.dh_error:
            raise doc.error(
                joint_loc + ("dh_error",),
                f"dh_error is for robots given by dh: rows; '{joint.name}' is a URDF joint "
                "(give its origin's error as origin_error)",
                key=True,
            )
        origin = scaled_origin(joint)
        motion.tip = turn.T.copy()  # identity for an axis along x, y or z
        if settings.origin_error:
            # a pose error of the joint's <origin>, in the origin's frame, before the motion
            error_frame = name + "/origin"
            frames.append(error_frame)
            links.append(
                _error_link(
                    error_frame,
                    parent,
                    error_frame,
                    [0.0] * 6,
                    settings.origin_error,
                    units,
                    joint_loc + ("origin_error",),
                    doc,
                    origin=origin,
                )
            )
            parent, origin = error_frame, np.eye(4)
        if settings.zero is None:
            motion.parent = parent
            motion.origin = origin @ turn
            links.append(motion)
            continue
        joint_frame = name + "/zero"
        frames.append(joint_frame)
        zero_status = ["F"] * 6
        zero_status[slot] = "L"
        zero = GraphLink(
            name + "/zero",
            parent,
            joint_frame,
            np.zeros(6),
            "".join(zero_status),
            origin=origin @ turn,
            tip=turn.T.copy(),
            rank="robot",
            loc=joint_loc,
            distributions={(parameter,): settings.zero.scaled(sign * user_scale)},
        )
        motion.parent = joint_frame
        motion.origin = turn.copy()
        links.extend([zero, motion])

    # <mimic>: q = multiplier q_master + offset. Each link's parameter is sign x q, so the mimic's
    # parameter is sign multiplier sign_master x (the master's parameter) + sign offset.
    for motion, slot, sign, urdf_scale, joint in mimics:
        master_name, multiplier, offset = joint.mimic
        master = next(j for j in urdf.joints if j.name == master_name)
        if (
            master.type not in ACTUATED
            or master.mimic is not None
            or (master.type == "prismatic") != (joint.type == "prismatic")
        ):
            raise InputError(
                path,
                f"joint '{joint.name}' mimics '{master_name}': bcad needs an actuated master of the same kind "
                "(revolute or prismatic) that mimics no other joint",
                joint.line,
                joint.column,
            )
        master_axis, master_sign, _ = _axis_of(master)
        master_slot = master_axis if master.type == "prismatic" else 3 + master_axis
        motion.coupled[slot] = (
            prefix + master_name,
            master_slot,
            sign * multiplier * master_sign,
            sign * offset * urdf_scale,
        )

    check_edge(robot, loc, doc)
    base = edge_from_spec(prefix + "base", robot.parent, prefix + root, robot, loc, units, rank="robot")
    return frames, [base] + links, RobotFrames(robot.name, prefix + root, tuple(joint_frames))


def dh_error_slots(revolute: bool, convention: str) -> dict[str, dict[str, str]]:
    """Which pose parameter of a DH row's ``zero`` and ``dh`` links carries each DH error:
    theta on the zero link's rz; a, alpha and beta on the dh link's tx, rx and ry; d on the dh
    link's tz in a classic revolute row, on the zero link's tz otherwise (see below)."""
    d_fixed = revolute and convention == "classic"
    zero = {"tz": "d", "rz": "theta"} if not d_fixed else {"rz": "theta"}
    dh = {"tx": "a", "tz": "d", "rx": "alpha", "ry": "beta"} if d_fixed else {"tx": "a", "rx": "alpha", "ry": "beta"}
    return {"zero": zero, "dh": dh}


def dh_robot_frames_and_links(
    robot: Robot, robot_index: int, units: Units, doc: SourceDocument
) -> tuple[list[str], list[GraphLink], RobotFrames]:
    """Frames and links of a robot given by DH rows (the rows of clearance chains).

    Classic row i, T = Rz(theta) Tz(d) Tx(a) Rx(alpha) (Eq. 2 of the 2010 paper), becomes
    three links: ``J/zero`` (pose (0, 0, 0, 0, 0, theta): the joint's zero, its error L on rz),
    ``J`` (the joint variable on rz) and ``J/dh`` (pose (a, 0, d, alpha, 0, 0): Tz(d) Tx(a)
    Rx(alpha) is that pose exactly, so the errors of a, d and alpha are L on tx, tz and rx;
    Hayati's beta, a tilt about y, is L on ry: the pose's rotation becomes Ry(beta) Rx(alpha)).
    A prismatic row moves d: ``J/zero`` is (0, 0, d, 0, 0, theta), the variable and the zero error
    (d's) are on tz, and ``J/dh`` is (a, 0, 0, alpha, 0, 0). Modified row i, T = Rx(alpha) Tx(a) Rz(theta) Tz(d),
    is ``J/dh`` (a, 0, 0, alpha, 0, 0), then ``J/zero`` (0, 0, d, 0, 0, theta), then ``J``.
    Frames: ``NAME/link_0`` (the base) to ``NAME/link_N``, and ``NAME/J`` after each motion.
    """
    loc: Location = ("robots", robot_index)
    prefix = robot.name + "/"
    angle = angle_scale(units)
    rows = robot.dh or []
    names = [row.name or f"joint_{i + 1}" for i, row in enumerate(rows)]
    if len(set(names)) != len(names):
        raise doc.error(loc + ("dh",), f"robot '{robot.name}' names a joint twice: {', '.join(names)}")
    _check_joint_names(robot, set(names), loc, doc)
    frames = [f"{prefix}link_{i}" for i in range(len(rows) + 1)]
    links: list[GraphLink] = []
    joint_frames: list[str] = []
    for i, (row, joint_name) in enumerate(zip(rows, names)):
        row_loc = loc + ("dh", i)
        joint_loc = loc + ("joints", joint_name) if joint_name in robot.joints else row_loc
        settings = _joint_settings(robot, joint_name)
        if settings.origin_error:
            raise doc.error(
                joint_loc + ("origin_error",),
                f"origin_error is for URDF joints; '{joint_name}' is a DH row "
                "(give its errors as dh_error: a, alpha, d, theta)",
                key=True,
            )
        errors = dict(settings.dh_error)
        revolute = row.type == "revolute"
        # the zero-position error is along the joint's own variable: theta's for a revolute row, d's
        # (a length) for a prismatic one
        variable = "theta" if revolute else "d"
        if settings.zero is not None:
            if variable in errors:
                raise doc.error(
                    joint_loc + ("zero",),
                    f"joint '{joint_name}' gives its zero error twice (zero and dh_error.{variable})",
                    key=True,
                )
            errors[variable] = settings.zero
        user_scale = angle if revolute else 1.0
        if settings.bounds is not None:
            limits = settings.bounds
        elif row.limits is not None:
            limits = row.limits
        elif revolute:
            limits = (-math.pi / angle, math.pi / angle)
        elif settings.status == "X":
            raise doc.error(row_loc, f"prismatic joint '{joint_name}' needs limits: [low, high]")
        else:
            limits = (0.0, 0.0)
        low, high = limits[0] * user_scale, limits[1] * user_scale
        value = (settings.value * user_scale) if settings.value is not None else min(max(0.0, low), high)
        hard_limits = None
        if row.limits is not None:
            limits = hard_limits = (row.limits[0] * user_scale, row.limits[1] * user_scale)
            (low, high), value = _within_limits(
                robot, joint_name, settings, limits, (low, high), value, revolute, units, loc, doc
            )
        _check_prior(robot, joint_name, settings, (low, high), user_scale, loc, doc)

        name = prefix + joint_name
        slot = PARAMETERS.index("rz" if revolute else "tz")
        # Where d goes: with the fixed part in classic revolute rows, with the zero link otherwise.
        slots = dh_error_slots(revolute, robot.convention)
        d_fixed = "tz" in slots["dh"]
        zero_pose = [0.0, 0.0, 0.0 if d_fixed else row.d, 0.0, 0.0, row.theta]
        dh_pose = [row.a, 0.0, row.d if d_fixed else 0.0, row.alpha, 0.0, 0.0]
        zero_errors = {key: errors[source] for key, source in slots["zero"].items() if source in errors}
        dh_errors = {key: errors[source] for key, source in slots["dh"].items() if source in errors}
        previous, child = frames[i], frames[i + 1]

        def zero_link(parent: str, child_frame: str) -> GraphLink:
            return _error_link(name + "/zero", parent, child_frame, zero_pose, zero_errors, units, joint_loc, doc)

        def dh_link(parent: str, child_frame: str) -> GraphLink:
            return _error_link(name + "/dh", parent, child_frame, dh_pose, dh_errors, units, joint_loc, doc)

        def motion_link(child_frame: str) -> GraphLink:
            return _motion_link(
                name,
                name + "/zero",
                child_frame,
                settings,
                slot,
                1.0,
                (low, high),
                value,
                user_scale,
                joint_loc,
                hard_limits,
            )

        if robot.convention == "classic":
            frames.extend([name + "/zero", name])
            links.extend([zero_link(previous, name + "/zero"), motion_link(name), dh_link(name, child)])
        else:
            frames.extend([name + "/dh", name + "/zero"])
            links.extend([dh_link(previous, name + "/dh"), zero_link(name + "/dh", name + "/zero"), motion_link(child)])
        joint_frames.append(child)
    check_edge(robot, loc, doc)
    base = edge_from_spec(prefix + "base", robot.parent, frames[0], robot, loc, units, rank="robot")
    return frames, [base] + links, RobotFrames(robot.name, frames[0], tuple(joint_frames))
