"""The calibrated robot as a URDF (``bcad calibrate --urdf``).

A joint's calibrated geometry is everything between its parent link and its
motion: the URDF ``<origin>``, then an ``origin_error`` and a ``zero`` link
(URDF robots), or a DH row's ``J/dh`` and ``J/zero`` links. Their product at
the calibrated parameters becomes the joint's new ``<origin>``, so the
written joint's value is the one the controller commands (the zero offset is
folded into the origin) and its forward kinematics are the calibrated
model's. A URDF robot keeps every other element of its file as written; a DH
robot is written from scratch: per row a joint about z (its origin: the
calibrated ``J/zero``, after ``J/dh`` in the modified convention) and, in the
classic convention, a fixed joint ``J_dh`` carrying the calibrated
Tz(d) Tx(a) Rx(alpha). Lengths are written in metres, numbers with 17
significant digits. A camera mounted on the robot (eye-in-hand) is a fixed
joint, named as its mount link, from the robot's link to a link named as the
camera's optical frame, at the calibrated hand-eye transform. The robot's base
placement (``NAME/base``) and the other links outside the robot (a tool, a
tracker) are not part of a URDF: they are in the JSON result.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from lxml import etree

from bcad.compiler import CompiledProblem
from bcad.compiler.units import urdf_length_scale
from bcad.compiler.urdf import UrdfText, urdf_text
from bcad.kinematics.chain import Chain, Samples
from bcad.kinematics.se3 import matrix_to_rpy_exact
from bcad.model.problem import Robot


def _numbers(values) -> str:
    return " ".join(repr(float(v)) for v in values)


class LinkMatrices:
    """Each graph link's transform at given X and L (one sample)."""

    def __init__(self, compiled: CompiledProblem, x: np.ndarray, l: np.ndarray):
        self.compiled = compiled
        self.x = np.asarray(x, dtype=float)[None]
        self.samples = Samples(np.asarray(l, dtype=float)[None])
        self.index = {link.name: k for k, link in enumerate(compiled.graph.links)}

    def __call__(self, name: str) -> np.ndarray:
        transform = self.compiled.transforms[self.index[name]]
        return Chain([(transform, True)]).evaluate(self.x, self.samples).matrices()[0]

    def link(self, name: str):
        return self.compiled.graph.links[self.index[name]]


def _origin_element(joint, T: np.ndarray, metres: float) -> None:
    origin = joint.find("origin")
    if origin is None:
        origin = etree.SubElement(joint, "origin")
    origin.set("xyz", _numbers(T[:3, 3] * metres))
    origin.set("rpy", _numbers(matrix_to_rpy_exact(T[:3, :3])))


def _urdf_robot(robot: Robot, matrices: LinkMatrices, metres: float) -> str:
    """The robot's own URDF file with every actuated joint's origin replaced by its calibrated one."""
    compiled = matrices.compiled
    path = compiled.problem.source.relative_path(robot.urdf)
    # a xacro file: its expansion; parsed as the compiler's reader parses it, its comments kept
    root = UrdfText(path, urdf_text(path, robot.xacro_args)).parse(keep_comments=True)
    tree = etree.ElementTree(root)
    prefix = robot.name + "/"
    for joint in tree.getroot().iter("joint"):
        name = prefix + joint.get("name", "")
        if name not in matrices.index or joint.get("type") == "fixed":
            continue
        motion = matrices.link(name)
        parent_frame = prefix + joint.find("parent").get("link")
        # Walk back from the motion link's parent to the URDF parent link through the error links.
        steps, frame = [], motion.parent
        while frame != parent_frame:
            link = next(link for link in compiled.graph.links if link.child == frame)
            steps.append(matrices(link.name))
            frame = link.parent
        T = np.eye(4)
        for step in reversed(steps):
            T = T @ step
        _origin_element(joint, T @ motion.origin @ motion.tip, metres)
    _camera_mounts(tree.getroot(), robot, matrices, metres)
    return etree.tostring(tree, xml_declaration=True, encoding="utf-8").decode("utf-8")


