"""One cell at several configurations of its robots: the graph replicated per configuration.

A workcell is designed, or a part is probed, with the same robot at several poses. The robot has
one set of errors (zeros, DH and origin errors, tool and fixture offsets), so the configurations
are not independent copies of the arm: the objective is Eq. 2 of the 2000 paper over the whole
graph, p(X) integral p(L) prod_c (cycle and relation terms of configuration c) dL, with L drawn
once per sample and shared by every configuration.

The graph that says this: every joint a configuration names is *replicated*. The frames
downstream of a replicated joint are *moving*: the children of its motion link, and every frame
reached from a moving frame through a plain link (a robot's own links, a tool, a robot mounted
on the arm), not through a relation, a closing link or a link some configuration lists. Each
configuration ``c`` gets a copy of the moving frames (``FRAME@c``) and of every link that
touches one (its ends mapped to the copies):

* a replicated joint's motion link ``ROBOT/JOINT@c`` with the configuration's own variable
  (status, value, bounds and prior from ``configurations[c].joints``, the rest from the robot's
  ``joints:``): its own X column per configuration;
* a relation, or a link with ``close: true``, named ``NAME@c``: each configuration scores its
  own (a relation or link that a configuration lists exists in that configuration only and
  keeps its name);
* any other link (a zero-error link, a DH row's fixed part, a tool): in the first
  configuration it keeps its name and its parameters; in the others it is ``NAME@c`` and shares
  them (:attr:`bcad.compiler.graph.GraphLink.shared`): the same L draw and the same X in every
  configuration.

Frames, links and parameters off the moving part (the base placement, the part, the fixtures)
exist once. The original moving frames are dropped: with configurations, the cell is only ever
at one of them.
"""

from __future__ import annotations

import copy
import difflib
from dataclasses import dataclass, field

import numpy as np

from bcad.compiler.edges import prior_outside_bounds, prior_outside_message
from bcad.compiler.graph import GraphLink
from bcad.compiler.robots import within_limits
from bcad.model.pose import PARAMETERS
from bcad.model.problem import Problem
from bcad.model.source import SourceDocument

#: separates a copy's name from its configuration's
SEPARATOR = "@"


@dataclass(frozen=True)
class ConfigurationCopy:
    """What one configuration is in the compiled graph."""

    name: str
    #: the replicated joints' motion links in this configuration: ROBOT/JOINT -> link name
    joints: dict[str, str]
    #: links and relations that belong to this configuration only (listed, or copies of the
    #: relations and closing links on its moving frames)
    links: tuple[str, ...]
    #: original frame -> this configuration's frame, for every moving frame
    frames: dict[str, str] = field(default_factory=dict)

    def frame(self, name: str) -> str:
        """This configuration's copy of ``name`` (``name`` itself off the moving part)."""
        return self.frames.get(name, name)


def copy_name(name: str, configuration: str) -> str:
    return f"{name}{SEPARATOR}{configuration}"


def _unknown(kind: str, name: str, known: list[str]) -> str:
    close = difflib.get_close_matches(name, known, n=1)
    return f"unknown {kind} '{name}'" + (f" (did you mean '{close[0]}'?)" if close else "")


def _replicated_joints(problem: Problem, links: list[GraphLink], doc: SourceDocument) -> dict[str, GraphLink]:
    """ROBOT/JOINT -> the original motion link of every joint some configuration names, with the
    joints that mimic one of them (a mimic follows its master in each configuration)."""
    motions = {link.joint[0]: link for link in links if link.joint is not None}
    robots = {robot.name for robot in problem.robots}
    replicated: dict[str, GraphLink] = {}
    for i, configuration in enumerate(problem.configurations):
        for robot, joints in configuration.joints.items():
            loc = ("configurations", i, "joints", robot)
            if robot not in robots:
                raise doc.error(
                    loc,
                    _unknown("robot", robot, sorted(robots)) + "; configurations name the robots under robots:",
                    key=True,
                )
            own = sorted(name.split("/", 1)[1] for name in motions if name.startswith(robot + "/"))
            for joint in joints:
                if joint != "default" and joint not in own:
                    raise doc.error(
                        loc + (joint,),
                        _unknown("joint", joint, own) + f" of robot '{robot}'; its actuated "
                        f"joints are {', '.join(own)}",
                        key=True,
                    )
            # The robot named with no joint, or with default: all its actuated joints.
            for joint in own if not joints or "default" in joints else joints:
                motion = motions[f"{robot}/{joint}"]
                if motion.coupled and joint in joints and joints[joint].status == "X":
                    raise doc.error(
                        loc + (joint, "status"),
                        f"joint '{joint}' mimics another joint: its value follows that joint's, it cannot be X",
                    )
                replicated[motion.joint[0]] = motion
    masters = {link.name for link in replicated.values()}
    for name, motion in motions.items():
        if any(master in masters for master, *_ in motion.coupled.values()):
            replicated[name] = motion
    return replicated


