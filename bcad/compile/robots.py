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

from bcad.compile.graph import GraphLink
from bcad.compile.edges import check_edge, edge_from_spec
from bcad.compile.urdf import UrdfJoint, UrdfRobot, read_urdf
from bcad.compile.units import angle_scale, urdf_length_scale
from bcad.errors import InputError
from bcad.model.problem import Joint, Robot, Units
from bcad.model.source import Location, SourceDocument

ACTUATED = {"revolute", "continuous", "prismatic"}


def _load_urdf(robot: Robot, doc: SourceDocument, loc: Location) -> UrdfRobot:
    path = doc.relative_path(robot.urdf)
    if not path.exists():
        raise doc.error(loc + ("urdf",), f"URDF file '{path}' not found (paths are relative to the problem file)")
    if not path.is_file():
        raise doc.error(loc + ("urdf",), f"'{path}' is not a regular file; expected a URDF file")
    return read_urdf(path)


def _joint_settings(robot: Robot, name: str) -> Joint:
    merged = {}
    for key in ("default", name):
        if key in robot.joints:
            merged.update(robot.joints[key].model_dump(exclude_unset=True))
    return Joint.model_validate(merged)


def _axis_of(joint: UrdfJoint, path) -> tuple[int, float]:
    axis = joint.axis
    k = int(np.argmax(np.abs(axis)))
    if np.count_nonzero(np.abs(axis) > 1e-12) != 1:
        raise InputError(
            path,
            f"joint '{joint.name}' has axis {axis.round(6).tolist()}; bcad needs an axis along x, y or z "
            "(rotate the joint's origin so that the axis is z)",
            joint.line,
        )
    return k, float(np.sign(axis[k]))


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
    urdf = _load_urdf(robot, doc, loc)
    path = urdf.path
    length = urdf_length_scale(units)
    angle = angle_scale(units)
    prefix = robot.name + "/"

    joint_names = {joint.name for joint in urdf.joints}
    for key in robot.joints:
        if key != "default" and key not in joint_names:
            close = difflib.get_close_matches(key, sorted(joint_names), n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise doc.error(
                loc + ("joints", key),
                f"robot '{robot.name}' has no joint '{key}'{hint}; its URDF joints are {', '.join(sorted(joint_names))}",
                key=True,
            )

    frames = [prefix + link for link in urdf.links]
    children = {joint.child for joint in urdf.joints}
    roots = [link for link in urdf.links if link not in children]
    if len(roots) != 1:
        raise InputError(path, f"a URDF needs exactly one root link (one that is no joint's child), found {roots}")
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
            links.append(GraphLink(name, parent, child, np.zeros(6), "FFFFFF", origin=scaled_origin(joint), rank="robot", loc=loc))
            continue
        if joint.type not in ACTUATED:
            raise InputError(
                path,
                f"joint '{joint.name}' is of type '{joint.type}'; bcad supports revolute, continuous, prismatic and fixed joints",
                joint.line,
            )
        settings = _joint_settings(robot, joint.name)
        if joint.mimic is not None:
            if joint.name in robot.joints and robot.joints[joint.name].model_dump(exclude_unset=True).get("status") == "X":
                raise doc.error(joint_loc + ("status",), f"joint '{joint.name}' mimics '{joint.mimic[0]}': its value follows that joint, it cannot be X")
            settings = settings.model_copy(update={"status": "F"})
        axis, sign = _axis_of(joint, path)
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
                f"joint '{joint.name}' has no <limit lower upper>; give bounds under robots[{robot_index}].joints.{joint.name}",
                joint.line,
            )
        else:
            low, high = joint.lower * urdf_scale, joint.upper * urdf_scale
        value = (settings.value * user_scale) if settings.value is not None else min(max(0.0, low), high)

        status = ["F"] * 6
        status[slot] = settings.status
        nominal = np.zeros(6)
        nominal[slot] = sign * value
        motion = GraphLink(name, parent, child, nominal, "".join(status), rank="robot", loc=joint_loc)
        motion.joint = (name, sign, user_scale)
        if joint.mimic is not None:
            mimics.append((motion, slot, sign, urdf_scale, joint))
        if settings.status == "X":
            motion.bounds[parameter] = tuple(sorted((sign * low, sign * high)))
            if settings.prior is not None:
                motion.distributions[(parameter,)] = settings.prior.scaled(sign * user_scale)

        if settings.zero is None:
            motion.origin = scaled_origin(joint)
            links.append(motion)
            continue
        joint_frame = name + "/zero"
        frames.append(joint_frame)
        zero_status = ["F"] * 6
        zero_status[slot] = "L"
        zero = GraphLink(
            name + "/zero", parent, joint_frame, np.zeros(6), "".join(zero_status),
            origin=scaled_origin(joint), rank="robot", loc=joint_loc,
            distributions={(parameter,): settings.zero.scaled(sign * user_scale)},
        )
        motion.parent = joint_frame
        links.extend([zero, motion])

    # <mimic>: q = multiplier q_master + offset. Each link's parameter is sign x q, so the mimic's
    # parameter is sign multiplier sign_master x (the master's parameter) + sign offset.
    for motion, slot, sign, urdf_scale, joint in mimics:
        master_name, multiplier, offset = joint.mimic
        master = next(j for j in urdf.joints if j.name == master_name)
        if master.type not in ACTUATED or master.mimic is not None or (master.type == "prismatic") != (joint.type == "prismatic"):
            raise InputError(
                path, f"joint '{joint.name}' mimics '{master_name}': bcad needs an actuated master of the same kind "
                "(revolute or prismatic) that mimics no other joint", joint.line,
            )
        master_axis, master_sign = _axis_of(master, path)
        master_slot = master_axis if master.type == "prismatic" else 3 + master_axis
        motion.coupled[slot] = (prefix + master_name, master_slot, sign * multiplier * master_sign, sign * offset * urdf_scale)

    check_edge(robot, loc, doc)
    base = edge_from_spec(prefix + "base", robot.parent, prefix + roots[0], robot, loc, units, rank="robot")
    return frames, [base] + links, RobotFrames(robot.name, prefix + roots[0], tuple(joint_frames))