def _camera_mounts(root, robot: Robot, matrices: LinkMatrices, metres: float) -> None:
    """Each camera mounted on this robot (its optical frame's link from one of the robot's links:
    eye-in-hand) as a fixed joint to a link named after the optical frame, at the calibrated
    mount (the hand-eye transform)."""
    compiled = matrices.compiled
    prefix = robot.name + "/"
    for camera in compiled.problem.cameras:
        for link in compiled.graph.links:
            if link.child != camera.frame or not link.parent.startswith(prefix):
                continue
            etree.SubElement(root, "link", name=camera.frame)
            joint = etree.SubElement(root, "joint", name=link.name, type="fixed")
            etree.SubElement(joint, "parent", link=link.parent[len(prefix) :])
            etree.SubElement(joint, "child", link=camera.frame)
            _origin_element(joint, matrices(link.name), metres)


def _dh_robot(robot: Robot, matrices: LinkMatrices, metres: float) -> str:
    """A URDF written from the calibrated DH rows."""
    root = etree.Element("robot", name=robot.name)
    prefix = robot.name + "/"
    rows = robot.dh or []
    etree.SubElement(root, "link", name="link_0")
    for i, row in enumerate(rows):
        joint_name = row.name or f"joint_{i + 1}"
        name = prefix + joint_name
        motion = matrices.link(name)
        before = matrices(name + "/zero")
        if robot.convention == "modified":
            before = matrices(name + "/dh") @ before
        moving = f"link_{i + 1}" if robot.convention == "modified" else f"{joint_name}_moving"
        etree.SubElement(root, "link", name=moving)
        joint = etree.SubElement(root, "joint", name=joint_name, type=row.type)
        etree.SubElement(joint, "parent", link=f"link_{i}")
        etree.SubElement(joint, "child", link=moving)
        _origin_element(joint, before @ motion.origin, metres)
        etree.SubElement(joint, "axis", xyz="0 0 1")
        slot = 5 if row.type == "revolute" else 2
        parameter = ("tx", "ty", "tz", "rx", "ry", "rz")[slot]
        scale = 1.0 if row.type == "revolute" else metres
        low, high = motion.bounds.get(parameter, (motion.nominal[slot], motion.nominal[slot]))
        etree.SubElement(
            joint, "limit", lower=repr(float(low * scale)), upper=repr(float(high * scale)), effort="0", velocity="0"
        )
        if robot.convention == "classic":
            etree.SubElement(root, "link", name=f"link_{i + 1}")
            fixed = etree.SubElement(root, "joint", name=f"{joint_name}_dh", type="fixed")
            etree.SubElement(fixed, "parent", link=moving)
            etree.SubElement(fixed, "child", link=f"link_{i + 1}")
            _origin_element(fixed, matrices(name + "/dh"), metres)
    _camera_mounts(root, robot, matrices, metres)
    return etree.tostring(root, xml_declaration=True, encoding="utf-8", pretty_print=True).decode("utf-8")


def calibrated_urdfs(compiled: CompiledProblem, x: np.ndarray, l: np.ndarray) -> dict[str, str]:
    """URDF text of every robot of the problem at the calibrated X and L, by robot name."""
    matrices = LinkMatrices(compiled, x, l)
    metres = 1.0 / urdf_length_scale(compiled.problem.units)
    return {
        robot.name: (_dh_robot if robot.dh is not None else _urdf_robot)(robot, matrices, metres)
        for robot in compiled.problem.robots
    }


def urdf_paths(target: Path, robots: list[str], suffix: str = ".urdf") -> dict[str, Path]:
    """Where ``--urdf TARGET`` writes each robot (``--camera-info`` each camera): TARGET itself for
    one, TARGET_STEM_NAME.urdf (or TARGET's own suffix) for several."""
    if len(robots) == 1:
        return {robots[0]: target}
    return {
        name: target.with_name(f"{target.stem}_{_file_name_part(name)}{target.suffix or suffix}") for name in robots
    }


#: the longest robot name part of a file name (file systems allow 255 bytes in all)
MAX_NAME_PART = 64


def _file_name_part(name: str) -> str:
    """A robot's name as part of a file name: letters, digits, ``_ . -`` only (never a folder
    separator), at most MAX_NAME_PART characters; a name changed to fit ends with a short
    hash of itself, so distinct robots keep distinct files."""
    import hashlib
    import re

    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", name).lstrip(".")
    if safe == name and len(name) <= MAX_NAME_PART:
        return name
    digest = hashlib.sha256(name.encode("utf-8", "surrogatepass")).hexdigest()[:8]
    return f"{safe[: MAX_NAME_PART - 9]}_{digest}"