def _listed(problem: Problem, links: list[GraphLink], doc: SourceDocument) -> dict[str, str]:
    """Link or relation name -> the configuration that lists it (each listed at most once)."""
    names = {link.name for link in links if link.rank in {"link", "relation", "closing"}}
    owner: dict[str, str] = {}
    for i, configuration in enumerate(problem.configurations):
        for key in ("relations", "links"):
            for k, name in enumerate(getattr(configuration, key)):
                loc = ("configurations", i, key, k)
                if name not in names:
                    raise doc.error(
                        loc,
                        _unknown("link or relation", name, sorted(names)) + "; a configuration lists "
                        "links and relations declared under links: and relations:",
                    )
                if name in owner:
                    raise doc.error(
                        loc,
                        f"'{name}' is listed by configuration '{owner[name]}' already; a link or "
                        "relation belongs to one configuration (list none to have it in every one)",
                    )
                owner[name] = configuration.name
    return owner


def _moving_frames(links: list[GraphLink], replicated: dict[str, GraphLink], listed: dict[str, str]) -> set[str]:
    """The frames downstream of a replicated joint (module docstring)."""
    moving = {motion.child for motion in replicated.values()}
    rigid = [
        link
        for link in links
        if link.relation is None and link.rank not in {"relation", "closing"} and link.name not in listed
    ]
    grown = True
    while grown:  # ends: each pass adds a frame, and there are finitely many
        grown = False
        for link in rigid:
            if link.parent in moving and link.child not in moving:
                moving.add(link.child)
                grown = True
    return moving


def _configured_motion(
    motion: GraphLink, settings: dict, name: str, configuration: str, doc: SourceDocument, loc, units
) -> GraphLink:
    """A replicated joint's motion link in one configuration: the robot's settings overridden by
    the configuration's (``settings``: what it sets, in the problem's units)."""
    joint, sign, scale = motion.joint
    slot = motion.joint_slot
    parameter = PARAMETERS[slot]
    link = copy.deepcopy(motion)
    link.name = name
    link.joint = (copy_name(joint, configuration), sign, scale)
    link.configuration = configuration
    status = settings.get("status", motion.status[slot])
    if "bounds" in settings:
        low, high = (value * scale for value in settings["bounds"])
        link.bounds_given = True  # the problem's bounds, not the robot's limits (x_at_bound names them)
    else:
        low, high = motion.joint_limits
    if motion.hard_limits is not None:  # within the joint's own travel, as the robot's own settings
        (low, high), _ = within_limits(
            joint,
            motion.hard_limits,
            (low, high) if "bounds" in settings else None,
            settings["value"] * scale if "value" in settings else None,
            slot >= 3,
            units,
            (loc + ("bounds",), loc + ("value",)),
            doc,
            ((low, high), 0.0),
        )
    if status == "X" and not low < high:
        raise doc.error(
            loc,
            f"joint '{joint}' is X in configuration '{configuration}' but has no range to move in; give "
            "bounds: [low, high]",
        )
    link.joint_limits = (low, high)
    letters = list(link.status)
    letters[slot] = status
    link.status = "".join(letters)
    if "value" in settings:
        link.nominal[slot] = sign * settings["value"] * scale
    elif status != motion.status[slot] or "bounds" in settings:
        value = motion.nominal[slot] * sign
        link.nominal[slot] = sign * min(max(value, low), high)
    link.bounds = {}
    link.distributions = {}
    if status == "X":
        link.bounds[parameter] = tuple(sorted((sign * low, sign * high)))
        prior = settings.get("prior", motion.distributions.get((parameter,)) if motion.status[slot] == "X" else None)
        if "prior" in settings:
            if prior_outside_bounds(prior, low / scale, high / scale):
                raise doc.error(
                    loc + ("prior",), prior_outside_message(f"joint '{joint}'", prior, low / scale, high / scale)
                )
            prior = prior.scaled(sign * scale)
        if prior is not None:
            link.distributions[(parameter,)] = prior
    return link


def _setting_place(problem: Problem, index: int, joint: str) -> tuple:
    """Where configuration ``index`` writes ROBOT/JOINT's settings: under the joint's own name, or
    under ``default``, or (neither) the robot's entry."""
    robot, name = joint.split("/", 1)
    joints = problem.configurations[index].joints.get(robot, {})
    place = ("configurations", index, "joints", robot)
    for key in (name, "default"):
        if key in joints:
            return place + (key,)
    return place


def _settings(problem: Problem, index: int, joint: str) -> dict:
    """What configuration ``index`` sets for ROBOT/JOINT: its ``default`` then the joint's own."""
    robot, name = joint.split("/", 1)
    joints = problem.configurations[index].joints.get(robot, {})
    merged: dict = {}
    for key in ("default", name):
        if key in joints:
            merged.update({k: getattr(joints[key], k) for k in joints[key].model_fields_set})
    return merged


def replicate_configurations(
    problem: Problem, frames: list[str], links: list[GraphLink]
) -> tuple[list[str], list[GraphLink], list[ConfigurationCopy]]:
    """The frames and links of the cell at each of its configurations (module docstring)."""
    if not problem.configurations:
        return frames, links, []
    doc = problem.source
    names = [configuration.name for configuration in problem.configurations]
    for i, name in enumerate(names):
        if name in names[:i]:
            raise doc.error(("configurations", i, "name"), f"duplicate configuration name '{name}'")
    replicated = _replicated_joints(problem, links, doc)
    listed = _listed(problem, links, doc)
    moving = _moving_frames(links, replicated, listed)
    motion_names = {motion.name for motion in replicated.values()}
    joint_of = {motion.name: joint for joint, motion in replicated.items()}
    # A mimic's master, in a configuration: its copy there.
    renamed_motion = lambda name, c: copy_name(name, c) if name in motion_names else name  # noqa: E731

    kept_frames = [frame for frame in frames if frame not in moving]
    kept_links: list[GraphLink] = []
    touched: list[GraphLink] = []
    for link in links:
        if link.parent in moving or link.child in moving:
            touched.append(link)
        else:
            if link.name in listed:
                link.configuration = listed[link.name]
            kept_links.append(link)

    copies: list[ConfigurationCopy] = []
    new_frames: list[str] = []
    new_links: list[GraphLink] = []
    for index, configuration in enumerate(problem.configurations):
        c = configuration.name
        frame_map = {frame: copy_name(frame, c) for frame in frames if frame in moving}
        new_frames.extend(frame_map[frame] for frame in frames if frame in moving)
        joints: dict[str, str] = {}
        own: list[str] = [link.name for link in kept_links if link.configuration == c]
        for link in touched:
            if link.name in listed and listed[link.name] != c:
                continue
            if link.name in motion_names:
                joint = joint_of[link.name]
                loc = _setting_place(problem, index, joint)
                clone = _configured_motion(
                    link, _settings(problem, index, joint), copy_name(link.name, c), c, doc, loc, problem.units
                )
                clone.coupled = {
                    slot: (renamed_motion(master, c), *rest) for slot, (master, *rest) in link.coupled.items()
                }
                joints[joint] = clone.name
            else:
                clone = copy.deepcopy(link)
                per_configuration = link.rank in {"relation", "closing"} or link.relation is not None
                if link.name in listed:
                    clone.configuration = c
                    own.append(clone.name)
                elif per_configuration:
                    clone.name = copy_name(link.name, c)
                    clone.configuration = c
                    own.append(clone.name)
                elif index > 0:
                    clone.name = copy_name(link.name, c)
                    clone.shared = link.name
                    clone.configuration = c
                clone.coupled = {
                    slot: (renamed_motion(master, c), *rest) for slot, (master, *rest) in link.coupled.items()
                }
            clone.parent = frame_map.get(link.parent, link.parent)
            clone.child = frame_map.get(link.child, link.child)
            new_links.append(clone)
        copies.append(ConfigurationCopy(c, joints, tuple(own), frame_map))
    return kept_frames + new_frames, kept_links + new_links, copies


def check_shared_links(links: list[GraphLink], closing: set[int]) -> str | None:
    """A shared copy must be a tree link where the link it shares is one (each configuration's
    copy of a tool is in its tree); the message when one is not."""
    index = {link.name: k for k, link in enumerate(links)}
    for k, link in enumerate(links):
        if link.shared is not None and (k in closing) != (index[link.shared] in closing):
            return (
                f"'{link.shared}' closes a cycle in one configuration and not in another ('{link.name}'); "
                "set close: true or false on it so that every configuration's copy is alike"
            )
    return None


def configuration_joint_values(
    copies: list[ConfigurationCopy], links: list[GraphLink], transforms, x: np.ndarray
) -> dict[str, dict[str, float]]:
    """Each configuration's joint values at ``x`` (problem units): ROBOT/JOINT -> value, read off
    the motion links' affine parameters (a mimic's follows its master's)."""
    by_name = {link.name: k for k, link in enumerate(links)}
    values: dict[str, dict[str, float]] = {}
    for configuration in copies:
        joints = {}
        for joint, name in configuration.joints.items():
            k = by_name[name]
            _, sign, scale = links[k].joint
            parameter = transforms[k].parameters[links[k].joint_slot]
            raw = parameter.offset + sum(
                term.coefficient * x[term.index] for term in parameter.terms if term.source == "x"
            )
            joints[joint] = float(raw / (sign * scale))
        values[configuration.name] = joints
    return values
